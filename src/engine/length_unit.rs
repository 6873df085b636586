//! The length units a calibration (and so every cloud and map made with it)
//! may be in: one table, so that no converter knows a unit another forgets
//! (a calibration in nm once switched the height-uncertainty limit off).

use std::fmt;
use std::str::FromStr;

/// A length unit of world coordinates. Files carry it as its name
/// ([`LengthUnit::as_str`]; serde too), so JSON formats keep their strings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LengthUnit {
    M,
    /// What Sheen's rigs are calibrated in, and what a file without a unit means.
    #[default]
    Mm,
    Um,
    Nm,
}

/// A unit name that is no length Sheen knows.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unit '{found}' is not a length Sheen knows; write \"mm\", \"um\" (or \"µm\"), \"nm\" or \"m\"")]
pub struct UnknownLengthUnit {
    pub found: String,
}

impl LengthUnit {
    /// Millimetres in one of this unit.
    pub fn mm_per_unit(self) -> f64 {
        match self {
            Self::M => 1e3,
            Self::Mm => 1.0,
            Self::Um => 1e-3,
            Self::Nm => 1e-6,
        }
    }

    /// Micrometres in one of this unit (height figures are quoted in µm).
    pub fn um_per_unit(self) -> f64 {
        self.mm_per_unit() * 1e3
    }

    /// The name written to files ("um" rather than "µm", so ASCII readers cope).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::M => "m",
            Self::Mm => "mm",
            Self::Um => "um",
            Self::Nm => "nm",
        }
    }
}

impl FromStr for LengthUnit {
    type Err = UnknownLengthUnit;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "m" => Ok(Self::M),
            "mm" => Ok(Self::Mm),
            "um" | "µm" | "μm" => Ok(Self::Um),
            "nm" => Ok(Self::Nm),
            _ => Err(UnknownLengthUnit { found: s.to_string() }),
        }
    }
}

impl serde::Serialize for LengthUnit {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> serde::Deserialize<'de> for LengthUnit {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

impl fmt::Display for LengthUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_parses_to_its_factor_and_writes_back() {
        let cases = [("m", 1e3), ("mm", 1.0), ("um", 1e-3), ("µm", 1e-3), ("nm", 1e-6)];
        for (name, mm) in cases {
            let unit: LengthUnit = name.parse().unwrap();
            assert_eq!(unit.mm_per_unit(), mm, "{name}");
            assert_eq!(unit.um_per_unit(), mm * 1e3, "{name}");
            let written: LengthUnit = unit.to_string().parse().unwrap();
            assert_eq!(written, unit, "{name} round trip");
        }
    }

    #[test]
    fn an_unknown_name_is_refused_and_named() {
        let err = "inch".parse::<LengthUnit>().unwrap_err();
        assert_eq!(err.found, "inch");
        assert!(err.to_string().contains("'inch'"));
        assert_eq!(
            "MM".parse::<LengthUnit>().map_err(|e| e.found),
            Err("MM".to_string()),
            "names are case-sensitive, as the file contract says"
        );
    }

    #[test]
    fn serde_keeps_the_names_files_always_had() {
        for unit in [LengthUnit::M, LengthUnit::Mm, LengthUnit::Um, LengthUnit::Nm] {
            let text = serde_json::to_string(&unit).unwrap();
            assert_eq!(text, format!("\"{}\"", unit.as_str()));
            assert_eq!(serde_json::from_str::<LengthUnit>(&text).unwrap(), unit);
        }
        assert_eq!(serde_json::from_str::<LengthUnit>("\"µm\"").unwrap(), LengthUnit::Um);
        let err = serde_json::from_str::<LengthUnit>("\"inch\"").unwrap_err();
        assert!(err.to_string().contains("'inch'"), "{err}");
    }
}
