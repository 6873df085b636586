//! Issue 53: the PostgreSQL store over TLS, as libpq does it, against a real
//! server that accepts only encrypted connections (CI starts one with
//! `.ci/postgres-server start-tls` and a throw-away CA; its certificate
//! names the host `localhost` only).

use std::path::PathBuf;
use std::process::{Command, Output};

use sheen::records::{DbLocation, HistoryFilter, Store};

use super::records::record;

/// The TLS-only server's URL (host 127.0.0.1, no sslmode).
const TLS_URL_ENV: &str = "SHEEN_TEST_POSTGRES_TLS_URL";
/// The folder holding `ca.crt` (signed the server's certificate) and
/// `other-ca.crt` (did not).
const TLS_DIR_ENV: &str = "SHEEN_TEST_POSTGRES_TLS_DIR";
const REQUIRE_ENV: &str = "SHEEN_REQUIRE_POSTGRES_TESTS";

struct TlsServer {
    /// `postgres://sheen:PW@127.0.0.1:PORT/sheen_test`.
    url: String,
    password: String,
    ca: PathBuf,
    other_ca: PathBuf,
}

impl TlsServer {
    fn get(test: &str) -> Option<TlsServer> {
        let (Ok(url), Ok(dir)) = (std::env::var(TLS_URL_ENV), std::env::var(TLS_DIR_ENV)) else {
            if std::env::var(REQUIRE_ENV).is_ok_and(|v| v == "1") {
                panic!("{test}: {REQUIRE_ENV}=1 but {TLS_URL_ENV} or {TLS_DIR_ENV} is not set");
            }
            eprintln!("skipping {test}: set {TLS_URL_ENV} and {TLS_DIR_ENV} (.ci/postgres-server start-tls)");
            return None;
        };
        let password = url
            .split_once("://")
            .and_then(|(_, rest)| rest.split_once('@'))
            .and_then(|(user, _)| user.split_once(':'))
            .map(|(_, pw)| pw.to_string())
            .expect("a password in the TLS server's URL");
        let dir = PathBuf::from(dir);
        Some(TlsServer { url, password, ca: dir.join("ca.crt"), other_ca: dir.join("other-ca.crt") })
    }

    /// The URL with `host` for 127.0.0.1 and `query` appended.
    fn with(&self, host: &str, query: &str) -> String {
        let url = self.url.replace("@127.0.0.1:", &format!("@{host}:"));
        if query.is_empty() { url } else { format!("{url}?{query}") }
    }
}

fn sheen_history(db: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sheen"))
        .args(["history", "--db", db])
        .env_remove("PGPASSWORD")
        .env_remove("PGSSLMODE")
        .env_remove("PGSSLROOTCERT")
        .output()
        .expect("run sheen")
}

/// verify-full records into and reads back from the TLS-only server;
/// require and the default (prefer) reach it too; verify-ca takes the
/// certificate by IP address although it names only `localhost`.
#[test]
fn a_tls_only_server_is_recorded_into_with_verify_full() {
    let Some(server) = TlsServer::get("a_tls_only_server_is_recorded_into_with_verify_full") else { return };
    let ca = server.ca.display().to_string();
    let full = server.with("localhost", &format!("sslmode=verify-full&sslrootcert={ca}"));
    let mut store = Store::open(&DbLocation::Postgres(full.clone())).expect("verify-full reaches the server");
    let part = format!("tls-{}", std::process::id());
    let mut r = record(&part, "tls-recipe", "2026-12-07T10:00:00Z", &[Some(1.5)]);
    r.recipe = format!("tls-recipe-{}", std::process::id());
    store.insert(&r).expect("record over TLS");
    let filter = HistoryFilter { recipe: Some(r.recipe.clone()), ..HistoryFilter::default() };
    let back = store.parts(&filter).expect("read back");
    assert_eq!(back.len(), 1);
    assert_eq!(back[0].record.part_id, part);
    for query in ["sslmode=require".to_string(), String::new(), format!("sslmode=verify-ca&sslrootcert={ca}")] {
        let url = server.with("127.0.0.1", &query);
        Store::open(&DbLocation::Postgres(url)).unwrap_or_else(|e| panic!("{query:?}: {e}"));
    }
    let o = sheen_history(&full);
    assert!(o.status.success(), "sheen history with verify-full: {}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains(&part));
}

/// A wrong root certificate, a host name the certificate does not name,
/// and sslmode=disable against a TLS-only server are each refused with
/// one line that says why; no message holds the password.
#[test]
fn wrong_certificates_and_host_names_are_refused_with_one_clear_line() {
    let Some(server) = TlsServer::get("wrong_certificates_and_host_names_are_refused_with_one_clear_line") else {
        return;
    };
    let (ca, other) = (server.ca.display().to_string(), server.other_ca.display().to_string());
    let cases = [
        (server.with("localhost", &format!("sslmode=verify-full&sslrootcert={other}")), "not signed by"),
        (server.with("localhost", &format!("sslmode=verify-ca&sslrootcert={other}")), "not signed by"),
        (server.with("127.0.0.1", &format!("sslmode=verify-full&sslrootcert={ca}")), "not for the host name"),
        (server.with("127.0.0.1", "sslmode=disable"), "requires TLS"),
        (server.with("127.0.0.1", "sslmode=verify-full&sslrootcert=/no/such/ca.crt"), "/no/such/ca.crt"),
    ];
    for (url, expected) in cases {
        let o = sheen_history(&url);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{url}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(err.contains(expected), "{url}: expected {expected:?} in {err}");
        assert!(!err.contains(&server.password), "the password leaked: {err}");
        let library = Store::open(&DbLocation::Postgres(url.clone())).err().expect("refused").to_string();
        assert!(library.contains(expected) && !library.contains(&server.password), "{library}");
    }
}
