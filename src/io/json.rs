//! Reading JSON contracts (manifest, calibration) key by key, so that every
//! fault names the key it is about (`sets[1].images.left`), what was expected
//! and what was found, instead of a generic deserialization message.

use crate::engine::warning::{Warning, WarningKind};
use serde_json::{Map, Value};

/// A fault in a JSON document, located by line/column or by key path.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum JsonFault {
    #[error("is not valid JSON at line {line}, column {column}: {message}; fix the syntax (a missing comma or quote?)")]
    Syntax { line: usize, column: usize, message: String },
    #[error("lacks the key '{key}'{hint}")]
    MissingKey { key: String, hint: &'static str },
    #[error("must be a JSON object ({{...}}), found {found}")]
    NotAnObject { found: String },
    #[error("'{key}' must be {expected}, found {found}")]
    WrongType { key: String, expected: &'static str, found: String },
}

/// Parses a document; syntax errors carry serde_json's line and column.
pub(crate) fn parse(bytes: &[u8]) -> Result<Value, JsonFault> {
    serde_json::from_slice(bytes).map_err(|e| {
        // serde_json appends " at line L column C"; the fault says it once.
        let text = e.to_string();
        let message = match text.rfind(" at line ") {
            Some(i) => text[..i].to_string(),
            None => text,
        };
        JsonFault::Syntax { line: e.line(), column: e.column(), message }
    })
}

/// Joins a key path: `child("sets[1]", "period")` is `sets[1].period`.
pub(crate) fn child(path: &str, key: &str) -> String {
    if path.is_empty() { key.to_string() } else { format!("{path}.{key}") }
}

/// A short rendering of a found value for messages (long values are cut).
pub(crate) fn describe(v: &Value) -> String {
    let kind = match v {
        Value::Null => return "null".to_string(),
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "the number",
        Value::String(_) => "the text",
        Value::Array(a) => return format!("a list of {} item(s)", a.len()),
        Value::Object(_) => return "an object".to_string(),
    };
    let mut text = v.to_string();
    if text.chars().count() > 40 {
        text = text.chars().take(37).collect::<String>() + "...";
    }
    format!("{kind} {text}")
}

pub(crate) fn wrong(key: &str, expected: &'static str, v: &Value) -> JsonFault {
    JsonFault::WrongType { key: key.to_string(), expected, found: describe(v) }
}

pub(crate) fn as_object<'a>(v: &'a Value, key: &str) -> Result<&'a Map<String, Value>, JsonFault> {
    v.as_object().ok_or_else(|| {
        if key.is_empty() { JsonFault::NotAnObject { found: describe(v) } } else { wrong(key, "an object", v) }
    })
}

pub(crate) fn require<'a>(
    map: &'a Map<String, Value>,
    path: &str,
    key: &str,
    hint: &'static str,
) -> Result<&'a Value, JsonFault> {
    map.get(key).ok_or_else(|| JsonFault::MissingKey { key: child(path, key), hint })
}

pub(crate) fn number(v: &Value, key: &str) -> Result<f64, JsonFault> {
    v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| wrong(key, "a number", v))
}

/// An integer; integral floats (`12.0`, as some tools write) are accepted.
pub(crate) fn integer(v: &Value, key: &str, expected: &'static str) -> Result<i64, JsonFault> {
    if let Some(i) = v.as_i64() {
        return Ok(i);
    }
    match v.as_f64() {
        Some(x) if x.fract() == 0.0 && x.abs() < 9.0e15 => Ok(x as i64),
        _ => Err(wrong(key, expected, v)),
    }
}

pub(crate) fn string<'a>(v: &'a Value, key: &str) -> Result<&'a str, JsonFault> {
    v.as_str().ok_or_else(|| wrong(key, "a text", v))
}

pub(crate) fn array<'a>(v: &'a Value, key: &str, expected: &'static str) -> Result<&'a [Value], JsonFault> {
    v.as_array().map(Vec::as_slice).ok_or_else(|| wrong(key, expected, v))
}

/// Adds a warning for each key of `map` that is not in `known`: a typo in an
/// optional key would otherwise be ignored silently.
pub(crate) fn warn_unknown_keys(
    map: &Map<String, Value>,
    path: &str,
    known: &[&str],
    file: &str,
    warnings: &mut Vec<Warning>,
) {
    for key in map.keys().filter(|k| !known.contains(&k.as_str())) {
        warnings.push(Warning::new(
            WarningKind::IgnoredInput,
            format!(
                "{file}: unknown key '{}' ignored (a typo? known keys here: {})",
                child(path, key),
                known.join(", ")
            ),
        ));
    }
}

/// Runs `check` on `cases` inputs drawn from `strategy` and returns how many
/// it accepted (`Ok(true)`) and refused (`Ok(false)`): a property over a
/// parser's accepted inputs proves nothing unless some were accepted.
#[cfg(test)]
pub(crate) fn count_outcomes<S: proptest::strategy::Strategy>(
    cases: u32,
    strategy: &S,
    check: impl Fn(S::Value) -> Result<bool, proptest::test_runner::TestCaseError>,
) -> (usize, usize) {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let (accepted, refused) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let config = proptest::test_runner::Config { cases, failure_persistence: None, ..Default::default() };
    let outcome = proptest::test_runner::TestRunner::new(config).run(strategy, |input| {
        let counter = if check(input)? { &accepted } else { &refused };
        counter.fetch_add(1, Ordering::Relaxed);
        Ok(())
    });
    if let Err(e) = outcome {
        panic!("{e}");
    }
    (accepted.into_inner(), refused.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn syntax_error_has_line_and_column_once() {
        let e = parse(b"{\n  \"a\": 1\n  \"b\": 2\n}").unwrap_err();
        let JsonFault::Syntax { line, column, ref message } = e else { panic!("{e:?}") };
        assert_eq!((line, column), (3, 3));
        assert!(!message.contains("at line"), "{message}");
        assert!(e.to_string().contains("line 3, column 3"), "{e}");
    }

    #[test]
    fn written_numbers_read_back_to_the_same_f64() {
        // A calibration's P read 1 ulp off (186.47321184579343 came back as
        // ...346) before serde_json's float_roundtrip: files must reproduce
        // the model that was written, bit for bit.
        let awkward =
            [186.47321184579343, 136.99732879259437, 26.417286463964658, 0.0038048659483538604, 9.58853857734406e-6];
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut values = awkward.to_vec();
        for _ in 0..2000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            values.push(f64::from_bits(state >> 2) % 1e3);
        }
        let text = serde_json::to_string(&values).unwrap();
        let back = parse(text.as_bytes()).unwrap();
        let back: Vec<f64> = back.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        for (a, b) in values.iter().zip(&back) {
            assert_eq!(a.to_bits(), b.to_bits(), "{a} read back as {b}");
        }
    }

    #[test]
    fn integers_accept_integral_floats_only() {
        assert_eq!(integer(&serde_json::json!(12), "k", "an integer"), Ok(12));
        assert_eq!(integer(&serde_json::json!(12.0), "k", "an integer"), Ok(12));
        let e = integer(&serde_json::json!(12.5), "sets[0].shifts", "an integer").unwrap_err();
        assert_eq!(e.to_string(), "'sets[0].shifts' must be an integer, found the number 12.5");
        let e = integer(&serde_json::json!("12"), "k", "an integer").unwrap_err();
        assert!(e.to_string().ends_with("found the text \"12\""), "{e}");
    }

    #[test]
    fn unknown_keys_are_named_with_their_path() {
        let v = serde_json::json!({"period": 1, "perod": 2});
        let mut w = Vec::new();
        warn_unknown_keys(v.as_object().unwrap(), "sets[2]", &["period"], "m.json", &mut w);
        assert_eq!(w.len(), 1);
        assert_eq!(w[0].kind, WarningKind::IgnoredInput);
        assert!(w[0].message.contains("'sets[2].perod'") && w[0].message.contains("m.json"), "{}", w[0]);
    }
}
