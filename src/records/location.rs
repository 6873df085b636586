//! Where the records are: a SQLite file or a PostgreSQL URL, the default
//! file in the platform's data folder, the folder for the records' height
//! maps, and the PostgreSQL password (URL, `PGPASSWORD` or `.pgpass`), which
//! never appears in anything Sheen prints.

use std::path::{Path, PathBuf};

/// Why `--db` names no store Sheen can use.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LocationError {
    /// A URL of a kind Sheen does not store to; `shown` has no password.
    #[error(
        "--db {shown}: '{scheme}:' is not a records store Sheen knows; give a SQLite file path or a \
         PostgreSQL URL (postgres://user@host/database)"
    )]
    ForeignUrl { shown: String, scheme: String },
    #[error("no data folder is known for this user (HOME unset?); give --db FILE")]
    NoDataFolder,
}

/// The default SQLite file's name in `<data dir>/sheen/`.
pub const DEFAULT_FILE: &str = "records.sqlite";

/// A records store.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DbLocation {
    Sqlite(PathBuf),
    /// A `postgres://` or `postgresql://` URL, possibly with a password.
    Postgres(String),
}

impl DbLocation {
    /// `--db TEXT`: a PostgreSQL URL by its scheme, a file path otherwise.
    /// Text that looks like another kind of URL (`mysql://...`, or
    /// `postgres:/u@h/db` with one slash) is refused: read as a path it
    /// would record into a stray SQLite file in a folder named after the
    /// scheme, and the station's parts would silently miss the shared store.
    pub fn parse(text: &str) -> Result<Self, LocationError> {
        let trimmed = text.trim();
        let lower = trimmed.to_ascii_lowercase();
        if lower.starts_with("postgres://") || lower.starts_with("postgresql://") {
            return Ok(DbLocation::Postgres(trimmed.to_string()));
        }
        if let Some(scheme) = url_scheme(trimmed) {
            return Err(LocationError::ForeignUrl { shown: redact_url(trimmed), scheme: scheme.to_string() });
        }
        Ok(DbLocation::Sqlite(PathBuf::from(text)))
    }

    /// `--db` when given, else the default SQLite file.
    pub fn from_option(db: Option<&str>) -> Result<Self, LocationError> {
        match db {
            Some(text) => Self::parse(text),
            None => Ok(DbLocation::Sqlite(sheen_data_dir()?.join(DEFAULT_FILE))),
        }
    }

    /// The store as it may be printed: a file's path, or the URL with its
    /// password removed.
    pub fn display(&self) -> String {
        match self {
            DbLocation::Sqlite(path) => path.display().to_string(),
            DbLocation::Postgres(url) => redact_url(url),
        }
    }

    /// The folder the records' height maps go to: `records/` beside the
    /// SQLite file (so file and folder move together), or for PostgreSQL
    /// `records_dir` if given, else `records/` in the data folder (a
    /// server cannot hold the station's files).
    pub fn height_map_dir(&self, records_dir: Option<&Path>) -> Result<PathBuf, LocationError> {
        if let Some(dir) = records_dir {
            return Ok(dir.to_path_buf());
        }
        match self {
            DbLocation::Sqlite(path) => {
                let folder = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
                Ok(folder.join("records"))
            }
            DbLocation::Postgres(_) => Ok(sheen_data_dir()?.join("records")),
        }
    }
}

/// `<platform data folder>/sheen` (`~/.local/share/sheen` on Linux, or
/// `$XDG_DATA_HOME/sheen`).
pub fn sheen_data_dir() -> Result<PathBuf, LocationError> {
    dirs::data_dir().map(|d| d.join("sheen")).ok_or(LocationError::NoDataFolder)
}

/// The scheme of text that reads as a URL rather than a path: a scheme of
/// two or more characters (RFC 3986: a letter, then letters, digits, `+`,
/// `-`, `.`; one letter is a Windows drive) followed by `:/`, or a database
/// scheme followed by `:` alone (`postgres:u@h`). A file name such as
/// `line:2.sqlite` stays a path.
fn url_scheme(text: &str) -> Option<&str> {
    const DATABASE_SCHEMES: [&str; 6] = ["postgres", "postgresql", "mysql", "mariadb", "sqlite", "sqlite3"];
    let (scheme, rest) = text.split_once(':')?;
    let mut chars = scheme.chars();
    let well_formed = chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
        && scheme.len() >= 2;
    let database = DATABASE_SCHEMES.contains(&scheme.to_ascii_lowercase().as_str());
    (well_formed && (rest.starts_with('/') || rest.starts_with('\\') || database)).then_some(scheme)
}

/// The URL with any password removed: the user information becomes the
/// user name alone, and a `password=` query parameter is dropped.
///
/// The user information is cut as generously as any reader could take it:
/// up to the *last* `@`. The `postgres` client reads it up to the first
/// `@` whatever comes before, so a password holding an unencoded `/`, `?`
/// or `#` (`u:pa/ss@h`) is still a password to it, and one holding an `@`
/// would leave its tail in the host; cutting at the last `@` removes all of
/// them. A query value with an `@` loses what precedes it in the printed
/// form, which is the safe side.
pub fn redact_url(url: &str) -> String {
    // The scheme and its slashes, however many were typed (`postgres:/u@h`).
    let Some(colon) = url.find(':') else { return url.to_string() };
    let slashes = url[colon + 1..].bytes().take_while(|&b| b == b'/').count();
    let (scheme, rest) = url.split_at(colon + 1 + slashes);
    let (user, rest) = match rest.rfind('@') {
        Some(at) => (rest[..at].split([':', '/', '?', '#']).next().unwrap_or(""), &rest[at..]),
        None => ("", rest),
    };
    let rest = match rest.split_once('?') {
        Some((before, query)) => {
            let kept: Vec<&str> =
                query.split('&').filter(|kv| !kv.to_ascii_lowercase().starts_with("password=")).collect();
            if kept.is_empty() { before.to_string() } else { format!("{before}?{}", kept.join("&")) }
        }
        None => rest.to_string(),
    };
    format!("{scheme}{user}{rest}")
}

/// The password `.pgpass` holds for a connection, by libpq's rules: lines
/// `hostname:port:database:username:password`, `*` matching anything, `\:`
/// and `\\` escapes, `#` comments, the first matching line winning. A
/// socket connection matches the host name `localhost`.
pub fn pgpass_password(text: &str, host: &str, port: u16, database: &str, user: &str) -> Option<String> {
    let port = port.to_string();
    let wanted = [host, port.as_str(), database, user];
    for line in text.lines() {
        if line.trim_start().starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let fields = split_pgpass_line(line);
        if fields.len() < 5 {
            continue;
        }
        if fields[..4].iter().zip(wanted).all(|(f, w)| f == "*" || f == w) {
            return Some(fields[4].clone());
        }
    }
    None
}

/// Splits one `.pgpass` line on unescaped colons (the password, the last
/// field, keeps any further colons as written, as libpq does).
fn split_pgpass_line(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        let last = fields.len() - 1;
        match c {
            '\\' => {
                if let Some(next) = chars.next() {
                    fields[last].push(next);
                }
            }
            ':' if fields.len() < 5 => fields.push(String::new()),
            _ => fields[last].push(c),
        }
    }
    fields
}

/// The `.pgpass` file libpq would read: `PGPASSFILE`, else `~/.pgpass`.
pub fn pgpass_file() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("PGPASSFILE") {
        return Some(PathBuf::from(p));
    }
    dirs::home_dir().map(|h| h.join(".pgpass"))
}

/// Reads the password file, refusing (as libpq does) one that others can
/// read: a password file open to the group or the world is a leak.
pub fn read_pgpass(path: &Path) -> Option<String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(path).ok()?.permissions().mode();
        if mode & 0o077 != 0 {
            eprintln!(
                "warning: password file {} has group or world access; it is ignored (chmod 0600 it)",
                path.display()
            );
            return None;
        }
    }
    std::fs::read_to_string(path).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn db_option_tells_urls_from_files() {
        let parse = |t: &str| DbLocation::parse(t).unwrap();
        assert_eq!(parse("postgres://u@h/db"), DbLocation::Postgres("postgres://u@h/db".into()));
        assert_eq!(parse("PostgreSQL://u@h/db"), DbLocation::Postgres("PostgreSQL://u@h/db".into()));
        assert_eq!(parse("lab/records.sqlite"), DbLocation::Sqlite("lab/records.sqlite".into()));
        assert_eq!(parse("line:2.sqlite"), DbLocation::Sqlite("line:2.sqlite".into()));
        assert_eq!(parse("C:/lab/records.sqlite"), DbLocation::Sqlite("C:/lab/records.sqlite".into()));
        assert_eq!(parse("/srv/qc/records.sqlite"), DbLocation::Sqlite("/srv/qc/records.sqlite".into()));
        let sqlite = DbLocation::Sqlite("lab/line 2/records.sqlite".into());
        assert_eq!(sqlite.height_map_dir(None).unwrap(), PathBuf::from("lab/line 2/records"));
        assert_eq!(DbLocation::Sqlite("r.sqlite".into()).height_map_dir(None).unwrap(), PathBuf::from("./records"));
        let pg = DbLocation::Postgres("postgres://u@h/db".into());
        assert_eq!(pg.height_map_dir(Some(Path::new("/srv/maps"))).unwrap(), PathBuf::from("/srv/maps"));
    }

    #[test]
    fn urls_of_other_stores_or_mistyped_ones_are_refused_not_made_into_files() {
        for (text, scheme) in [
            ("mysql://x@y/z", "mysql"),
            ("postgres:/u@host/db", "postgres"),
            ("postgresql:u@host/db", "postgresql"),
            ("sqlite:///tmp/r.sqlite", "sqlite"),
            ("http://db.lab/qc", "http"),
            ("mysql:/u:s3cret@host/db", "mysql"),
        ] {
            let err = DbLocation::parse(text).unwrap_err();
            assert!(matches!(&err, LocationError::ForeignUrl { scheme: s, .. } if s == scheme), "{text}: {err}");
            let err = err.to_string();
            assert!(err.contains(&format!("'{scheme}:'")) && err.contains("postgres://"), "{text}: {err}");
            assert!(!err.contains("s3cret"), "{err}");
        }
    }

    #[test]
    fn passwords_never_survive_redaction() {
        let cases = [
            ("postgres://sheen:s3cret@db.lab:5433/qc", "postgres://sheen@db.lab:5433/qc"),
            (
                "postgresql://sheen:p%40ss:w@127.0.0.1/qc?sslmode=disable",
                "postgresql://sheen@127.0.0.1/qc?sslmode=disable",
            ),
            ("postgres://sheen@h/qc?password=s3cret&application_name=x", "postgres://sheen@h/qc?application_name=x"),
            ("postgres://h/qc?password=s3cret", "postgres://h/qc"),
            ("postgres://sheen:s3cret@h", "postgres://sheen@h"),
            ("postgres://h:5432/qc", "postgres://h:5432/qc"),
            // Unencoded '/' and '@' in the password: the client still reads them as password.
            ("postgres://u:pa/s3cret@host/db", "postgres://u@host/db"),
            ("postgres://u:s3cret/@host:5432/db?sslmode=disable", "postgres://u@host:5432/db?sslmode=disable"),
            ("postgres://u:p@s3cret@host/db", "postgres://u@host/db"),
            ("postgres://u:s3cret#x@host/db", "postgres://u@host/db"),
            ("postgres://u:s3cret?x@host/db?password=s3cret", "postgres://u@host/db"),
        ];
        for (url, want) in cases {
            let got = redact_url(url);
            assert_eq!(got, want);
            assert!(!got.contains("s3cret") && !got.contains("ss:w") && !got.contains("pa/"), "{got}");
        }
    }

    #[test]
    fn pgpass_follows_libpq() {
        let text = "# lab servers\n\
                    db.lab:5432:qc:sheen:first\n\
                    *:*:qc:sheen:second\n\
                    localhost:54329:*:sheen:with\\:colon:and more\n\
                    h\\:x:5432:*:*:escaped-host\n\
                    short:line\n";
        assert_eq!(pgpass_password(text, "db.lab", 5432, "qc", "sheen").as_deref(), Some("first"));
        assert_eq!(pgpass_password(text, "other", 1, "qc", "sheen").as_deref(), Some("second"));
        assert_eq!(pgpass_password(text, "localhost", 54329, "x", "sheen").as_deref(), Some("with:colon:and more"));
        assert_eq!(pgpass_password(text, "h:x", 5432, "y", "z").as_deref(), Some("escaped-host"));
        assert_eq!(pgpass_password(text, "db.lab", 5432, "other", "sheen"), None);
    }
}
