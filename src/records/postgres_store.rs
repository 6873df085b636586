//! The PostgreSQL store: a server several stations record into, through the
//! synchronous `postgres` client.
//!
//! The password comes from the URL, else `PGPASSWORD`, else the password
//! file (`PGPASSFILE` or `~/.pgpass`, libpq's rules), since the client
//! itself reads none of them. Errors name the URL with the password removed
//! ([`super::location::redact_url`]); the client's own messages never
//! contain it. TLS follows libpq's `sslmode` and certificate settings
//! ([`super::tls`]): by default encrypted where the server offers it.
//! A Unix socket connection never uses TLS, as in libpq.
//!
//! Opening takes an advisory lock for the migration, so stations starting
//! at the same moment against an empty database create its tables once.

use std::time::Duration;

use postgres::config::Host;
use postgres::{Client, Config, NoTls};
use tokio_postgres_rustls::MakeRustlsConnect;

use super::location::{pgpass_file, pgpass_password, read_pgpass, redact_url};
use super::query::{HistoryFilter, StoredPart, attach_measurements};
use super::row::{self, RowError, SqlValue};
use super::schema::{self, SCHEMA_VERSION, VERSION_TABLE};
use super::sqlite_store::newer_schema;
use super::tls;
use super::{PartRecord, RecordsError, after_row_written};

/// Key of the advisory lock held while migrating ("sheen" in ASCII).
const MIGRATION_LOCK: i64 = 0x0073_6865_656e;

/// How long to try reaching the server before saying it is down.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

pub struct PostgresStore {
    client: Client,
    location: String,
}

impl PostgresStore {
    pub fn open(url: &str) -> Result<Self, RecordsError> {
        let location = redact_url(url);
        let open_err = |reason: String| RecordsError::Open { location: location.clone(), reason: scrub(&reason, url) };
        let (client_url, tls) = tls::split_url(url, |k| std::env::var(k).ok()).map_err(|e| open_err(e.to_string()))?;
        let mut config: Config =
            client_url.parse().map_err(|e: postgres::Error| open_err(format!("{}: {}", e, source_text(&e))))?;
        config.ssl_mode(tls.mode.client_mode());
        if config.get_password().is_none()
            && let Some(password) = password_from_environment(&config)
        {
            config.password(password);
        }
        if config.get_connect_timeout().is_none() {
            config.connect_timeout(CONNECT_TIMEOUT);
        }
        if config.get_application_name().is_none() {
            config.application_name("sheen");
        }
        let connected = match tls::client_config(&tls).map_err(|e| open_err(e.to_string()))? {
            Some(client_config) => config.connect(MakeRustlsConnect::new(client_config)),
            None => config.connect(NoTls),
        };
        let client = connected.map_err(|e| {
            open_err(tls::explain_certificate_error(&e, &tls).unwrap_or_else(|| connect_reason(&e, &tls)))
        })?;
        let mut store = Self { client, location };
        store.migrate()?;
        Ok(store)
    }

    fn store_err(&self, e: &postgres::Error) -> RecordsError {
        RecordsError::Store { location: self.location.clone(), reason: reason(e) }
    }

    pub fn schema_version(&mut self) -> Result<i64, RecordsError> {
        let row = self
            .client
            .query_one("SELECT to_regclass($1) IS NOT NULL", &[&VERSION_TABLE])
            .map_err(|e| self.store_err(&e))?;
        if !row.get::<_, bool>(0) {
            return Ok(0);
        }
        let v: Option<i64> = self
            .client
            .query_one(&format!("SELECT max(version)::BIGINT FROM {VERSION_TABLE}"), &[])
            .map_err(|e| self.store_err(&e))?
            .get(0);
        Ok(v.unwrap_or(0))
    }

    fn migrate(&mut self) -> Result<(), RecordsError> {
        let location = self.location.clone();
        let open_err = |e: postgres::Error| RecordsError::Open { location: location.clone(), reason: reason(&e) };
        let mut tx = self.client.transaction().map_err(open_err)?;
        tx.execute("SELECT pg_advisory_xact_lock($1)", &[&MIGRATION_LOCK]).map_err(open_err)?;
        tx.batch_execute(&format!("CREATE TABLE IF NOT EXISTS {VERSION_TABLE} (version INTEGER NOT NULL)"))
            .map_err(open_err)?;
        let found: i64 = tx
            .query_one(&format!("SELECT coalesce(max(version), 0)::BIGINT FROM {VERSION_TABLE}"), &[])
            .map_err(open_err)?
            .get(0);
        if found > SCHEMA_VERSION {
            return Err(newer_schema(self.location.clone(), found));
        }
        if found < SCHEMA_VERSION {
            for to in found + 1..=SCHEMA_VERSION {
                for statement in schema::migration(to, schema::Dialect::Postgres) {
                    tx.batch_execute(&statement).map_err(open_err)?;
                }
            }
            tx.batch_execute(&format!("DELETE FROM {VERSION_TABLE}")).map_err(open_err)?;
            tx.execute(&format!("INSERT INTO {VERSION_TABLE} (version) VALUES ($1)"), &[&(SCHEMA_VERSION as i32)])
                .map_err(open_err)?;
        }
        tx.commit().map_err(open_err)
    }

    pub fn insert(&mut self, record: &PartRecord) -> Result<i64, RecordsError> {
        let abort_after = super::abort_after_rows();
        let drop_after = super::hook_rows(super::DROP_CONNECTION_AFTER_ROWS_ENV);
        let location = self.location.clone();
        let err = |e: postgres::Error| RecordsError::Store { location: location.clone(), reason: reason(&e) };
        let mut tx = self.client.transaction().map_err(err)?;
        let values = row::part_values(record);
        let id: i64 = tx.query_one(&schema::insert_part(), &sql_params(&values)).map_err(err)?.get(0);
        let insert = tx.prepare(&schema::insert_measurement()).map_err(err)?;
        for (position, m) in record.measurements.iter().enumerate() {
            let values = row::measurement_values(id, position, m);
            tx.execute(&insert, &sql_params(&values)).map_err(err)?;
            after_row_written(position + 1, abort_after);
            if drop_after == Some(position + 1) {
                // The server ends this backend; what follows meets a lost connection.
                let _ = tx.batch_execute("SELECT pg_terminate_backend(pg_backend_pid())");
            }
        }
        tx.commit().map_err(err)?;
        Ok(id)
    }

    pub fn input_hashes(&mut self, recipe: &str) -> Result<std::collections::HashSet<String>, RecordsError> {
        let rows = self.client.query(schema::SELECT_INPUT_HASHES, &[&recipe]).map_err(|e| self.store_err(&e))?;
        Ok(rows.iter().map(|r| r.get::<_, String>(0)).collect())
    }

    pub fn parts(&mut self, filter: &HistoryFilter) -> Result<Vec<StoredPart>, RecordsError> {
        let location = self.location.clone();
        let err = |e: postgres::Error| RecordsError::Store { location: location.clone(), reason: reason(&e) };
        let row_err = |e: RowError<postgres::Error>| match e {
            RowError::Driver(e) => err(e),
            RowError::Corrupt(reason) => RecordsError::Corrupt { location: location.clone(), reason },
        };
        // One snapshot for parts and measurements while stations commit.
        let mut tx = self
            .client
            .build_transaction()
            .read_only(true)
            .isolation_level(postgres::IsolationLevel::RepeatableRead)
            .start()
            .map_err(err)?;
        let f = filter.parameters();
        let params: [&(dyn postgres::types::ToSql + Sync); 4] = [&f[0], &f[1], &f[2], &f[3]];
        let mut parts = Vec::new();
        for r in tx.query(&schema::select_parts(), &params).map_err(err)? {
            parts.push(row::stored_part(&r).map_err(row_err)?);
        }
        let mut measurements = Vec::new();
        for r in tx.query(&schema::select_measurements(), &params).map_err(err)? {
            measurements.push(row::stored_measurement(&r).map_err(row_err)?);
        }
        tx.commit().map_err(err)?;
        attach_measurements(&mut parts, measurements);
        Ok(parts)
    }
}

/// The values of an `INSERT` as the driver binds them.
fn sql_params<'a, const N: usize>(
    values: &'a [(&'static str, SqlValue<'a>); N],
) -> Vec<&'a (dyn postgres::types::ToSql + Sync)> {
    values.iter().map(|(_, v)| v.postgres()).collect()
}

/// `PGPASSWORD`, else the password file's entry for this connection.
fn password_from_environment(config: &Config) -> Option<String> {
    if let Ok(p) = std::env::var("PGPASSWORD") {
        return Some(p);
    }
    let text = read_pgpass(&pgpass_file()?)?;
    let host = match config.get_hosts().first() {
        Some(Host::Tcp(h)) => h.clone(),
        // libpq matches a socket connection against "localhost".
        _ => "localhost".to_string(),
    };
    let port = config.get_ports().first().copied().unwrap_or(5432);
    let user = config.get_user().map(str::to_string).or_else(|| std::env::var("USER").ok()).unwrap_or_default();
    let database = config.get_dbname().map_or_else(|| user.clone(), str::to_string);
    pgpass_password(&text, &host, port, &database, &user)
}

/// The server's message for a database error, else the client's kind and
/// its cause ("error connecting to server: Connection refused (os error 111)").
fn reason(e: &postgres::Error) -> String {
    if let Some(db) = e.as_db_error() {
        return format!("{} ({})", db.message(), db.code().code());
    }
    let source = source_text(e);
    if source.is_empty() { e.to_string() } else { format!("{e}: {source}") }
}

/// [`reason`] for a failed connection, with the TLS setting that a
/// refusal of an unencrypted connection points to.
fn connect_reason(e: &postgres::Error, settings: &tls::TlsSettings) -> String {
    let text = reason(e);
    if settings.mode == tls::SslMode::Disable && text.contains("no encryption") {
        return format!("{text} (the server requires TLS: leave out sslmode=disable)");
    }
    text
}

/// The client's message with anything of the URL's password taken out: a
/// malformed URL's password can end up in a host or option the client
/// names (`u:pw@x@h` gives the host `x@h`), and no message may hold it.
fn scrub(reason: &str, url: &str) -> String {
    let Some(userinfo) = url.split_once("://").and_then(|(_, rest)| rest.rsplit_once('@')).map(|(u, _)| u) else {
        return reason.to_string();
    };
    let Some((_, password)) = userinfo.split_once(':') else { return reason.to_string() };
    let mut scrubbed = reason.to_string();
    for secret in std::iter::once(password).chain(password.split(['@', '/', '?', '#'])) {
        if secret.len() >= 3 {
            scrubbed = scrubbed.replace(secret, "***");
        }
    }
    scrubbed
}

fn source_text(e: &postgres::Error) -> String {
    std::error::Error::source(e).map(ToString::to_string).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    #[test]
    fn client_messages_lose_every_piece_of_the_password() {
        let url = "postgres://u:hunter@2secret@host/db";
        let said = "failed to look up host 2secret@host; password hunter@2secret rejected";
        let got = super::scrub(said, url);
        assert!(!got.contains("hunter") && !got.contains("2secret"), "{got}");
        assert_eq!(super::scrub("connection refused", "postgres://u@host/db"), "connection refused");
    }
}
