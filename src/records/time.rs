//! Record times: stored as RFC 3339 UTC with microseconds and a `Z`, one
//! fixed width (`2026-12-03T18:26:19.000000Z`), so text order is time order
//! in SQLite and PostgreSQL alike; shown and filtered in local time unless
//! an offset is given.

use chrono::{
    DateTime, Duration, FixedOffset, Local, LocalResult, NaiveDate, NaiveDateTime, SubsecRound, TimeZone, Utc,
};

/// The stored form's format.
const STORED: &str = "%Y-%m-%dT%H:%M:%S%.6fZ";

/// Now, to the stored resolution (a microsecond), so a record reads back
/// as it was written.
pub fn now_utc() -> DateTime<Utc> {
    Utc::now().trunc_subsecs(6)
}

/// An instant in the stored form.
pub fn stored(t: DateTime<Utc>) -> String {
    t.format(STORED).to_string()
}

/// A stored time read back.
pub fn parse_stored(text: &str) -> Option<DateTime<Utc>> {
    DateTime::parse_from_rfc3339(text).ok().map(|t| t.with_timezone(&Utc))
}

/// A record's time as local time with its offset, to the second, for tables.
pub fn local_display(t: &DateTime<Utc>) -> String {
    t.with_timezone(&Local).format("%Y-%m-%d %H:%M:%S %:z").to_string()
}

/// Why a date given as a range bound is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DateError {
    #[error("'{0}' is not an ISO 8601 date or date-time (2026-12-03, 2026-12-03T14:00, 2026-12-03T14:00:00+02:00)")]
    NotIso8601(String),
    #[error("'{0}' does not exist in local time (the clock skipped it); give an offset")]
    SkippedLocalTime(String),
}

/// Which end of a range a date bounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RangeEnd {
    /// `--since`: from this instant on (inclusive).
    Since,
    /// `--until`: up to and including this instant, or this whole day for a
    /// date without a time.
    Until,
}

/// An ISO 8601 date or date-time (`2026-12-03`, `2026-12-03T14:00`,
/// `2026-12-03 14:00:30.5`, with `Z`, `+02:00` or `+0200` for an offset,
/// else local time) as the bound the filter compares with: `since`
/// inclusive, `until` exclusive (the next day's midnight for a date, one
/// microsecond, the stored resolution, after a date-time).
pub fn range_bound(text: &str, end: RangeEnd) -> Result<DateTime<Utc>, DateError> {
    let t = text.trim();
    let bad = || DateError::NotIso8601(text.to_string());
    if let Ok(date) = NaiveDate::parse_from_str(t, "%Y-%m-%d") {
        let day = match end {
            RangeEnd::Since => date,
            RangeEnd::Until => date.succ_opt().ok_or_else(bad)?,
        };
        let midnight = day.and_hms_opt(0, 0, 0).ok_or_else(bad)?;
        return local_to_utc(midnight, text);
    }
    // One separator between date and time, 'T' or a space.
    let normal: String =
        t.char_indices().map(|(i, c)| if i == 10 && (c == ' ' || c == 't') { 'T' } else { c }).collect();
    let instant = if let Some(with_offset) = parse_with_offset(&normal) {
        with_offset.with_timezone(&Utc)
    } else {
        let naive = ["%Y-%m-%dT%H:%M:%S%.f", "%Y-%m-%dT%H:%M"]
            .iter()
            .find_map(|f| NaiveDateTime::parse_from_str(&normal, f).ok())
            .ok_or_else(bad)?;
        local_to_utc(naive, text)?
    };
    Ok(match end {
        RangeEnd::Since => instant,
        RangeEnd::Until => instant + Duration::microseconds(1),
    })
}

fn parse_with_offset(text: &str) -> Option<DateTime<FixedOffset>> {
    let text = match text.strip_suffix(['Z', 'z']) {
        Some(head) => format!("{head}+00:00"),
        None => text.to_string(),
    };
    ["%Y-%m-%dT%H:%M:%S%.f%:z", "%Y-%m-%dT%H:%M%:z", "%Y-%m-%dT%H:%M:%S%.f%z", "%Y-%m-%dT%H:%M%z"]
        .iter()
        .find_map(|f| DateTime::parse_from_str(&text, f).ok())
}

/// A local wall-clock time as UTC; the earlier instant where the clock was
/// set back, an error inside the hour it skipped.
fn local_to_utc(naive: NaiveDateTime, text: &str) -> Result<DateTime<Utc>, DateError> {
    match Local.from_local_datetime(&naive) {
        LocalResult::Single(t) => Ok(t.with_timezone(&Utc)),
        LocalResult::Ambiguous(earlier, _) => Ok(earlier.with_timezone(&Utc)),
        LocalResult::None => Err(DateError::SkippedLocalTime(text.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_form_is_fixed_width_and_sorts_as_time() {
        let a = stored(Utc.with_ymd_and_hms(2026, 1, 2, 3, 4, 5).single().unwrap());
        assert_eq!(a, "2026-01-02T03:04:05.000000Z");
        let b = stored(Utc.with_ymd_and_hms(2026, 1, 2, 3, 4, 5).single().unwrap() + Duration::microseconds(7));
        assert_eq!(b, "2026-01-02T03:04:05.000007Z");
        assert!(a < b && b.len() == a.len());
        assert_eq!(parse_stored(&b).map(stored).as_deref(), Some(b.as_str()));
        let now = now_utc();
        assert_eq!(parse_stored(&stored(now)), Some(now), "now reads back as written");
    }

    #[test]
    fn offsets_are_honoured() {
        let since = |t| range_bound(t, RangeEnd::Since).map(stored);
        assert_eq!(since("2026-12-03T14:00+02:00").unwrap(), "2026-12-03T12:00:00.000000Z");
        assert_eq!(since("2026-12-03T14:00:30Z").unwrap(), "2026-12-03T14:00:30.000000Z");
        assert_eq!(since("2026-12-03 14:00:30.25-0130").unwrap(), "2026-12-03T15:30:30.250000Z");
        assert_eq!(stored(range_bound("2026-12-03T14:00Z", RangeEnd::Until).unwrap()), "2026-12-03T14:00:00.000001Z");
        for bad in ["03.12.2026", "2026-13-01", "yesterday", "2026-12-03T25:00"] {
            assert_eq!(since(bad).unwrap_err(), DateError::NotIso8601(bad.to_string()));
        }
    }

    #[test]
    fn dates_without_offset_are_local_days() {
        // Whatever the machine's zone: a day's bounds are 24 h apart around
        // local midnight (no DST change on this date in common zones) and
        // `until` a date includes that whole day.
        let since = range_bound("2026-07-15", RangeEnd::Since).unwrap();
        let until = range_bound("2026-07-15", RangeEnd::Until).unwrap();
        let (s, u) = (since, until);
        assert_eq!(u - s, Duration::hours(24));
        assert_eq!(s.with_timezone(&Local).format("%Y-%m-%d %H:%M").to_string(), "2026-07-15 00:00");
    }
}
