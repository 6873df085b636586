//! An error and its causes as one line for people, shared by the CLI and
//! the app.

/// `a: b: c` as anyhow's `{:#}` prints a chain, but without a cause whose
/// text its parent already shows: many errors here name their source in
/// their own message (`cannot read F: No such file or directory`), and the
/// chain would print it a second time.
pub fn error_chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot read {path}: {source}")]
    struct ReadError {
        path: &'static str,
        source: std::io::Error,
    }

    #[test]
    fn causes_follow_once() {
        let io = || std::io::Error::other("disk full");
        let plain = anyhow::Error::new(io()).context("writing cloud.ply");
        assert_eq!(error_chain(&plain), "writing cloud.ply: disk full");
        // The source is in the message already: `{:#}` would repeat it.
        let named = anyhow::Error::new(ReadError { path: "m.json", source: io() }).context("opening the set");
        assert_eq!(format!("{named:#}"), "opening the set: cannot read m.json: disk full: disk full");
        assert_eq!(error_chain(&named), "opening the set: cannot read m.json: disk full");
    }
}
