//! `sheen recipe`: a part type's recipe from a reference part. The reference
//! is measured once as `sheen analyze` would (its results and height map go
//! to `NAME.reference/` beside the recipe), and the recipe keeps the
//! session that did it (manifest, engine parameters, the inspection as run,
//! its pitch fixed) and points at that height map, which every later part
//! is registered to.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::Args;

use super::analyze::{self, AnalyzeArgs};
use crate::analysis::recipe::{DEFAULT_MIN_MATCH_SCORE, Recipe};
use crate::analysis::session::Session;
use crate::io;

#[derive(Debug, Args)]
pub struct RecipeArgs {
    /// The reference part's fringe-set manifest.
    pub reference: PathBuf,
    /// Inspection spec (JSON) whose regions and sections are drawn on the reference.
    #[arg(long, value_name = "INSPECTION.json", conflicts_with = "session", required_unless_present = "session")]
    pub spec: Option<PathBuf>,
    /// Session saved by the app: its engine parameters and inspection.
    #[arg(long, value_name = "SESSION.json")]
    pub session: Option<PathBuf>,
    /// The recipe file to write (`*.sheen-recipe.json`); the reference's
    /// results go to a folder beside it.
    #[arg(long, value_name = "RECIPE.json")]
    pub out: PathBuf,
    /// The recipe's name in records and reports [default: the file's stem].
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,
    /// Parts whose match score is below this are not measured ("part not found").
    #[arg(long = "min-score", value_name = "S", default_value_t = DEFAULT_MIN_MATCH_SCORE)]
    pub min_score: f64,
    /// Largest rotation of a part in the stage plane that is searched.
    #[arg(long = "max-rotation", value_name = "DEG", default_value_t = 10.0)]
    pub max_rotation_deg: f64,
    /// A file whose appearance says a part's folder is complete (`sheen watch`).
    #[arg(long, value_name = "FILE_NAME")]
    pub sentinel: Option<String>,
    /// For parts that arrive as folders of images without a manifest: one
    /// `sheen import` option per use, in order, e.g. --import-option=--pattern
    /// --import-option='{camera}/p{period}_{shift:02}.png'.
    #[arg(long = "import-option", value_name = "ARG", allow_hyphen_values = true)]
    pub import_options: Vec<String>,
    /// The rig's calibration, copied into such a folder when it has none.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Where a part's ID is in its folder's name (`sheen watch`): a regular
    /// expression whose first group (or whole match) is the ID, e.g.
    /// 'SN(\d+)'; names that do not match keep the folder's name.
    #[arg(long = "part-id-pattern", value_name = "REGEX")]
    pub part_id_pattern: Option<String>,
    /// The part type's description for the plant's quality system (AQDEF
    /// K1002).
    #[arg(long, value_name = "TEXT")]
    pub description: Option<String>,
    /// The production step the part is inspected after (AQDEF K1086).
    #[arg(long, value_name = "TEXT")]
    pub operation: Option<String>,
    /// No progress on stderr and no table on stdout.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(args: &RecipeArgs) -> anyhow::Result<()> {
    let name = args.name.clone().unwrap_or_else(|| Recipe::name_of_file(&args.out));
    if name.trim().is_empty() {
        bail!("{}: give the recipe a name (--name)", args.out.display());
    }
    // Before the reference is measured, which takes a while.
    if let Some(pattern) = &args.part_id_pattern {
        crate::analysis::recipe::part_id_regex(pattern).context("--part-id-pattern")?;
    }
    if !args.import_options.is_empty() {
        super::import::recipe_import_spec(&args.import_options).context("--import-option")?;
    }
    let folder = args.out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let reference_dir_name = format!("{name}.reference");
    let reference_dir = folder.join(&reference_dir_name);
    // The reference is measured with exactly the defaults a part will be.
    let analyze_args = AnalyzeArgs {
        spec: args.spec.clone(),
        session: args.session.clone(),
        quiet: args.quiet,
        ..AnalyzeArgs::new(Some(args.reference.clone()), reference_dir.clone())
    };
    let measured = analyze::measure_reference(&analyze_args)?;
    let manifest = io::paths::relative_to(&args.reference, folder);
    let session = Session {
        inspection: measured.inspection,
        ..Session::new(manifest, measured.params.context("the reference's engine parameters")?)
    };
    let recipe = Recipe {
        min_match_score: args.min_score,
        max_rotation_deg: args.max_rotation_deg,
        sentinel: args.sentinel.clone(),
        import: args.import_options.clone(),
        calibration: args.calibration.as_ref().map(|c| io::paths::relative_to(c, folder)),
        part_id_pattern: args.part_id_pattern.clone(),
        description: args.description.clone(),
        operation: args.operation.clone(),
        ..Recipe::new(name.clone(), session, PathBuf::from(reference_dir_name).join("height_map.x3p"))
    };
    // Checked as it will be read: limits in range, inspection valid.
    let recipe = Recipe::from_json(&recipe.to_json()).with_context(|| format!("recipe {}", args.out.display()))?;
    io::atomic::write_atomic(&args.out, |w| w.write_all(recipe.to_json().as_bytes()))?;
    if !args.quiet {
        eprintln!(
            "sheen: recipe '{name}' written to {} (reference measured in {})",
            args.out.display(),
            reference_dir.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct AnalyzeCommand {
        #[command(flatten)]
        args: AnalyzeArgs,
    }

    /// The typed start of the watch's and the recipe's inspections is the
    /// command line's: every option at the default `sheen analyze` gives it.
    #[test]
    fn typed_analyze_options_start_at_the_command_lines_defaults() {
        let parsed = AnalyzeCommand::try_parse_from(["sheen analyze", "part/fringe-set.json", "--out", "results"])
            .expect("parses")
            .args;
        let typed = AnalyzeArgs::new(Some("part/fringe-set.json".into()), "results".into());
        assert_eq!(format!("{typed:?}"), format!("{parsed:?}"));
    }
}
