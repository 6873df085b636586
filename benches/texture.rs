//! Texture benchmark (issue 20): every areal parameter of a 2048x1536 map
//! (the paper's camera size) with a plane F-operator, an S-filter at
//! λs = 0.025 mm and an L-filter at λc = 0.8 mm, as one `--texture` item
//! computes them: crop, filters, ISO 25178-2 height/hybrid/material-ratio/
//! volume parameters and the FFT-based Sal, Str, Std. Also the parts alone,
//! so a regression can be placed. `cargo bench --bench texture`.

use criterion::{Criterion, criterion_group, criterion_main};
use sheen::analysis::height_map::HeightMap;
use sheen::analysis::texture::areal::{MaterialRatioPoints, areal_parameters};
use sheen::analysis::texture::filter::FormRemoval;
use sheen::analysis::texture::measure::{TextureSettings, crop, measure_texture, scale_limited_surface};
use sheen::analysis::texture::spatial::spatial_parameters;

/// A tilted plate at the camera pitch (0.0117 mm) with a ground texture:
/// three crossing waves and a pseudo-random roughness, 1 % holes.
fn plate() -> HeightMap {
    let (w, h, pitch) = (2048usize, 1536usize, 0.0117);
    let z = (0..w * h)
        .map(|i| {
            let (c, r) = ((i % w) as f64, (i / w) as f64);
            if (i as u64).wrapping_mul(2654435761).is_multiple_of(100) {
                return f32::NAN;
            }
            let (x, y) = (c * pitch, r * pitch);
            let noise = ((i as u64).wrapping_mul(40503) % 1000) as f64 / 1000.0 - 0.5;
            (0.1 + 0.001 * x
                + 0.0004 * (x / 0.3).sin()
                + 0.0002 * ((x + y) / 0.07).sin()
                + 0.001 * (y / 5.0).sin()
                + 0.0001 * noise) as f32
        })
        .collect();
    HeightMap::new(w, h, 0.0, 0.0, pitch, z).expect("map")
}

fn benches(c: &mut Criterion) {
    let map = plate();
    let all = vec![true; map.z.len()];
    let settings = TextureSettings {
        form: FormRemoval::Plane,
        ls_mm: Some(0.025),
        lc_mm: Some(0.8),
        points: MaterialRatioPoints::default(),
    };
    let cropped = crop(&map, &all).expect("crop");
    let surface = scale_limited_surface(&cropped, &settings, "all").expect("surface");
    let mut group = c.benchmark_group("texture-2048x1536");
    group.sample_size(10);
    group.bench_function("all_areal_parameters_s_and_l_filtered", |b| {
        b.iter_with_large_drop(|| {
            let c = crop(&map, &all).expect("crop");
            measure_texture(&c, &settings, None, "all", &sheen::engine::control::RunControl::new()).expect("texture")
        })
    });
    group.bench_function("form_and_filters", |b| {
        b.iter_with_large_drop(|| scale_limited_surface(&cropped, &settings, "all").expect("surface"))
    });
    group.bench_function("height_hybrid_material_volume", |b| {
        b.iter(|| areal_parameters(&surface.z_um, map.width, map.height, map.pitch_mm, settings.points))
    });
    group.bench_function("sal_str_std_fft", |b| {
        b.iter(|| spatial_parameters(&surface.z_um, map.width, map.height, map.pitch_mm))
    });
    group.finish();
}

criterion_group!(texture, benches);
criterion_main!(texture);
