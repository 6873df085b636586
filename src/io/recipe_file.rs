//! A recipe file (`sheen recipe`, the app's Save as recipe) read with the
//! reference height map it names beside it, so the CLI, the watch and the
//! app start from the same two things.

use std::path::{Path, PathBuf};

use crate::analysis::alignment::ReferenceLevels;
use crate::analysis::error::AnalysisError;
use crate::analysis::height_map::HeightMap;
use crate::analysis::recipe::Recipe;
use crate::engine::length_unit::LengthUnit;
use crate::io::IoError;
use crate::io::height_map_file::{TiffMapScale, read_height_map_file};

/// A recipe and its reference part's height map, with the map's alignment
/// levels as they are made (kept for the next part).
#[derive(Clone, Debug)]
pub struct LoadedRecipe {
    pub recipe: Recipe,
    pub reference: HeightMap,
    pub reference_levels: ReferenceLevels,
}

#[derive(Debug, thiserror::Error)]
pub enum RecipeFileError {
    #[error(transparent)]
    Read(Box<IoError>),
    #[error("recipe {}: {source}", path.display())]
    Invalid { path: PathBuf, source: Box<AnalysisError> },
    #[error("reference height map of recipe {}: {source}", path.display())]
    Reference { path: PathBuf, source: Box<IoError> },
}

/// Reads a recipe and the reference map beside it (its path is relative to
/// the recipe file).
pub fn read_recipe(path: &Path) -> Result<LoadedRecipe, RecipeFileError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| RecipeFileError::Read(Box::new(IoError::Read { path: path.to_path_buf(), source })))?;
    let recipe = Recipe::from_json(&text)
        .map_err(|source| RecipeFileError::Invalid { path: path.to_path_buf(), source: Box::new(source) })?;
    let map_path = path.parent().unwrap_or(Path::new("")).join(&recipe.reference_map);
    let reference = read_height_map_file(&map_path, &TiffMapScale { pixel_mm: None, z_unit: LengthUnit::Um })
        .map_err(|source| RecipeFileError::Reference { path: path.to_path_buf(), source: Box::new(source) })?
        .map;
    Ok(LoadedRecipe { recipe, reference, reference_levels: ReferenceLevels::default() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recipe_whose_reference_map_is_missing_names_both_files() {
        let dir = tempfile::tempdir().unwrap();
        let session = crate::analysis::session::Session::new("ref/fringe-set.json", Default::default());
        let recipe = Recipe::new("plate", session, "plate.reference/height_map.x3p");
        let path = dir.path().join("plate.sheen-recipe.json");
        std::fs::write(&path, recipe.to_json()).unwrap();
        let e = read_recipe(&path).unwrap_err().to_string();
        assert!(e.starts_with(&format!("reference height map of recipe {}", path.display())), "{e}");
        assert!(e.contains("height_map.x3p"), "{e}");
        std::fs::write(&path, "{\"sheen_recipe\": 99}").unwrap();
        let e = read_recipe(&path).unwrap_err();
        assert!(matches!(e, RecipeFileError::Invalid { .. }), "{e}");
    }
}
