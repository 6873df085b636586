//! Following a recipe in the Inspect view: each map the view measures is
//! registered to the recipe's reference map ([`place_inspection`], the same
//! as `sheen analyze --recipe` and the watch), the recipe's inspection is
//! moved onto the part, the alignment's rows lead the table, and the map
//! can show the part less its aligned reference. No GUI types.

use std::path::PathBuf;
use std::sync::Arc;

use crate::analysis::alignment::{ReferenceLevels, difference_to_reference};
use crate::analysis::height_map::{HeightMap, z_um};
use crate::analysis::recipe::{PartNotFound, PlacedInspection, Recipe, place_inspection};
use crate::io::recipe_file::LoadedRecipe;

use super::compute::{Analysis, MapShows};

/// A recipe the view follows, with its reference map.
pub struct FollowedRecipe {
    pub path: PathBuf,
    pub recipe: Recipe,
    pub reference: Arc<HeightMap>,
    reference_levels: ReferenceLevels,
    /// Distinguishes two openings of the same file (it may have changed).
    pub generation: u64,
}

impl FollowedRecipe {
    pub fn new(path: PathBuf, loaded: LoadedRecipe, generation: u64) -> Self {
        Self {
            path,
            recipe: loaded.recipe,
            reference: Arc::new(loaded.reference),
            reference_levels: loaded.reference_levels,
            generation,
        }
    }

    pub fn name(&self) -> &str {
        &self.recipe.name
    }

    /// Finds the part on `map` and moves the recipe's inspection onto it.
    pub fn place_on(&self, map: &HeightMap) -> Result<PlacedInspection, PartNotFound> {
        place_inspection(&self.recipe, &self.reference, &self.reference_levels, map, &self.recipe.session.inspection)
    }
}

/// What an analysis of a found part adds: the alignment's rows, and the
/// difference to the reference when the map shows it.
pub struct Following {
    /// The key the part was placed under (its map and the recipe opened),
    /// which names the placement in an analysis key.
    pub key: u64,
    pub placed: Arc<PlacedInspection>,
    pub reference: Arc<HeightMap>,
    pub show_difference: bool,
}

impl Following {
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
            analysis.range_um =
                crate::io::colormap::symmetric_half_range(&analysis.display_um, 99).map(|half| (-half, half));
            analysis.filled = None;
            analysis.shown = MapShows::DifferenceToReference;
        }
        analysis
    }
}
