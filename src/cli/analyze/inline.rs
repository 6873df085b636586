//! The inline inspection syntax of `sheen analyze`: regions, section lines
//! and measurements given as options, parsed into the same
//! [`InspectionSpec`] types a JSON spec holds, so a production line needs no
//! JSON file and a JSON file and options mean the same thing.
//!
//! Every parse error names the option and the value it came from, and says
//! what form was expected.

use anyhow::{Context, bail};

use std::collections::BTreeMap;

use crate::analysis::inspection::{
    FlatnessStatistic, InspectionSpec, Measure, MeasurementSpec, ParameterLimit, WHOLE_MAP, check_cutoffs,
};
use crate::analysis::measurement_table::Tolerance;
use crate::analysis::profile::{ProfileLine, ProfileSpec};
use crate::analysis::region::{NamedRegion, Region};
use crate::analysis::texture::filter::FormRemoval;
use crate::analysis::texture::measure::ArealParameter;
use crate::analysis::texture::profile_params::ProfileParameter;

/// Where an item of the merged spec came from, for error messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Origin(pub String);

impl Origin {
    pub fn option(option: &str, value: &str) -> Self {
        Self(format!("{option} {value}"))
    }
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// The inline items, each with its option text.
#[derive(Clone, Debug, Default)]
pub struct InlineItems {
    pub regions: Vec<(NamedRegion, Origin)>,
    pub profiles: Vec<(ProfileSpec, Origin)>,
    pub measurements: Vec<(MeasurementSpec, Origin)>,
    pub level_to: Option<(Vec<String>, Origin)>,
}

/// Splits `NAME=REST` at the first '='; the name is trimmed and must not be empty.
fn named<'a>(option: &str, value: &'a str, form: &str) -> anyhow::Result<(String, &'a str)> {
    let Some((name, rest)) = value.split_once('=') else {
        bail!("{option} {value}: expected {form}");
    };
    let name = name.trim();
    if name.is_empty() {
        bail!("{option} {value}: the name before '=' is empty; expected {form}");
    }
    Ok((name.to_string(), rest))
}

/// Comma-separated numbers (spaces allowed), each finite.
fn numbers(option: &str, value: &str, text: &str) -> anyhow::Result<Vec<f64>> {
    text.split(',')
        .map(|t| {
            let t = t.trim();
            match t.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => bail!("{option} {value}: '{t}' is not a number"),
            }
        })
        .collect()
}

fn number(option: &str, value: &str, text: &str) -> anyhow::Result<f64> {
    let t = text.trim();
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => bail!("{option} {value}: '{t}' is not a number"),
    }
}

/// The unit a tolerance's number is in: the row's (heights and lengths in
/// micrometres, tilts in degrees, texture parameters in their own).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LimitUnit {
    Micrometre,
    Degree,
    /// A texture parameter: its own unit, no suffix understood.
    Own,
}

impl LimitUnit {
    fn name(self) -> &'static str {
        match self {
            LimitUnit::Micrometre => "um",
            LimitUnit::Degree => "deg",
            LimitUnit::Own => "",
        }
    }

    /// Unit suffixes and their size in this unit. A bare number is in the
    /// unit itself, as before units were accepted.
    fn suffixes(self) -> &'static [(&'static str, f64)] {
        match self {
            LimitUnit::Micrometre => &[("nm", 1e-3), ("um", 1.0), ("µm", 1.0), ("μm", 1.0), ("mm", 1e3)],
            LimitUnit::Degree => &[
                ("deg", 1.0),
                ("°", 1.0),
                ("mrad", 0.180 / std::f64::consts::PI),
                ("rad", 180.0 / std::f64::consts::PI),
            ],
            LimitUnit::Own => &[],
        }
    }
}

/// A number in `unit`, with an optional unit suffix (`5um`, `0.005mm`,
/// `250 nm`, `0.1deg`): so a tolerance typed in millimetres is read as
/// such, not as micrometres.
fn quantity(option: &str, value: &str, text: &str, unit: LimitUnit) -> anyhow::Result<f64> {
    let t = text.trim();
    for (suffix, size) in unit.suffixes() {
        if let Some(n) = t.strip_suffix(suffix) {
            return Ok(number(option, value, n)? * size);
        }
    }
    let stem = t.trim_end_matches(|c: char| c.is_alphabetic() || c == '°');
    if unit != LimitUnit::Own && stem.len() < t.len() && stem.trim().parse::<f64>().is_ok() {
        let known: Vec<&str> = unit.suffixes().iter().map(|(s, _)| *s).collect();
        bail!(
            "{option} {value}: '{t}' has a unit this limit does not take; give one of {} or a bare number in {}",
            known.join(", "),
            unit.name()
        );
    }
    number(option, value, t)
}

/// Comma-separated region names, none empty.
fn names(option: &str, value: &str, text: &str) -> anyhow::Result<Vec<String>> {
    let list: Vec<String> = text.split(',').map(|n| n.trim().to_string()).collect();
    if list.iter().any(String::is_empty) {
        bail!("{option} {value}: a region name in '{text}' is empty (names are separated by commas)");
    }
    Ok(list)
}

const REGION_FORM: &str =
    "NAME=rect:X0,Y0,X1,Y1, NAME=circle:CX,CY,R or NAME=polygon:X1,Y1,X2,Y2,X3,Y3[,...] (millimetres)";

/// `NAME=rect:x0,y0,x1,y1` | `NAME=circle:cx,cy,r` | `NAME=polygon:x,y,x,y,x,y,...`.
pub fn parse_region(value: &str) -> anyhow::Result<NamedRegion> {
    const OPT: &str = "--region";
    let (name, shape) = named(OPT, value, REGION_FORM)?;
    let Some((kind, coords)) = shape.split_once(':') else {
        bail!("{OPT} {value}: no shape; expected {REGION_FORM}");
    };
    let v = numbers(OPT, value, coords)?;
    let region = match kind.trim().to_ascii_lowercase().as_str() {
        "rect" | "rectangle" => {
            if v.len() != 4 {
                bail!(
                    "{OPT} {value}: a rectangle takes 4 numbers X0,Y0,X1,Y1 (opposite corners, mm), {} given",
                    v.len()
                );
            }
            Region::Rectangle { x_mm: [v[0], v[2]], y_mm: [v[1], v[3]] }
        }
        "circle" => {
            if v.len() != 3 {
                bail!("{OPT} {value}: a circle takes 3 numbers CX,CY,R (centre and radius, mm), {} given", v.len());
            }
            Region::Circle { centre_mm: [v[0], v[1]], radius_mm: v[2] }
        }
        "polygon" | "poly" => {
            if v.len() < 6 || v.len() % 2 != 0 {
                bail!(
                    "{OPT} {value}: a polygon takes X,Y pairs of at least 3 vertices (mm), {} numbers given",
                    v.len()
                );
            }
            Region::Polygon { vertices_mm: v.chunks_exact(2).map(|p| [p[0], p[1]]).collect() }
        }
        other => bail!("{OPT} {value}: unknown shape '{other}'; expected {REGION_FORM}"),
    };
    let named = NamedRegion::new(name, region);
    named.validate().with_context(|| format!("{OPT} {value}"))?;
    Ok(named)
}

/// An optional `@WIDTH_MM` suffix: the text before it and the width (0 without).
fn width_suffix<'a>(option: &str, value: &str, text: &'a str) -> anyhow::Result<(&'a str, f64)> {
    match text.split_once('@') {
        Some((line, w)) => {
            let w = number(option, value, w)?;
            if w < 0.0 {
                bail!("{option} {value}: the averaging width {w} mm is negative");
            }
            Ok((line, w))
        }
        None => Ok((text, 0.0)),
    }
}

const PROFILE_FORM: &str = "NAME=X0,Y0,X1,Y1[@WIDTH_MM] (end points in mm, optional averaging width)";

/// `NAME=x0,y0,x1,y1[@width_mm]`.
pub fn parse_profile(value: &str, step_mm: Option<f64>) -> anyhow::Result<ProfileSpec> {
    const OPT: &str = "--profile";
    let (name, rest) = named(OPT, value, PROFILE_FORM)?;
    let (line, width_mm) = width_suffix(OPT, value, rest)?;
    let v = numbers(OPT, value, line)?;
    if v.len() != 4 {
        bail!("{OPT} {value}: expected {PROFILE_FORM}, got {} numbers", v.len());
    }
    let spec = ProfileSpec {
        name,
        line: ProfileLine::Segment { start_mm: [v[0], v[1]], end_mm: [v[2], v[3]] },
        step_mm,
        width_mm,
        raw_samples: false,
    };
    spec.validate().with_context(|| format!("{OPT} {value}"))?;
    Ok(spec)
}

/// `[NAME=]COORD[@width_mm]` of `--hsection` (COORD = Y) or `--vsection` (COORD = X).
pub fn parse_section(value: &str, horizontal: bool, step_mm: Option<f64>) -> anyhow::Result<ProfileSpec> {
    let (opt, axis) = if horizontal { ("--hsection", "Y") } else { ("--vsection", "X") };
    let form = format!("[NAME=]{axis}_MM[@WIDTH_MM]");
    let (name, rest) = match value.split_once('=') {
        Some((n, r)) if !n.trim().is_empty() => (Some(n.trim().to_string()), r),
        Some(_) => bail!("{opt} {value}: the name before '=' is empty; expected {form}"),
        None => (None, value),
    };
    let (coord, width_mm) = width_suffix(opt, value, rest)?;
    let c = number(opt, value, coord)?;
    let name = name.unwrap_or_else(|| format!("{} {axis}={}", if horizontal { "H" } else { "V" }, coord.trim()));
    let line = if horizontal {
        ProfileLine::Horizontal { through_mm: [0.0, c] }
    } else {
        ProfileLine::Vertical { through_mm: [c, 0.0] }
    };
    let spec = ProfileSpec { name, line, step_mm, width_mm, raw_samples: false };
    spec.validate().with_context(|| format!("{opt} {value}"))?;
    Ok(spec)
}

/// An optional `<=LIMIT` suffix: the text before it and a one-sided tolerance `0..LIMIT`.
fn upper_limit<'a>(
    option: &str,
    value: &str,
    text: &'a str,
    unit: LimitUnit,
) -> anyhow::Result<(&'a str, Option<Tolerance>)> {
    match text.split_once("<=") {
        Some((head, limit)) => {
            let l = quantity(option, value, limit, unit)?;
            if l < 0.0 {
                bail!("{option} {value}: the limit {l} {} is negative", unit.name());
            }
            Ok((head, Some(Tolerance { lower: 0.0, upper: l })))
        }
        None => Ok((text, None)),
    }
}

/// A positive length in mm given as `KEY=MM`.
/// One `KEY=VALUE` or `PARAM<=X` item of `--texture` and `--roughness`:
/// the key, and the upper limit or the value after `=`.
fn split_item<'a>(
    option: &str,
    value: &str,
    expected: &str,
    item: &'a str,
) -> anyhow::Result<(&'a str, Option<&'a str>, Option<&'a str>)> {
    match (item.split_once("<="), item.split_once('=')) {
        (Some((k, x)), _) => Ok((k.trim(), Some(x), None)),
        (None, Some((k, v))) => Ok((k.trim(), None, Some(v))),
        (None, None) => bail!("{option} {value}: '{item}' is not KEY=VALUE or PARAM<=X; expected {expected}"),
    }
}

/// Refuses a key given twice in one item list.
fn once(option: &str, value: &str, key: &str, already_set: bool) -> anyhow::Result<()> {
    if already_set {
        bail!("{option} {value}: '{key}' is given twice");
    }
    Ok(())
}

fn cutoff(option: &str, value: &str, key: &str, text: &str) -> anyhow::Result<f64> {
    let v = number(option, value, text)?;
    if !(v > 0.0) {
        bail!("{option} {value}: {key}={} is not a positive cut-off length in mm", text.trim());
    }
    Ok(v)
}

/// `REGION[<=TOL_UM][,ls=MM]` of `--flatness` (peak to valley) or `--flatness-rms`.
pub fn parse_flatness(value: &str, statistic: FlatnessStatistic) -> anyhow::Result<MeasurementSpec> {
    let opt = match statistic {
        FlatnessStatistic::PeakToValley => "--flatness",
        FlatnessStatistic::Rms => "--flatness-rms",
    };
    const FORM: &str = "REGION[<=TOL_UM][,ls=MM], one region name and an optional S-filter cut-off";
    let mut parts = value.split(',');
    let head = parts.next().unwrap_or_default();
    let mut ls_mm = None;
    for item in parts {
        match item.split_once('=') {
            Some((k, v)) if k.trim().eq_ignore_ascii_case("ls") && ls_mm.is_none() => {
                ls_mm = Some(cutoff(opt, value, "ls", v)?);
            }
            _ => bail!("{opt} {value}: '{}' is not understood; expected {FORM}", item.trim()),
        }
    }
    let (region, tolerance) = upper_limit(opt, value, head, LimitUnit::Micrometre)?;
    let region = region.trim().to_string();
    if region.is_empty() {
        bail!("{opt} {value}: expected {FORM}");
    }
    let name = match statistic {
        FlatnessStatistic::PeakToValley => format!("flatness {region}"),
        FlatnessStatistic::Rms => format!("flatness rms {region}"),
    };
    Ok(MeasurementSpec { name, measure: Measure::Flatness { region, statistic, ls_mm }, nominal: None, tolerance })
}

const TEXTURE_FORM: &str = "NAME=REGION[,form=none|plane|poly:N][,ls=MM][,lc=MM][,c=UM][,mr=PCT][,PARAM<=X]\
                            [,PARAM=NOMINAL±TOL]... (REGION a region name or 'all')";

/// `form=none|plane|poly:N`.
fn parse_form(option: &str, value: &str, text: &str) -> anyhow::Result<FormRemoval> {
    let t = text.trim().to_ascii_lowercase();
    match t.as_str() {
        "none" => return Ok(FormRemoval::None),
        "plane" => return Ok(FormRemoval::Plane),
        _ => {}
    }
    if let Some(n) = t.strip_prefix("poly:").or_else(|| t.strip_prefix("polynomial:")) {
        match n.trim().parse::<u8>() {
            Ok(n) if (1..=10).contains(&n) => return Ok(FormRemoval::Polynomial(n)),
            _ => bail!("{option} {value}: form=poly:{n}: the polynomial order must be a whole number 1 to 10"),
        }
    }
    bail!("{option} {value}: form={}: expected form=none, form=plane or form=poly:N", text.trim())
}

/// A parameter's limit from `PARAM<=X` (`upper = Some(X)`) or `PARAM=NOMINAL±TOL`.
fn parameter_limit(
    option: &str,
    value: &str,
    (name, can_be_negative): (&str, bool),
    upper: Option<&str>,
    target: Option<&str>,
) -> anyhow::Result<ParameterLimit> {
    if let Some(x) = upper {
        if can_be_negative {
            bail!("{option} {value}: {name} can be negative, so '<=' has no lower limit; give {name}=NOMINAL±TOL");
        }
        let x = number(option, value, x)?;
        if x < 0.0 {
            bail!("{option} {value}: the limit {name} <= {x} is negative, but {name} is not");
        }
        return Ok(ParameterLimit { nominal: None, tolerance: Tolerance { lower: 0.0, upper: x } });
    }
    let t = target.unwrap_or_default();
    let (nominal, tolerance) = nominal_and_tolerance(option, value, t, LimitUnit::Own)?;
    let Some(tolerance) = tolerance else {
        bail!("{option} {value}: {name}={} has no tolerance; give {name}<=X or {name}=NOMINAL±TOL", t.trim());
    };
    Ok(ParameterLimit { nominal: Some(nominal), tolerance })
}

/// `NAME=REGION[,form=..][,ls=MM][,lc=MM][,c=UM][,mr=PCT][,PARAM<=X][,PARAM=NOM±TOL]...`.
pub fn parse_texture(value: &str) -> anyhow::Result<MeasurementSpec> {
    const OPT: &str = "--texture";
    let (name, rest) = named(OPT, value, TEXTURE_FORM)?;
    if name.contains([',', '<']) {
        bail!("{OPT} {value}: no measurement name before the region; expected {TEXTURE_FORM}");
    }
    let mut items = rest.split(',');
    let region = items.next().unwrap_or_default().trim().to_string();
    if region.is_empty() || region.contains(['<', '=']) {
        bail!("{OPT} {value}: the region after '=' is missing; expected {TEXTURE_FORM}");
    }
    let (mut form, mut ls_mm, mut lc_mm, mut smr_c_um, mut smc_mr_percent) = (None, None, None, None, None);
    let mut limits: BTreeMap<ArealParameter, ParameterLimit> = BTreeMap::new();
    for item in items {
        let item = item.trim();
        let (key, upper, target) = split_item(OPT, value, TEXTURE_FORM, item)?;
        let once = |set: bool| once(OPT, value, key, set);
        match (key.to_ascii_lowercase().as_str(), target) {
            ("form", Some(v)) => {
                once(form.is_some())?;
                form = Some(parse_form(OPT, value, v)?);
            }
            ("ls", Some(v)) => {
                once(ls_mm.is_some())?;
                ls_mm = Some(cutoff(OPT, value, "ls", v)?);
            }
            ("lc", Some(v)) => {
                once(lc_mm.is_some())?;
                lc_mm = Some(cutoff(OPT, value, "lc", v)?);
            }
            ("c", Some(v)) => {
                once(smr_c_um.is_some())?;
                smr_c_um = Some(number(OPT, value, v)?);
            }
            ("mr", Some(v)) => {
                once(smc_mr_percent.is_some())?;
                let mr = number(OPT, value, v)?;
                if !(0.0..=100.0).contains(&mr) {
                    bail!("{OPT} {value}: mr={mr} is outside 0..100 %");
                }
                smc_mr_percent = Some(mr);
            }
            _ => {
                let Some(p) = ArealParameter::from_name(key) else {
                    bail!(
                        "{OPT} {value}: unknown parameter or key '{key}'; keys: form, ls, lc, c, mr; parameters: {}",
                        ArealParameter::names()
                    );
                };
                once(limits.contains_key(&p))?;
                limits.insert(p, parameter_limit(OPT, value, (p.name(), p.can_be_negative()), upper, target)?);
            }
        }
    }
    check_cutoffs(ls_mm, lc_mm).map_err(|e| anyhow::anyhow!("{OPT} {value}: {e}"))?;
    Ok(MeasurementSpec {
        name,
        measure: Measure::Texture {
            region,
            form: form.unwrap_or(FormRemoval::Plane),
            ls_mm,
            lc_mm,
            smr_c_um,
            smc_mr_percent,
            limits,
        },
        nominal: None,
        tolerance: None,
    })
}

/// `=NOMINAL`, `=NOMINAL±TOL`, `=NOMINAL+-TOL` or `=NOMINAL+UPPER-LOWER`,
/// each number in `unit` or with a unit suffix it takes.
fn nominal_and_tolerance(
    option: &str,
    value: &str,
    text: &str,
    unit: LimitUnit,
) -> anyhow::Result<(f64, Option<Tolerance>)> {
    let text = text.trim();
    let form = "NOMINAL, NOMINAL±TOL, NOMINAL+-TOL or NOMINAL+UPPER-LOWER";
    let number = |option: &str, value: &str, t: &str| quantity(option, value, t, unit);
    for sep in ["±", "+-", "+/-"] {
        if let Some((n, t)) = text.split_once(sep) {
            let t = number(option, value, t)?;
            return Ok((number(option, value, n)?, Some(Tolerance::symmetric(t))));
        }
    }
    // Asymmetric: the nominal may itself be negative, so look for '+' after its first character.
    if let Some(plus) = text.char_indices().skip(1).find(|(_, c)| *c == '+').map(|(i, _)| i) {
        let (n, rest) = (&text[..plus], &text[plus + 1..]);
        let Some((up, down)) = rest.split_once('-') else {
            bail!("{option} {value}: '{text}' has an upper deviation but no '-LOWER'; expected {form}");
        };
        let (up, down) = (number(option, value, up)?, number(option, value, down)?);
        let tolerance = Tolerance { lower: -down, upper: up };
        if !(tolerance.lower <= tolerance.upper) {
            bail!("{option} {value}: tolerance +{up}-{down} {} is not an interval", unit.name());
        }
        return Ok((number(option, value, n)?, Some(tolerance)));
    }
    number(option, value, text)
        .map(|v| (v, None))
        .map_err(|_| anyhow::anyhow!("{option} {value}: '{text}' is not {form}"))
}

const STEP_FORM: &str = "NAME=REF[,REF...]:MEAS[,MEAS...][=NOMINAL±TOL_UM]";

/// `NAME=REF_REGIONS:MEAS_REGIONS[=NOMINAL±TOL_UM]`.
pub fn parse_step(value: &str) -> anyhow::Result<MeasurementSpec> {
    const OPT: &str = "--step";
    let (name, rest) = named(OPT, value, STEP_FORM)?;
    let (regions, target) = match rest.split_once('=') {
        Some((r, t)) => (r, Some(t)),
        None => (rest, None),
    };
    let Some((reference, measured)) = regions.split_once(':') else {
        bail!("{OPT} {value}: reference and measured regions must be separated by ':'; expected {STEP_FORM}");
    };
    let (nominal, tolerance) = match target {
        Some(t) => {
            let (n, tol) = nominal_and_tolerance(OPT, value, t, LimitUnit::Micrometre)?;
            (Some(n), tol)
        }
        None => (None, None),
    };
    Ok(MeasurementSpec {
        name,
        measure: Measure::StepHeight {
            reference: names(OPT, value, reference)?,
            measured: names(OPT, value, measured)?,
        },
        nominal,
        tolerance,
    })
}

/// `NAME=R1,R2[,...][<=TOL_UM]`.
pub fn parse_coplanarity(value: &str) -> anyhow::Result<MeasurementSpec> {
    const OPT: &str = "--coplanarity";
    let (name, rest) = named(OPT, value, "NAME=LAND1,LAND2[,...][<=TOL_UM]")?;
    let (lands, tolerance) = upper_limit(OPT, value, rest, LimitUnit::Micrometre)?;
    let lands = names(OPT, value, lands)?;
    if lands.len() < 2 {
        bail!("{OPT} {value}: coplanarity needs at least two lands (region names separated by commas)");
    }
    Ok(MeasurementSpec { name, measure: Measure::Coplanarity { lands }, nominal: None, tolerance })
}

/// `NAME=R1[,R2...][<=TOL_DEG]`.
pub fn parse_tilt(value: &str) -> anyhow::Result<MeasurementSpec> {
    const OPT: &str = "--tilt";
    let (name, rest) = named(OPT, value, "NAME=REGION[,REGION...][<=TOL_DEG]")?;
    let (regions, tolerance) = upper_limit(OPT, value, rest, LimitUnit::Degree)?;
    Ok(MeasurementSpec {
        name,
        measure: Measure::Tilt { regions: names(OPT, value, regions)? },
        nominal: None,
        tolerance,
    })
}

const ROUGHNESS_FORM: &str = "PROFILE[,ls=MM][,lc=MM|lc=rsm][,c=UM][,PARAM<=X][,PARAM=NOMINAL±TOL]... \
                              (PROFILE a profile's name; lc=rsm: a periodic profile, λc from RSm; PARAM Ra, Rq, Rsk, Rku, Rp, Rv, Rz, Rt, RSm, Rdq, Rmr, Rdc or the same \
                              with P or W)";

/// `PROFILE[,ls=MM][,lc=MM][,c=UM][,PARAM<=X][,PARAM=NOM±TOL]...` of `--roughness`.
pub fn parse_roughness(value: &str) -> anyhow::Result<MeasurementSpec> {
    const OPT: &str = "--roughness";
    let mut items = value.split(',');
    let profile = items.next().unwrap_or_default().trim().to_string();
    if profile.is_empty() || profile.contains(['<', '=']) {
        bail!("{OPT} {value}: the profile name comes first; expected {ROUGHNESS_FORM}");
    }
    let (mut ls_mm, mut lc_mm, mut c_um, mut periodic) = (None, None, None, false);
    let mut limits: BTreeMap<ProfileParameter, ParameterLimit> = BTreeMap::new();
    for item in items {
        let item = item.trim();
        let (key, upper, target) = split_item(OPT, value, ROUGHNESS_FORM, item)?;
        let once = |set: bool| once(OPT, value, key, set);
        match (key.to_ascii_lowercase().as_str(), target) {
            ("ls", Some(v)) => {
                once(ls_mm.is_some())?;
                ls_mm = Some(cutoff(OPT, value, "ls", v)?);
            }
            ("lc", Some(v)) if v.trim().eq_ignore_ascii_case("rsm") => {
                once(lc_mm.is_some() || periodic)?;
                periodic = true;
            }
            ("lc", Some(v)) => {
                once(lc_mm.is_some() || periodic)?;
                lc_mm = Some(cutoff(OPT, value, "lc", v)?);
            }
            ("c", Some(v)) => {
                once(c_um.is_some())?;
                c_um = Some(number(OPT, value, v)?);
            }
            _ => {
                let Some(p) = ProfileParameter::from_name(key) else {
                    bail!(
                        "{OPT} {value}: unknown parameter or key '{key}'; keys: ls, lc, c; parameters: {}",
                        ProfileParameter::names()
                    );
                };
                once(limits.contains_key(&p))?;
                limits.insert(p, parameter_limit(OPT, value, (&p.name(), p.can_be_negative()), upper, target)?);
            }
        }
    }
    check_cutoffs(ls_mm, lc_mm).map_err(|e| anyhow::anyhow!("{OPT} {value}: {e}"))?;
    Ok(MeasurementSpec {
        name: profile.clone(),
        measure: Measure::ProfileTexture { profile, ls_mm, lc_mm, c_um, periodic, limits },
        nominal: None,
        tolerance: None,
    })
}

/// `--level R1[,R2...]`.
pub fn parse_level(value: &str) -> anyhow::Result<Vec<String>> {
    names("--level", value, value)
}

/// Merges inline items into `base` (from a spec or session file, whose items
/// carry `base_origin`): an inline item replaces a file item of the same name
/// (so a line can adjust one region of a shared spec), `--level` replaces the
/// file's levelling, and `pitch_mm` overrides the file's pitch. Returns the
/// spec and the origin of every region, profile and measurement by name.
pub fn merge(
    mut base: InspectionSpec,
    base_origin: &Origin,
    inline: InlineItems,
    pitch_mm: Option<f64>,
) -> (InspectionSpec, Origins) {
    let mut origins = Origins::default();
    for r in &base.regions {
        origins.regions.push((r.name.clone(), base_origin.clone()));
    }
    for m in &base.measurements {
        origins.measurements.push((m.name.clone(), base_origin.clone()));
    }
    for p in &base.profiles {
        origins.profiles.push((p.name.clone(), base_origin.clone()));
    }
    origins.level = base_origin.clone();
    fn upsert<T>(list: &mut Vec<T>, item: T, same: impl Fn(&T) -> bool) {
        match list.iter_mut().find(|x| same(x)) {
            Some(slot) => *slot = item,
            None => list.push(item),
        }
    }
    fn set_origin(list: &mut Vec<(String, Origin)>, name: &str, origin: Origin) {
        match list.iter_mut().find(|(n, _)| n == name) {
            Some(slot) => slot.1 = origin,
            None => list.push((name.to_string(), origin)),
        }
    }
    for (r, o) in inline.regions {
        set_origin(&mut origins.regions, &r.name, o);
        let name = r.name.clone();
        upsert(&mut base.regions, r, |x| x.name == name);
    }
    for (p, o) in inline.profiles {
        set_origin(&mut origins.profiles, &p.name, o);
        let name = p.name.clone();
        upsert(&mut base.profiles, p, |x| x.name == name);
    }
    for (m, o) in inline.measurements {
        set_origin(&mut origins.measurements, &m.name, o);
        let name = m.name.clone();
        upsert(&mut base.measurements, m, |x| x.name == name);
    }
    if let Some((level, o)) = inline.level_to {
        base.level_to = level;
        origins.level = o;
    }
    if pitch_mm.is_some() {
        base.height_map.pitch_mm = pitch_mm;
    }
    (base, origins)
}

/// Where each named item of a merged spec came from.
#[derive(Clone, Debug, Default)]
pub struct Origins {
    pub regions: Vec<(String, Origin)>,
    pub profiles: Vec<(String, Origin)>,
    pub measurements: Vec<(String, Origin)>,
    pub level: Origin,
}

impl Default for Origin {
    fn default() -> Self {
        Self("the command line".into())
    }
}

impl Origins {
    fn find<'a>(list: &'a [(String, Origin)], name: &str) -> Option<&'a Origin> {
        list.iter().find(|(n, _)| n == name).map(|(_, o)| o)
    }
    pub fn region(&self, name: &str) -> Option<&Origin> {
        Self::find(&self.regions, name)
    }
    pub fn profile(&self, name: &str) -> Option<&Origin> {
        Self::find(&self.profiles, name)
    }
    pub fn measurement(&self, name: &str) -> Option<&Origin> {
        Self::find(&self.measurements, name)
    }
}

/// Checks every region a measurement or the levelling names is defined,
/// naming the option (or file) that used an undefined one.
pub fn check_references(spec: &InspectionSpec, origins: &Origins) -> anyhow::Result<()> {
    let defined = || {
        if spec.regions.is_empty() {
            "none (define one with --region NAME=rect:X0,Y0,X1,Y1)".to_string()
        } else {
            spec.regions.iter().map(|r| format!("'{}'", r.name)).collect::<Vec<_>>().join(", ")
        }
    };
    let known = |n: &String| spec.regions.iter().any(|r| &r.name == n);
    for n in &spec.level_to {
        if !known(n) {
            bail!("{}: levelling region '{n}' is not defined; defined regions: {}", origins.level, defined());
        }
    }
    for m in &spec.measurements {
        let used: Vec<&String> = match &m.measure {
            Measure::StepHeight { reference, measured } => reference.iter().chain(measured).collect(),
            Measure::Flatness { region, .. } => vec![region],
            Measure::Coplanarity { lands } => lands.iter().collect(),
            Measure::Tilt { regions } => regions.iter().collect(),
            Measure::Texture { region, .. } => [region].into_iter().filter(|r| r.as_str() != WHOLE_MAP).collect(),
            Measure::ProfileTexture { profile, .. } => {
                if !spec.profiles.iter().any(|p| &p.name == profile) {
                    let origin = origins.measurement(&m.name).cloned().unwrap_or_default();
                    let defined = if spec.profiles.is_empty() {
                        "none (define one with --profile, --hsection or --vsection)".to_string()
                    } else {
                        spec.profiles.iter().map(|p| format!("'{}'", p.name)).collect::<Vec<_>>().join(", ")
                    };
                    bail!("{origin}: profile '{profile}' is not defined; defined profiles: {defined}");
                }
                Vec::new()
            }
        };
        if let Some(n) = used.into_iter().find(|n| !known(n)) {
            let origin = origins.measurement(&m.name).cloned().unwrap_or_default();
            bail!(
                "{origin}: measurement '{}' uses region '{n}', which is not defined; defined regions: {}",
                m.name,
                defined()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_parse_in_all_three_shapes() {
        let r = parse_region("base=rect:-11,-8.5,11,-7.5").unwrap();
        assert_eq!(r, NamedRegion::new("base", Region::Rectangle { x_mm: [-11.0, 11.0], y_mm: [-8.5, -7.5] }));
        let c = parse_region("land 2 = circle: 3, 0.5, 0.4").unwrap();
        assert_eq!(c, NamedRegion::new("land 2", Region::Circle { centre_mm: [3.0, 0.5], radius_mm: 0.4 }));
        let p = parse_region("tri=polygon:0,0,1,0,0.5,1").unwrap();
        assert_eq!(p.region, Region::Polygon { vertices_mm: vec![[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]] });
    }

    #[test]
    fn bad_regions_name_the_option_and_the_fault() {
        for (value, expected) in [
            ("base", "expected NAME=rect"),
            ("=rect:0,0,1,1", "name before '=' is empty"),
            ("base=rect:0,0,1", "takes 4 numbers"),
            ("base=rect:0,0,x,1", "'x' is not a number"),
            ("base=square:0,0,1,1", "unknown shape 'square'"),
            ("base=circle:0,0,-1", "radius"),
            ("base=polygon:0,0,1,1,2", "X,Y pairs"),
            ("base=rect:0,0,0,1", "no area"),
            ("base=0,0,1,1", "no shape"),
        ] {
            let e = format!("{:#}", parse_region(value).unwrap_err());
            assert!(e.starts_with(&format!("--region {value}")), "{e}");
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
    }

    #[test]
    fn profiles_and_sections_parse_with_width() {
        let p = parse_profile("A-A=-3,-4.3,-1,-4.3@0.05", Some(0.01)).unwrap();
        assert_eq!(p.line, ProfileLine::Segment { start_mm: [-3.0, -4.3], end_mm: [-1.0, -4.3] });
        assert_eq!((p.width_mm, p.step_mm), (0.05, Some(0.01)));
        let h = parse_section("-4.3", true, None).unwrap();
        assert_eq!((h.name.as_str(), &h.line), ("H Y=-4.3", &ProfileLine::Horizontal { through_mm: [0.0, -4.3] }));
        let v = parse_section("B=2.5@0.1", false, None).unwrap();
        assert_eq!((v.name.as_str(), v.width_mm), ("B", 0.1));
        let same_point = format!("{:#}", parse_profile("A=0,0,0,0", None).unwrap_err());
        assert!(same_point.contains("--profile A=0,0,0,0") && same_point.contains("same point"), "{same_point}");
        assert!(format!("{:#}", parse_profile("A=0,0,1", None).unwrap_err()).contains("got 3 numbers"));
        assert!(format!("{:#}", parse_section("1@-2", true, None).unwrap_err()).contains("negative"));
    }

    #[test]
    fn measurements_parse_with_tolerances() {
        let s = parse_step("block 1=base,base2:top=50±0.5").unwrap();
        assert_eq!(
            s.measure,
            Measure::StepHeight { reference: vec!["base".into(), "base2".into()], measured: vec!["top".into()] }
        );
        assert_eq!((s.nominal, s.tolerance), (Some(50.0), Some(Tolerance::symmetric(0.5))));
        let s = parse_step("d=a:b=-20+-1").unwrap();
        assert_eq!((s.nominal, s.tolerance), (Some(-20.0), Some(Tolerance::symmetric(1.0))));
        let s = parse_step("d=a:b=-20+0.3-0.5").unwrap();
        assert_eq!((s.nominal, s.tolerance), (Some(-20.0), Some(Tolerance { lower: -0.5, upper: 0.3 })));
        let s = parse_step("d=a:b").unwrap();
        assert_eq!((s.nominal, s.tolerance), (None, None));
        let f = parse_flatness("base<=2", FlatnessStatistic::PeakToValley).unwrap();
        assert_eq!((f.name.as_str(), f.tolerance), ("flatness base", Some(Tolerance { lower: 0.0, upper: 2.0 })));
        let c = parse_coplanarity("lands=a,b,c<=3").unwrap();
        assert_eq!(c.measure, Measure::Coplanarity { lands: vec!["a".into(), "b".into(), "c".into()] });
        for (r, expected) in [
            (parse_step("d=a,b"), "separated by ':'"),
            (parse_step("d=a:b=20±x"), "'x' is not a number"),
            (parse_step("d=a:,b"), "is empty"),
            (parse_coplanarity("c=a"), "at least two lands"),
            (parse_flatness("a<=-1", FlatnessStatistic::Rms), "negative"),
        ] {
            let e = format!("{:#}", r.unwrap_err());
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
    }

    /// Issue 50, item 4: a tolerance may carry its unit; a bare number stays
    /// in the row's unit (um; degrees for a tilt), as before.
    #[test]
    fn tolerances_take_units_and_bare_numbers_keep_the_rows_unit() {
        let upper =
            |text: &str| parse_flatness(text, FlatnessStatistic::PeakToValley).unwrap().tolerance.unwrap().upper;
        for (text, um) in [
            ("plate<=5", 5.0),
            ("plate<=5um", 5.0),
            ("plate<=5 µm", 5.0),
            ("plate<=0.005mm", 5.0),
            ("plate<=250nm", 0.25),
        ] {
            assert!((upper(text) - um).abs() < 1e-12, "{text}: {} um", upper(text));
        }
        let s = parse_step("boss=plate:boss=250um±2um").unwrap();
        assert_eq!((s.nominal, s.tolerance), (Some(250.0), Some(Tolerance::symmetric(2.0))));
        let s = parse_step("boss=plate:boss=0.25mm+2um-0.001mm").unwrap();
        let t = s.tolerance.unwrap();
        assert!(
            (s.nominal.unwrap() - 250.0).abs() < 1e-9 && (t.upper - 2.0).abs() < 1e-12 && (t.lower + 1.0).abs() < 1e-12
        );
        let c = parse_coplanarity("lands=a,b<=0.003mm").unwrap();
        assert!((c.tolerance.unwrap().upper - 3.0).abs() < 1e-12);
        let tilt = parse_tilt("t=a<=2mrad").unwrap().tolerance.unwrap().upper;
        assert!((tilt - 0.114_591_559).abs() < 1e-8, "{tilt} deg");
        assert_eq!(parse_tilt("t=a<=0.1deg").unwrap().tolerance.unwrap().upper, 0.1);
        for (r, expected) in [
            (parse_flatness("plate<=5m", FlatnessStatistic::PeakToValley), "'5m' has a unit this limit does not take"),
            (parse_tilt("t=a<=1um"), "'1um' has a unit this limit does not take"),
            (parse_step("d=a:b=20mm±x"), "'x' is not a number"),
        ] {
            let e = format!("{:#}", r.unwrap_err());
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
    }

    #[test]
    fn inline_items_override_file_items_and_references_are_checked() {
        let mut base = InspectionSpec::default();
        base.regions.push(parse_region("base=rect:0,0,1,1").unwrap());
        base.measurements.push(parse_flatness("base", FlatnessStatistic::Rms).unwrap());
        let file = Origin("--spec lot.json".into());
        let inline = InlineItems {
            regions: vec![
                (parse_region("base=rect:0,0,2,2").unwrap(), Origin::option("--region", "base=rect:0,0,2,2")),
                (parse_region("top=circle:5,5,1").unwrap(), Origin::option("--region", "top=circle:5,5,1")),
            ],
            measurements: vec![(parse_step("h=base:tpo").unwrap(), Origin::option("--step", "h=base:tpo"))],
            ..InlineItems::default()
        };
        let (spec, origins) = merge(base, &file, inline, Some(0.02));
        assert_eq!(spec.regions.len(), 2);
        assert_eq!(spec.regions[0].region, Region::Rectangle { x_mm: [0.0, 2.0], y_mm: [0.0, 2.0] });
        assert_eq!(spec.height_map.pitch_mm, Some(0.02));
        assert_eq!(origins.measurement("flatness rms base"), Some(&file));
        let e = check_references(&spec, &origins).unwrap_err().to_string();
        assert!(e.starts_with("--step h=base:tpo: ") && e.contains("'tpo'") && e.contains("'top'"), "{e}");
    }

    #[test]
    fn texture_and_filtered_flatness_parse_with_limits() {
        let t = parse_texture("seal=face,form=poly:2,ls=0.0025,lc=0.8,Sa<=0.4,sq=0.3±0.05,Ssk=-0.5±0.3,c=-0.1,mr=20")
            .unwrap();
        let Measure::Texture { region, form, ls_mm, lc_mm, smr_c_um, smc_mr_percent, limits } = &t.measure else {
            panic!("{t:?}")
        };
        assert_eq!((t.name.as_str(), region.as_str(), *form), ("seal", "face", FormRemoval::Polynomial(2)));
        assert_eq!((*ls_mm, *lc_mm, *smr_c_um, *smc_mr_percent), (Some(0.0025), Some(0.8), Some(-0.1), Some(20.0)));
        assert_eq!(
            limits[&ArealParameter::Sa],
            ParameterLimit { nominal: None, tolerance: Tolerance { lower: 0.0, upper: 0.4 } }
        );
        assert_eq!(limits[&ArealParameter::Sq].nominal, Some(0.3));
        assert_eq!(limits[&ArealParameter::Ssk].tolerance, Tolerance::symmetric(0.3));
        let all = parse_texture("w=all").unwrap();
        assert!(matches!(all.measure, Measure::Texture { form: FormRemoval::Plane, ls_mm: None, .. }));
        let f = parse_flatness("base<=2,ls=0.025", FlatnessStatistic::PeakToValley).unwrap();
        assert_eq!(
            f.measure,
            Measure::Flatness { region: "base".into(), statistic: FlatnessStatistic::PeakToValley, ls_mm: Some(0.025) }
        );
        assert_eq!(f.tolerance, Some(Tolerance { lower: 0.0, upper: 2.0 }));
        for (r, expected) in [
            (parse_texture("s=face,Sx<=1"), "unknown parameter or key 'Sx'"),
            (parse_texture("s=face,lc=-0.8"), "lc=-0.8 is not a positive cut-off"),
            (parse_texture("s=face,lc=abc"), "'abc' is not a number"),
            (parse_texture("s=face,ls=0.8,lc=0.25"), "must be shorter than the L-filter cut-off"),
            (parse_texture("s=face,form=poly:0"), "order must be a whole number 1 to 10"),
            (parse_texture("s=face,form=sphere"), "form=sphere"),
            (parse_texture("s=face,Ssk<=0.5"), "Ssk can be negative"),
            (parse_texture("s=face,Sa=0.3"), "has no tolerance"),
            (parse_texture("s=face,Sa<=1,sa<=2"), "given twice"),
            (parse_texture("face,Sa<=0.4"), "no measurement name"),
            (parse_texture("s=,Sa<=0.4"), "region after '=' is missing"),
            (parse_texture("s=face,mr=120"), "outside 0..100"),
            (parse_flatness("base,lc=0.8", FlatnessStatistic::Rms), "'lc=0.8' is not understood"),
            (parse_flatness("base,ls=0", FlatnessStatistic::Rms), "not a positive cut-off"),
        ] {
            let e = format!("{:#}", r.unwrap_err());
            assert!(e.starts_with("--texture ") || e.starts_with("--flatness"), "{e}");
            assert!(e.contains(expected), "expected '{expected}' in: {e}");
        }
    }

    #[test]
    fn roughness_parses_with_cutoffs_and_limits() {
        let r = parse_roughness("A-A,ls=0.0025,lc=0.8,Ra<=0.4,rz=2±0.5,Wt<=3,c=-0.2").unwrap();
        let Measure::ProfileTexture { profile, ls_mm, lc_mm, c_um, periodic, limits } = &r.measure else {
            panic!("{r:?}")
        };
        assert_eq!(
            (r.name.as_str(), profile.as_str(), *ls_mm, *lc_mm, *c_um, *periodic),
            ("A-A", "A-A", Some(0.0025), Some(0.8), Some(-0.2), false)
        );
        let r = parse_roughness("A-A,lc=RSm").unwrap();
        assert!(matches!(r.measure, Measure::ProfileTexture { lc_mm: None, periodic: true, .. }), "{r:?}");
        let json = serde_json::to_value(&r.measure).unwrap();
        assert_eq!(json["periodic"], true, "the spec says so: {json}");
        let get = |n: &str| limits[&ProfileParameter::from_name(n).unwrap()];
        assert_eq!(get("Ra").tolerance, Tolerance { lower: 0.0, upper: 0.4 });
        assert_eq!(get("Rz").nominal, Some(2.0));
        assert_eq!(get("Wt").tolerance.upper, 3.0);
        for (r, expected) in [
            (parse_roughness("A,Rx<=1"), "unknown parameter or key 'Rx'"),
            (parse_roughness("A,lc=0"), "not a positive cut-off"),
            (parse_roughness("A,ls=1,lc=0.8"), "must be shorter"),
            (parse_roughness("A,Rsk<=1"), "Rsk can be negative"),
            (parse_roughness("Ra<=1"), "the profile name comes first"),
            (parse_roughness("A,lc=rsm,lc=0.8"), "given twice"),
        ] {
            let e = format!("{:#}", r.unwrap_err());
            assert!(e.starts_with("--roughness ") && e.contains(expected), "expected '{expected}' in: {e}");
        }
    }
}
