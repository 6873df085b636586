//! CSV exports of profiles and measurement tables.
//!
//! Both start with `#` comment lines stating the producer, the source file,
//! the parameters and the units (pandas: `read_csv(path, comment='#')`), then
//! one header row and one row per record, comma-separated with RFC 4180
//! quoting. Missing values are empty fields. Lengths are written with 6
//! decimals in mm (1 nm) and heights with 4 decimals in um (0.1 nm), below
//! anything the instrument resolves.

use std::io::{self, Write};

use crate::analysis::measurement_table::MeasurementTable;
use crate::analysis::profile::Profile;

/// Column header of the profile CSV.
pub const PROFILE_COLUMNS: &str = "distance_mm,x_mm,y_mm,z_um,n";

/// Column header of the measurement CSV.
/// The uncertainty and decision columns follow the first ten, so a reader of
/// the older layout still finds its columns where they were.
pub const MEASUREMENT_COLUMNS: &str = "name,kind,value,unit,nominal,lower_limit,upper_limit,verdict,note,parameter,\
                                       u,U,k,uncertainty_method,decision_rule,acceptance_lower,acceptance_upper";

/// Writes one profile: header lines with units, source file, end points and
/// parameters, then `distance_mm,x_mm,y_mm,z_um,n` per station (`n` = samples
/// averaged; `z_um` empty where `n` is 0).
pub fn write_profile_csv<W: Write>(mut w: W, profile: &Profile, source: &str) -> io::Result<()> {
    writeln!(w, "# Sheen {} section profile", env!("CARGO_PKG_VERSION"))?;
    writeln!(w, "# name: {}", one_line(&profile.name))?;
    writeln!(w, "# source: {}", one_line(source))?;
    writeln!(w, "# start_mm: {:.6}, {:.6}", profile.start_mm[0], profile.start_mm[1])?;
    writeln!(w, "# end_mm: {:.6}, {:.6}", profile.end_mm[0], profile.end_mm[1])?;
    writeln!(w, "# length_mm: {:.6}", profile.length_mm)?;
    writeln!(w, "# step_mm: {:.6}", profile.step_mm)?;
    writeln!(w, "# averaging_width_mm: {:.6} ({} parallel lines)", profile.width_mm, profile.lines_across)?;
    writeln!(w, "# interpolation: {}", profile.interpolation.describe())?;
    writeln!(
        w,
        "# units: distance_mm, x_mm, y_mm in millimetres; z_um in micrometres; n = samples averaged, z_um empty where n = 0"
    )?;
    writeln!(w, "{PROFILE_COLUMNS}")?;
    for s in &profile.samples {
        let z = if s.n > 0 && s.z_um.is_finite() { format!("{:.4}", s.z_um) } else { String::new() };
        writeln!(w, "{:.6},{:.6},{:.6},{},{}", s.distance_mm, s.x_mm, s.y_mm, z, s.n)?;
    }
    w.flush()
}

/// Writes a measurement table: header lines (producer, source, overall
/// verdict), then one row per measurement.
pub fn write_measurement_csv<W: Write>(mut w: W, table: &MeasurementTable, source: &str) -> io::Result<()> {
    writeln!(w, "# Sheen {} measurements", env!("CARGO_PKG_VERSION"))?;
    writeln!(w, "# source: {}", one_line(source))?;
    let overall = table.overall_verdict().map_or("none (no tolerances)", |v| v.name());
    writeln!(w, "# overall verdict: {overall}")?;
    writeln!(w, "{MEASUREMENT_COLUMNS}")?;
    for row in &table.rows {
        let num = |v: Option<f64>| v.filter(|v| v.is_finite()).map_or(String::new(), |v| format!("{v:.4}"));
        let (lo, hi) = row.limits().map_or((None, None), |(l, h)| (Some(l), Some(h)));
        let fields = [
            field(&row.name),
            row.kind.name().to_string(),
            num(row.value),
            field(&row.unit),
            num(row.nominal),
            num(lo),
            num(hi),
            row.verdict().map_or(String::new(), |v| v.name().to_string()),
            field(row.note.as_deref().unwrap_or("")),
            field(row.parameter.as_deref().unwrap_or("")),
            num(row.uncertainty.as_ref().map(|u| u.u)),
            num(row.uncertainty.as_ref().map(|u| u.expanded)),
            row.uncertainty.as_ref().map_or(String::new(), |u| format!("{}", u.k)),
            row.uncertainty.as_ref().map_or(String::new(), |u| u.method.name().to_string()),
            row.applied_rule().map_or(String::new(), |rule| rule.name()),
            num(row.acceptance_limits().and_then(|(lo, _)| lo)),
            num(row.acceptance_limits().map(|(_, hi)| hi)),
        ];
        writeln!(w, "{}", fields.join(","))?;
    }
    w.flush()
}

/// A free-text field quoted when it holds a separator, a quote, a line break
/// or edge spaces (RFC 4180: quotes doubled inside).
pub fn field(text: &str) -> String {
    let needs = text.contains([',', '"', '\n', '\r']) || text.starts_with(' ') || text.ends_with(' ');
    if needs { format!("\"{}\"", text.replace('"', "\"\"")) } else { text.to_string() }
}

/// Header values are single lines.
fn one_line(text: &str) -> String {
    text.replace(['\r', '\n'], " ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::measurement_table::DecisionRule;
    use crate::analysis::measurement_table::{MeasurementKind, MeasurementRow, Tolerance};
    use crate::analysis::profile::{ProfileLine, ProfileSpec, extract_profile};
    use crate::analysis::testing::node_map;
    use crate::analysis::uncertainty::{Contribution, Uncertainty, UncertaintyMethod};

    /// Reads a profile CSV back: header map and rows (NaN for empty z).
    fn parse_profile(text: &str) -> (Vec<(String, String)>, Vec<[f64; 5]>) {
        let mut header = Vec::new();
        let mut rows = Vec::new();
        let mut columns_seen = false;
        for line in text.lines() {
            if let Some(h) = line.strip_prefix("# ") {
                if let Some((k, v)) = h.split_once(": ") {
                    header.push((k.to_string(), v.to_string()));
                }
                continue;
            }
            if !columns_seen {
                assert_eq!(line, PROFILE_COLUMNS);
                columns_seen = true;
                continue;
            }
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), 5, "{line}");
            let num = |s: &str| if s.is_empty() { f64::NAN } else { s.parse::<f64>().unwrap() };
            rows.push([num(f[0]), num(f[1]), num(f[2]), num(f[3]), num(f[4])]);
        }
        (header, rows)
    }

    #[test]
    fn profile_csv_parses_back_to_the_profile() {
        let map = node_map(60, 40, [1.0, 2.0], 0.01, |x, y| {
            ((x - 1.3).abs() > 0.02).then_some(0.01 * (x - 1.0) + 0.002 * (y - 2.0) + 0.1)
        });
        let spec = ProfileSpec {
            name: "across, groove".into(),
            line: ProfileLine::Segment { start_mm: [1.05, 2.1], end_mm: [1.55, 2.3] },
            step_mm: Some(0.004),
            width_mm: 0.03,
            raw_samples: false,
        };
        let profile = extract_profile(&map, &spec).unwrap();
        let mut out = Vec::new();
        write_profile_csv(&mut out, &profile, "/data/gasket 2/manifest.json").unwrap();
        let text = String::from_utf8(out).unwrap();
        let (header, rows) = parse_profile(&text);
        let get = |k: &str| header.iter().find(|(h, _)| h == k).map(|(_, v)| v.clone()).unwrap();
        assert_eq!(get("name"), "across, groove");
        assert_eq!(get("source"), "/data/gasket 2/manifest.json");
        assert_eq!(get("start_mm"), "1.050000, 2.100000");
        assert!(get("interpolation").starts_with("bilinear"));
        assert!(get("averaging_width_mm").starts_with("0.030000 (5 parallel lines)"));
        assert_eq!(rows.len(), profile.samples.len());
        let mut holes = 0;
        for (r, s) in rows.iter().zip(&profile.samples) {
            assert!((r[0] - s.distance_mm).abs() <= 5e-7 && (r[1] - s.x_mm).abs() <= 5e-7);
            assert!((r[2] - s.y_mm).abs() <= 5e-7 && r[4] == f64::from(s.n));
            if s.n == 0 {
                assert!(r[3].is_nan());
                holes += 1;
            } else {
                assert!((r[3] - s.z_um).abs() <= 5e-5, "{} vs {}", r[3], s.z_um);
            }
        }
        assert!(holes > 0, "the test line crosses the hole");
    }

    #[test]
    fn measurement_csv_quotes_text_and_states_verdicts() {
        let mut table = MeasurementTable::default();
        table.push(
            MeasurementRow::new("step \"A\", left", MeasurementKind::StepHeight, Some(20.12346), "um")
                .with_tolerance(Some(20.0), Some(Tolerance::symmetric(0.5)))
                .with_note("n=100")
                .with_decision_rule(DecisionRule::Iso14253)
                .with_uncertainty(Some(Uncertainty::from_budget(
                    UncertaintyMethod::Propagation,
                    vec![Contribution::new("noise", 0.1)],
                ))),
        );
        table.push(
            MeasurementRow::new("flat", MeasurementKind::FlatnessPeakToValley, None, "um")
                .with_tolerance(None, Some(Tolerance { lower: 0.0, upper: 3.0 }))
                .with_note("region 'x' covers 0 valid samples"),
        );
        let mut out = Vec::new();
        write_measurement_csv(&mut out, &table, "part.ply").unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[2], "# overall verdict: fail");
        assert_eq!(lines[3], MEASUREMENT_COLUMNS);
        // u, U = 2u, k, how, the rule and the limits shrunk by U.
        assert_eq!(
            lines[4],
            "\"step \"\"A\"\", left\",step_height,20.1235,um,20.0000,19.5000,20.5000,pass,n=100,,\
             0.1000,0.2000,2,propagation,iso-14253-1,19.7000,20.3000"
        );
        // No rule stated: simple acceptance; a one-sided limit has no lower acceptance limit.
        assert_eq!(
            lines[5],
            "flat,flatness_peak_to_valley,,um,,0.0000,3.0000,fail,region 'x' covers 0 valid samples,,,,,,simple,,3.0000"
        );
        // A texture row names its parameter in the last column.
        let mut table = MeasurementTable::default();
        table.push(MeasurementRow::new("seal Sa", MeasurementKind::Texture, Some(0.25), "um").with_parameter("Sa"));
        let mut out = Vec::new();
        write_measurement_csv(&mut out, &table, "part.ply").unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(text.lines().nth(4), Some("seal Sa,texture,0.2500,um,,,,,,Sa,,,,,,,"));
    }
}
