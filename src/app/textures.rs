//! GPU textures of the map views, rebuilt only when what they show changed.
//!
//! Each place a map is drawn (a *slot*: view, pane, camera) keeps one texture
//! and the key it was built for. The key hashes everything the image depends
//! on (result generation, set, shift, range, colour map, ...); an unchanged key
//! reuses the texture, so a frame costs no colour mapping at all. Slots not
//! drawn for a while are dropped to give the GPU memory back.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};

use eframe::egui::{self, ColorImage, TextureHandle, TextureOptions};

/// Slots unused for this many frames are freed.
const EVICT_AFTER_FRAMES: u64 = 600;
/// At most this many textures are kept (a full-resolution map is 12 MB).
const MAX_SLOTS: usize = 24;

struct Slot {
    key: u64,
    texture: TextureHandle,
    last_used_frame: u64,
}

#[derive(Default)]
pub struct TextureCache {
    slots: HashMap<egui::Id, Slot>,
    frame: u64,
    builds: u64,
}

impl TextureCache {
    /// The texture of `slot` for `key`, building it with `build` only when the
    /// slot is new or its key changed.
    pub fn get(
        &mut self,
        ctx: &egui::Context,
        slot: egui::Id,
        key: u64,
        build: impl FnOnce() -> ColorImage,
    ) -> TextureHandle {
        let frame = self.frame;
        if let Some(s) = self.slots.get_mut(&slot)
            && s.key == key
        {
            s.last_used_frame = frame;
            return s.texture.clone();
        }
        self.builds += 1;
        let max_side = ctx.input(|i| i.max_texture_side).max(1);
        let image = fit_texture_limit(build(), max_side);
        let name = format!("map {slot:?}");
        let texture = match self.slots.get_mut(&slot) {
            Some(s) => {
                // Same slot, new content: replace in place (the id stays valid).
                s.texture.set(image, TextureOptions::NEAREST);
                s.key = key;
                s.last_used_frame = frame;
                s.texture.clone()
            }
            None => {
                let texture = ctx.load_texture(name, image, TextureOptions::NEAREST);
                self.slots.insert(slot, Slot { key, texture: texture.clone(), last_used_frame: frame });
                texture
            }
        };
        self.evict();
        texture
    }

    /// Call once per frame, after drawing.
    pub fn end_frame(&mut self) {
        self.frame += 1;
        let frame = self.frame;
        self.slots.retain(|_, s| frame - s.last_used_frame <= EVICT_AFTER_FRAMES);
    }

    fn evict(&mut self) {
        while self.slots.len() > MAX_SLOTS {
            let Some(oldest) = self.slots.iter().min_by_key(|(_, s)| s.last_used_frame).map(|(id, _)| *id) else {
                break;
            };
            self.slots.remove(&oldest);
        }
    }

    /// How many images were built (colour-mapped and uploaded) so far.
    pub fn builds(&self) -> u64 {
        self.builds
    }

    pub fn len(&self) -> usize {
        self.slots.len()
    }

    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    pub fn clear(&mut self) {
        self.slots.clear();
    }
}

/// The image, decimated by the smallest integer factor that brings both sides
/// within the GPU's texture limit (nearest sample: maps keep exact values).
/// The map is still drawn over its full pixel extent, so hover and click map
/// to the original pixels.
pub fn fit_texture_limit(image: ColorImage, max_side: usize) -> ColorImage {
    let [w, h] = image.size;
    let factor = w.max(h).div_ceil(max_side.max(1));
    if factor <= 1 {
        return image;
    }
    let (dw, dh) = (w.div_ceil(factor), h.div_ceil(factor));
    let pixels =
        (0..dh).flat_map(|y| (0..dw).map(move |x| (x, y))).map(|(x, y)| image.pixels[y * factor * w + x * factor]);
    ColorImage::new([dw, dh], pixels.collect())
}

/// A 64-bit key of anything hashable (std's SipHash with fixed keys: stable within a run).
pub fn key_of(value: &impl Hash) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    value.hash(&mut h);
    h.finish()
}

/// `f32` values hashed by their bits (ranges, thresholds in view settings).
pub fn f32_bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_texture_is_built_once_per_key() {
        let ctx = egui::Context::default();
        let mut cache = TextureCache::default();
        let slot = egui::Id::unique("slot");
        let mut built = 0;
        for _ in 0..3 {
            let _ = cache.get(&ctx, slot, 1, || {
                built += 1;
                ColorImage::filled([2, 2], egui::Color32::RED)
            });
            cache.end_frame();
        }
        assert_eq!(built, 1);
        let _ = cache.get(&ctx, slot, 2, || {
            built += 1;
            ColorImage::filled([2, 2], egui::Color32::BLUE)
        });
        assert_eq!(built, 2);
        assert_eq!(cache.builds(), 2);
        assert_eq!(cache.len(), 1, "a new key replaces the slot's texture");
    }

    #[test]
    fn oversized_images_are_decimated_to_the_texture_limit() {
        let pixels = (0..10 * 4).map(|i| egui::Color32::from_gray(i as u8)).collect();
        let image = ColorImage::new([10, 4], pixels);
        let small = fit_texture_limit(image.clone(), 4);
        assert_eq!(small.size, [4, 2]);
        // Nearest samples: (0,0), (3,0), (6,0), (9,0) of row 0; row 3 next.
        assert_eq!(small.pixels[..4], [0, 3, 6, 9].map(egui::Color32::from_gray));
        assert_eq!(small.pixels[4], egui::Color32::from_gray(30));
        assert_eq!(fit_texture_limit(image.clone(), 10).size, [10, 4]);
    }

    #[test]
    fn unused_slots_are_freed_and_the_count_is_bounded() {
        let ctx = egui::Context::default();
        let mut cache = TextureCache::default();
        for i in 0..(MAX_SLOTS + 5) {
            let _ = cache.get(&ctx, egui::Id::unique(i), 0, || ColorImage::filled([1, 1], egui::Color32::WHITE));
        }
        assert_eq!(cache.len(), MAX_SLOTS);
        for _ in 0..=EVICT_AFTER_FRAMES {
            cache.end_frame();
        }
        assert!(cache.is_empty());
    }
}
