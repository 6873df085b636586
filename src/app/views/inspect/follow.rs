//! Following a recipe in the Inspect view: each map the view measures is
//! registered to the recipe's reference map ([`place_inspection`], the same
//! as `sheen analyze --recipe` and the watch), the recipe's inspection is
//! moved onto the part, the alignment's rows lead the table, and the map
//! can show the part less its aligned reference. No GUI types.

use std::path::PathBuf;
use std::sync::Arc;

use crate::analysis::alignment::difference_to_reference;
use crate::analysis::height_map::{HeightMap, z_um};
use crate::analysis::recipe::{PartNotFound, PlacedInspection, Recipe, place_inspection};
use crate::app::textures::key_of;
use crate::io::recipe_file::LoadedRecipe;

use super::compute::Analysis;

/// A recipe the view follows, with its reference map.
pub struct FollowedRecipe {
    pub path: PathBuf,
    pub recipe: Recipe,
    pub reference: Arc<HeightMap>,
    /// Distinguishes two openings of the same file (it may have changed).
    pub generation: u64,
}

impl FollowedRecipe {
    pub fn new(path: PathBuf, loaded: LoadedRecipe, generation: u64) -> Self {
        Self { path, recipe: loaded.recipe, reference: Arc::new(loaded.reference), generation }
    }

    pub fn name(&self) -> &str {
        &self.recipe.name
    }

    /// Finds the part on `map` and moves the recipe's inspection onto it.
    pub fn place_on(&self, map: &HeightMap) -> Result<PlacedInspection, PartNotFound> {
        place_inspection(&self.recipe, &self.reference, map, &self.recipe.session.inspection)
    }
}

/// What an analysis of a found part adds: the alignment's rows, and the
/// difference to the reference when the map shows it.
pub struct Following {
    pub placed: Arc<PlacedInspection>,
    pub reference: Arc<HeightMap>,
    pub show_difference: bool,
}

impl Following {
    /// Names the placement in an analysis key.
    pub fn key(&self) -> u64 {
        let a = &self.placed.alignment;
        let p = a.placement;
        key_of(&[a.score, p.rotation_deg, p.shift_mm[0], p.shift_mm[1]].map(f64::to_bits))
    }

    /// The analysis of the moved inspection on `map` with the alignment's
    /// rows first, as the command line's table has them, and, when asked,
    /// the part less its aligned reference in place of the heights (a
    /// range symmetric about zero, so a defect or a misplacement stands out).
    pub fn apply(&self, mut analysis: Analysis, map: &HeightMap) -> Analysis {
        if let Ok(report) = &mut analysis.report {
            report.table.rows.splice(0..0, self.placed.rows.iter().cloned());
        }
        if self.show_difference {
            let difference = difference_to_reference(&self.reference, map, &self.placed.alignment);
            analysis.display_um = z_um(&difference);
            analysis.range_um = crate::app::views::robust_range(&analysis.display_um, 0.01, 0.99).map(|(lo, hi)| {
                let half = lo.abs().max(hi.abs());
                (-half, half)
            });
            analysis.filled = None;
            analysis.shown_surface = None;
            analysis.shows_difference = true;
        }
        analysis
    }
}
