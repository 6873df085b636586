//! A recipe: how one part type is inspected on a line, wherever the part
//! lies. A saved session (the reference part's manifest, the engine
//! parameters, the inspection whose regions and sections are drawn on the
//! reference) plus the reference part's height map, an X3P beside the
//! recipe file. Each new part is registered to that map ([`super::alignment`])
//! and the inspection moves with it; below `min_match_score` the part is
//! not measured ("part not found"). Versioned JSON (`"sheen_recipe": 1`);
//! io reads the file and resolves the paths relative to it.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::alignment::{Alignment, AlignmentError, AlignmentSearch, ReferenceLevels, align_with, region_leaving_field};
use super::error::AnalysisError;
use super::height_map::HeightMap;
use super::inspection::{InspectionSpec, check_version};
use super::measurement_table::{MeasurementKind, MeasurementRow, Tolerance};
use super::session::Session;

/// Format version written and read.
pub const RECIPE_VERSION: u64 = 1;

/// The match score below which a part is not measured: the same part type
/// scores above 0.99 on the simulator's scenes and real parts alike (the
/// heights' correlation, noise and burrs included); another type far lower.
pub const DEFAULT_MIN_MATCH_SCORE: f64 = 0.9;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recipe {
    /// Format version, [`RECIPE_VERSION`].
    pub sheen_recipe: u64,
    /// The name parts are recorded and reported under.
    pub name: String,
    /// The reference part's manifest, engine parameters and inspection.
    pub session: Session,
    /// The reference part's height map (X3P), relative to the recipe file.
    pub reference_map: PathBuf,
    #[serde(default = "default_min_match_score")]
    pub min_match_score: f64,
    /// Rotations in the stage plane from -max to +max are searched.
    #[serde(default = "default_max_rotation_deg")]
    pub max_rotation_deg: f64,
    /// A file whose appearance in a part's folder says the part is complete
    /// (`sheen watch`); without it a part is complete when its manifest and
    /// every image it names have kept their sizes for a second.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sentinel: Option<String>,
    /// For a rig that drops folders of images without a manifest: `sheen
    /// import`'s options (`--pattern`, `--periods`, ...) that make one in
    /// each part's folder (`sheen watch`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub import: Vec<String>,
    /// The rig's calibration (relative to the recipe), copied into a part's
    /// folder of images as `calibration.json` when it has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<PathBuf>,
    /// Where a part's ID is in its folder's name (`sheen watch`): a regular
    /// expression whose first group (or whole match) is the ID, e.g.
    /// `SN(\d+)` for `20261205-1200_SN4711`. Without it, or where a name does
    /// not match, the folder's name is the ID.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part_id_pattern: Option<String>,
    /// The part type's description, for the plant's quality system (AQDEF
    /// `K1002`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The production step the part is inspected after (AQDEF `K1086`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operation: Option<String>,
}

fn default_min_match_score() -> f64 {
    DEFAULT_MIN_MATCH_SCORE
}

fn default_max_rotation_deg() -> f64 {
    AlignmentSearch::default().max_rotation_deg
}

impl Recipe {
    /// A recipe with the default limits and no import: its name, the
    /// reference's session and where its reference map lies.
    pub fn new(name: impl Into<String>, session: Session, reference_map: impl Into<PathBuf>) -> Self {
        Self {
            sheen_recipe: RECIPE_VERSION,
            name: name.into(),
            session,
            reference_map: reference_map.into(),
            min_match_score: DEFAULT_MIN_MATCH_SCORE,
            max_rotation_deg: default_max_rotation_deg(),
            sentinel: None,
            part_id_pattern: None,
            import: Vec::new(),
            calibration: None,
            description: None,
            operation: None,
        }
    }

    /// The name a recipe file gives: `part.sheen-recipe.json` is `part`.
    pub fn name_of_file(path: &std::path::Path) -> String {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let name = name.strip_suffix(".json").unwrap_or(&name);
        name.strip_suffix(".sheen-recipe").unwrap_or(name).to_string()
    }

    /// Parses a recipe, checking its version first and its inspection and
    /// limits after.
    pub fn from_json(text: &str) -> Result<Self, AnalysisError> {
        const WHAT: &str = "recipe";
        check_version(text, WHAT, "sheen_recipe", RECIPE_VERSION)?;
        let recipe: Self = serde_json::from_str(text).map_err(|source| AnalysisError::Json { what: WHAT, source })?;
        recipe.session.inspection.validate()?;
        if !(recipe.min_match_score.is_finite() && (0.0..=1.0).contains(&recipe.min_match_score)) {
            return Err(AnalysisError::InvalidRecipe {
                reason: format!("min_match_score {} is not between 0 and 1", recipe.min_match_score),
            });
        }
        if !(recipe.max_rotation_deg.is_finite() && (0.0..=45.0).contains(&recipe.max_rotation_deg)) {
            return Err(AnalysisError::InvalidRecipe {
                reason: format!("max_rotation_deg {} is not between 0 and 45", recipe.max_rotation_deg),
            });
        }
        if recipe.name.trim().is_empty() {
            return Err(AnalysisError::InvalidRecipe { reason: "the name is empty".into() });
        }
        if let Some(pattern) = &recipe.part_id_pattern {
            part_id_regex(pattern)?;
        }
        Ok(recipe)
    }

    /// The part ID a folder name carries (see [`Recipe::part_id_pattern`]);
    /// `None` where the name does not match, or the match is empty.
    pub fn part_id(&self, folder_name: &str) -> Option<String> {
        let regex = part_id_regex(self.part_id_pattern.as_deref()?).ok()?;
        let found = regex.captures(folder_name)?;
        let id = found.get(1).or_else(|| found.get(0))?.as_str();
        (!id.is_empty()).then(|| id.to_string())
    }

    /// Pretty JSON, the form [`Recipe::from_json`] reads.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    pub fn search(&self) -> AlignmentSearch {
        AlignmentSearch { max_rotation_deg: self.max_rotation_deg }
    }
}

/// A part-ID pattern compiled, or why it cannot be.
pub fn part_id_regex(pattern: &str) -> Result<regex::Regex, AnalysisError> {
    regex::Regex::new(pattern)
        .map_err(|e| AnalysisError::InvalidRecipe { reason: format!("part_id_pattern '{pattern}': {e}") })
}

/// The share of the reference's nodes that must land on the part's data for
/// its score to count: a part mostly out of the field is not the part.
const MIN_ALIGNMENT_OVERLAP: f64 = 0.5;

/// A recipe's inspection placed on a part: moved with it, and the table's
/// first rows (the match score with the recipe's minimum as its lower
/// limit, the rotation and the shift).
#[derive(Clone, Debug)]
pub struct PlacedInspection {
    pub spec: InspectionSpec,
    pub rows: Vec<MeasurementRow>,
    pub alignment: Alignment,
}

/// Why a part was not measured with its recipe. Every message starts with
/// "part not found", which the line and the records show as the reason.
#[derive(Debug, thiserror::Error)]
pub enum PartNotFound {
    /// (The alignment's error is in the message, not a source, so a chain
    /// of causes does not print it twice.)
    #[error("part not found: {0}")]
    NotAligned(AlignmentError),
    #[error(
        "part not found: match score {score:.4} (the recipe needs {min_score}), {overlap_percent:.0} % of the \
         reference on the part's data at the best placement ({placed})"
    )]
    NoMatch { score: f64, min_score: f64, overlap_percent: f64, placed: String },
    #[error(
        "part not found: region '{region}' leaves the measured field where the part lies ({placed}, match score {score:.4})"
    )]
    RegionOutOfField { region: String, placed: String, score: f64 },
}

/// Finds the part on `map` by its `reference` map and moves `spec` (the
/// recipe's inspection, drawn on the reference) onto it. A part that does
/// not match, lies beyond the rotation searched, or that a region would
/// leave, is not measured: never a measurement in the wrong place.
pub fn place_inspection(
    recipe: &Recipe,
    reference: &HeightMap,
    reference_levels: &ReferenceLevels,
    map: &HeightMap,
    spec: &InspectionSpec,
) -> Result<PlacedInspection, PartNotFound> {
    let min_score = recipe.min_match_score;
    let found = align_with(reference, reference_levels, map, &recipe.search()).map_err(PartNotFound::NotAligned)?;
    let p = found.placement;
    let placed = format!("rotation {:.3} deg, shift {:.4}, {:.4} mm", p.rotation_deg, p.shift_mm[0], p.shift_mm[1]);
    let searched = p.rotation_deg.abs() <= recipe.max_rotation_deg + 1.0;
    if found.score < min_score || found.overlap < MIN_ALIGNMENT_OVERLAP || !searched {
        return Err(PartNotFound::NoMatch {
            score: found.score,
            min_score,
            overlap_percent: 100.0 * found.overlap,
            placed,
        });
    }
    let spec = p.move_spec(spec, reference.extent_mm());
    if let Some(region) = region_leaving_field(&spec.regions, map) {
        return Err(PartNotFound::RegionOutOfField { region: region.name.clone(), placed, score: found.score });
    }
    let row = |name: &str, value: f64, unit: &str| {
        MeasurementRow::new(format!("alignment {name}"), MeasurementKind::Alignment, Some(value), unit)
    };
    let rows = vec![
        row("score", found.score, "1")
            .with_tolerance(None, Some(Tolerance { lower: min_score, upper: 1.0 }))
            .with_note(format!(
                "{:.1} % of the reference on the part, residual {:.3} um RMS",
                100.0 * found.overlap,
                found.residual_rms_um
            )),
        row("rotation", p.rotation_deg, "deg"),
        row("shift X", p.shift_mm[0], "mm"),
        row("shift Y", p.shift_mm[1], "mm"),
    ];
    Ok(PlacedInspection { spec, rows, alignment: found })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::pipeline::Params;

    fn recipe() -> Recipe {
        let session = Session::new("ref/fringe-set.json", Params::default());
        Recipe::new("plate", session, "plate.reference/height_map.x3p")
    }

    #[test]
    fn a_part_id_comes_from_the_folder_name_by_the_recipes_pattern() {
        let mut r = recipe();
        assert_eq!(r.part_id("20261205-1200_SN4711"), None, "no pattern: the caller keeps the name");
        r.part_id_pattern = Some(r"SN(\d+)".into());
        let r = Recipe::from_json(&r.to_json()).expect("a valid pattern reads back");
        assert_eq!(r.part_id("20261205-1200_SN4711").as_deref(), Some("4711"));
        assert_eq!(r.part_id("20261205-1200"), None, "no match");
        let whole = Recipe { part_id_pattern: Some(r"\d{4}$".into()), ..recipe() };
        assert_eq!(whole.part_id("part-0042").as_deref(), Some("0042"), "no group: the whole match");
        let bad = Recipe { part_id_pattern: Some("SN(".into()), ..recipe() };
        let e = Recipe::from_json(&bad.to_json()).unwrap_err().to_string();
        assert!(e.contains("part_id_pattern 'SN('"), "{e}");
    }

    #[test]
    fn a_recipe_file_names_its_recipe() {
        for (file, name) in [("a/plate.sheen-recipe.json", "plate"), ("gauge.json", "gauge"), ("x.sheen-recipe", "x")] {
            assert_eq!(Recipe::name_of_file(std::path::Path::new(file)), name);
        }
    }

    #[test]
    fn a_recipe_reads_back_as_written() {
        let r = recipe();
        assert_eq!(Recipe::from_json(&r.to_json()).expect("reads"), r);
    }

    #[test]
    fn limits_out_of_range_are_refused_with_the_field() {
        for (field, value) in [("min_match_score", "1.5"), ("max_rotation_deg", "90")] {
            let mut json: serde_json::Value = serde_json::from_str(&recipe().to_json()).expect("json");
            json[field] = serde_json::from_str(value).expect("number");
            let err = Recipe::from_json(&json.to_string()).expect_err("refused");
            assert!(err.to_string().contains(field), "{err}");
        }
        let newer = recipe().to_json().replace("\"sheen_recipe\": 1", "\"sheen_recipe\": 2");
        assert!(Recipe::from_json(&newer).expect_err("newer").to_string().contains("version"));
    }
}
