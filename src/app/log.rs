//! The session log: every info, warning and error the app reports, in order,
//! with the wall-clock time (UTC) it happened. The log panel shows it; the
//! error banner shows only the latest error.

use std::time::{SystemTime, UNIX_EPOCH};

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Level {
    Info,
    Warning,
    Error,
}

impl Level {
    pub fn name(self) -> &'static str {
        match self {
            Level::Info => "info",
            Level::Warning => "warning",
            Level::Error => "error",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct LogEntry {
    /// "HH:MM:SS" UTC.
    pub time: String,
    pub level: Level,
    pub text: String,
}

/// At most this many entries are kept; the oldest go first.
const MAX_ENTRIES: usize = 2000;

#[derive(Default)]
pub struct LogBook {
    entries: Vec<LogEntry>,
}

impl LogBook {
    pub fn push(&mut self, level: Level, text: impl Into<String>) {
        if self.entries.len() >= MAX_ENTRIES {
            self.entries.drain(..MAX_ENTRIES / 10);
        }
        self.entries.push(LogEntry { time: clock_utc(SystemTime::now()), level, text: text.into() });
    }

    pub fn info(&mut self, text: impl Into<String>) {
        self.push(Level::Info, text);
    }

    pub fn warning(&mut self, text: impl Into<String>) {
        self.push(Level::Warning, text);
    }

    pub fn error(&mut self, text: impl Into<String>) {
        self.push(Level::Error, text);
    }

    pub fn entries(&self) -> &[LogEntry] {
        &self.entries
    }

    pub fn count(&self, level: Level) -> usize {
        self.entries.iter().filter(|e| e.level == level).count()
    }

    pub fn clear(&mut self) {
        self.entries.clear();
    }
}

/// "HH:MM:SS" of a time, in UTC (no time-zone database needed).
fn clock_utc(time: SystemTime) -> String {
    let seconds = time.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let day_s = seconds % 86_400;
    format!("{:02}:{:02}:{:02}", day_s / 3600, day_s % 3600 / 60, day_s % 60)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn clock_is_utc_time_of_day() {
        let t = UNIX_EPOCH + Duration::from_secs(3 * 86_400 + 13 * 3600 + 5 * 60 + 9);
        assert_eq!(clock_utc(t), "13:05:09");
    }

    #[test]
    fn the_log_is_bounded_and_keeps_the_newest() {
        let mut log = LogBook::default();
        for i in 0..MAX_ENTRIES + 5 {
            log.info(format!("entry {i}"));
        }
        assert!(log.entries().len() <= MAX_ENTRIES);
        assert_eq!(log.entries().last().map(|e| e.text.as_str()), Some(format!("entry {}", MAX_ENTRIES + 4).as_str()));
    }
}
