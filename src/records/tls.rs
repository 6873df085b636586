//! TLS for the PostgreSQL store, with libpq's settings and meanings.
//!
//! The `postgres` client knows `sslmode` `disable`, `prefer` and `require`
//! and no certificate settings, so Sheen reads libpq's from the URL's query
//! (`sslmode`, `sslrootcert`, `sslcert`, `sslkey`) or, where the URL has
//! none, from PostgreSQL's environment variables (`PGSSLMODE`,
//! `PGSSLROOTCERT`, `PGSSLCERT`, `PGSSLKEY`), takes them out of the URL and
//! builds a rustls client (pure Rust, with `ring` for the cryptography: no
//! system library to match) that checks what libpq's mode says:
//!
//! | sslmode | encrypted | certificate chain | host name |
//! |---|---|---|---|
//! | `disable` | no | – | – |
//! | `prefer` (default) | when the server offers it | no | no |
//! | `require` | yes | only with a root certificate (libpq: then as `verify-ca`) | no |
//! | `verify-ca` | yes | yes | no |
//! | `verify-full` | yes | yes | yes |
//!
//! The root certificate defaults to `~/.postgresql/root.crt` and the client
//! certificate and key to `~/.postgresql/postgresql.crt` and `.key`, as in
//! libpq; `sslrootcert=system` is not supported (a plant's server has its own
//! CA) and says so.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::client::{ClientConfig, WebPkiServerVerifier};
use rustls::crypto::WebPkiSupportedAlgorithms;
use rustls::pki_types::pem::PemObject as _;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use rustls::{CertificateError, DigitallySignedStruct, RootCertStore, SignatureScheme};

/// libpq's `sslmode`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SslMode {
    Disable,
    #[default]
    Prefer,
    Require,
    VerifyCa,
    VerifyFull,
}

impl SslMode {
    pub fn parse(text: &str) -> Option<SslMode> {
        Some(match text {
            "disable" => SslMode::Disable,
            "prefer" => SslMode::Prefer,
            "require" => SslMode::Require,
            "verify-ca" => SslMode::VerifyCa,
            "verify-full" => SslMode::VerifyFull,
            // libpq's "allow" tries without TLS first; the client cannot, and
            // "prefer" is the safer of the two.
            "allow" => SslMode::Prefer,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            SslMode::Disable => "disable",
            SslMode::Prefer => "prefer",
            SslMode::Require => "require",
            SslMode::VerifyCa => "verify-ca",
            SslMode::VerifyFull => "verify-full",
        }
    }

    /// What the `postgres` client is told: whether TLS may be skipped.
    pub fn client_mode(self) -> postgres::config::SslMode {
        match self {
            SslMode::Disable => postgres::config::SslMode::Disable,
            SslMode::Prefer => postgres::config::SslMode::Prefer,
            SslMode::Require | SslMode::VerifyCa | SslMode::VerifyFull => postgres::config::SslMode::Require,
        }
    }
}

/// The TLS settings of one connection.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TlsSettings {
    pub mode: SslMode,
    pub root_cert: Option<PathBuf>,
    pub client_cert: Option<PathBuf>,
    pub client_key: Option<PathBuf>,
}

/// A TLS setting Sheen cannot use; the text names the setting and the file.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TlsError {
    #[error("sslmode={0}: expected disable, prefer, require, verify-ca or verify-full")]
    UnknownMode(String),
    #[error("sslmode={mode} needs the server's root certificate: give sslrootcert=FILE (or put it at {default})")]
    NoRootCert { mode: &'static str, default: String },
    #[error("sslrootcert=system is not supported: give the file of the CA that signed the server's certificate")]
    SystemRoots,
    #[error("{setting} {path}: {reason}")]
    File { setting: &'static str, path: String, reason: String },
    #[error("sslcert and sslkey go together: {0} is missing")]
    HalfClientIdentity(&'static str),
}

const TLS_KEYS: [&str; 4] = ["sslmode", "sslrootcert", "sslcert", "sslkey"];

/// Takes libpq's TLS settings out of `url` (the `postgres` client refuses
/// `verify-ca`, `verify-full` and the certificate keys), filling the ones
/// it lacks from the environment through `env`. Returns the URL the client
/// gets and the settings.
pub fn split_url(url: &str, env: impl Fn(&str) -> Option<String>) -> Result<(String, TlsSettings), TlsError> {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, q),
        None => (url, ""),
    };
    let mut kept = Vec::new();
    let mut found: [Option<String>; 4] = Default::default();
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        match TLS_KEYS.iter().position(|k| *k == key) {
            Some(i) => found[i] = Some(percent_decode(value)),
            None => kept.push(pair),
        }
    }
    let variables = ["PGSSLMODE", "PGSSLROOTCERT", "PGSSLCERT", "PGSSLKEY"];
    for (slot, variable) in found.iter_mut().zip(variables) {
        if slot.is_none() {
            *slot = env(variable).filter(|v| !v.is_empty());
        }
    }
    let [mode, root, cert, key] = found;
    let mode = match mode {
        Some(m) => SslMode::parse(&m).ok_or(TlsError::UnknownMode(m))?,
        None => SslMode::default(),
    };
    let settings = TlsSettings {
        mode,
        root_cert: root.map(PathBuf::from),
        client_cert: cert.map(PathBuf::from),
        client_key: key.map(PathBuf::from),
    };
    let url = if kept.is_empty() { base.to_string() } else { format!("{base}?{}", kept.join("&")) };
    Ok((url, settings))
}

fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match (bytes[i], bytes.get(i + 1).and_then(|&b| hex(b)), bytes.get(i + 2).and_then(|&b| hex(b))) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (b, _, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// libpq's folder of default certificates, `~/.postgresql`.
fn libpq_folder() -> Option<PathBuf> {
    dirs::home_dir().map(|h| h.join(".postgresql"))
}

/// The rustls client for `settings`, or `None` for `sslmode=disable`.
pub fn client_config(settings: &TlsSettings) -> Result<Option<ClientConfig>, TlsError> {
    if settings.mode == SslMode::Disable {
        return Ok(None);
    }
    // ring rather than aws-lc-rs: a few C and assembly files its own build
    // compiles, where aws-lc needs CMake on some platforms. rustls marks it
    // deprecated for lacking post-quantum key exchange, which PostgreSQL
    // servers do not ask for; the classical suites are those of any client.
    #[allow(deprecated)]
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let default_root = libpq_folder().map(|f| f.join("root.crt"));
    let root = match (&settings.root_cert, settings.mode) {
        (Some(path), _) if path.as_os_str() == "system" => return Err(TlsError::SystemRoots),
        (Some(path), _) => Some(path.clone()),
        // libpq verifies with the default root certificate where it exists.
        (None, SslMode::Require) => default_root.filter(|p| p.is_file()),
        (None, SslMode::VerifyCa | SslMode::VerifyFull) => match default_root.filter(|p| p.is_file()) {
            Some(p) => Some(p),
            None => {
                return Err(TlsError::NoRootCert {
                    mode: settings.mode.name(),
                    default: libpq_folder()
                        .map_or_else(|| "~/.postgresql/root.crt".into(), |f| f.join("root.crt").display().to_string()),
                });
            }
        },
        (None, _) => None,
    };
    let algorithms = provider.signature_verification_algorithms;
    // The verify modes have a root certificate here (or returned above).
    let verifier: Arc<dyn ServerCertVerifier> = match (settings.mode, &root) {
        (SslMode::Prefer, _) | (_, None) => Arc::new(LibpqVerifier { chain: None, algorithms }),
        (_, Some(root)) => {
            let roots = read_roots(root)?;
            let chain = WebPkiServerVerifier::builder_with_provider(Arc::new(roots), Arc::clone(&provider))
                .build()
                .map_err(|e| file_error("sslrootcert", root, e.to_string()))?;
            if settings.mode == SslMode::VerifyFull {
                chain
            } else {
                Arc::new(LibpqVerifier { chain: Some(chain), algorithms })
            }
        }
    };
    let builder = ClientConfig::builder_with_provider(Arc::clone(&provider))
        .with_safe_default_protocol_versions()
        .map_err(|e| TlsError::File { setting: "TLS", path: String::new(), reason: e.to_string() })?
        .dangerous()
        .with_custom_certificate_verifier(verifier);
    let default_pair = libpq_folder()
        .map(|f| (f.join("postgresql.crt"), f.join("postgresql.key")))
        .filter(|(c, k)| c.is_file() && k.is_file());
    let identity = match (&settings.client_cert, &settings.client_key) {
        (Some(c), Some(k)) => Some((c.clone(), k.clone())),
        (Some(_), None) => return Err(TlsError::HalfClientIdentity("sslkey")),
        (None, Some(_)) => return Err(TlsError::HalfClientIdentity("sslcert")),
        (None, None) => default_pair,
    };
    Ok(Some(match identity {
        Some((cert, key)) => {
            let chain = read_certs(&cert, "sslcert")?;
            let key_der = PrivateKeyDer::from_pem_file(&key).map_err(|e| file_error("sslkey", &key, e.to_string()))?;
            builder.with_client_auth_cert(chain, key_der).map_err(|e| file_error("sslcert", &cert, e.to_string()))?
        }
        None => builder.with_no_client_auth(),
    }))
}

fn file_error(setting: &'static str, path: &Path, reason: String) -> TlsError {
    TlsError::File { setting, path: path.display().to_string(), reason }
}

fn read_certs(path: &Path, setting: &'static str) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let certs = CertificateDer::pem_file_iter(path)
        .and_then(|it| it.collect::<Result<Vec<_>, _>>())
        .map_err(|e| file_error(setting, path, e.to_string()))?;
    if certs.is_empty() {
        return Err(file_error(setting, path, "no PEM certificate in the file".into()));
    }
    Ok(certs)
}

fn read_roots(path: &Path) -> Result<RootCertStore, TlsError> {
    let mut roots = RootCertStore::empty();
    for cert in read_certs(path, "sslrootcert")? {
        roots.add(cert).map_err(|e| file_error("sslrootcert", path, e.to_string()))?;
    }
    Ok(roots)
}

/// libpq's checks short of `verify-full` (which is rustls's own
/// `WebPkiServerVerifier`): without a chain (`prefer`, `require` without a
/// root certificate) the connection is encrypted and the handshake's
/// signatures are checked, but whose certificate it is is not; with one
/// (`verify-ca`, `require` with a root certificate) the chain must lead to
/// the root certificate and the host name is not compared (webpki checks the
/// chain before the name, so a name mismatch means the chain was good).
#[derive(Debug)]
struct LibpqVerifier {
    chain: Option<Arc<WebPkiServerVerifier>>,
    algorithms: WebPkiSupportedAlgorithms,
}

impl ServerCertVerifier for LibpqVerifier {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        let Some(chain) = &self.chain else { return Ok(ServerCertVerified::assertion()) };
        match chain.verify_server_cert(end_entity, intermediates, server_name, ocsp_response, now) {
            Err(rustls::Error::InvalidCertificate(
                CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. },
            )) => Ok(ServerCertVerified::assertion()),
            other => other,
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(message, cert, dss, &self.algorithms)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(message, cert, dss, &self.algorithms)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.algorithms.supported_schemes()
    }
}

/// A plain reading of a certificate failure, with the setting that decides
/// it; `None` for errors that are not about the server's certificate.
pub fn explain_certificate_error(error: &(dyn std::error::Error + 'static), settings: &TlsSettings) -> Option<String> {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(error);
    while let Some(e) = source {
        // tokio-rustls hands rustls's error on inside an io::Error, whose
        // `source` skips it: look inside as well.
        let inner = e
            .downcast_ref::<std::io::Error>()
            .and_then(|io| io.get_ref())
            .map(|i| i as &(dyn std::error::Error + 'static));
        let tls = e.downcast_ref::<rustls::Error>().or_else(|| inner.and_then(|i| i.downcast_ref::<rustls::Error>()));
        if let Some(rustls::Error::InvalidCertificate(c)) = tls {
            let root =
                settings.root_cert.as_ref().map_or_else(|| "the root certificate".into(), |p| p.display().to_string());
            return Some(match c {
                CertificateError::NotValidForNameContext { expected, presented } => {
                    let expected = match expected {
                        ServerName::DnsName(name) => name.as_ref().to_string(),
                        ServerName::IpAddress(ip) => std::net::IpAddr::from(*ip).to_string(),
                        other => format!("{other:?}"),
                    };
                    // rustls gives the certificate's names as `DnsName("x")`.
                    let names: Vec<&str> =
                        presented.iter().map(|p| p.split('"').nth(1).unwrap_or(p.as_str())).collect();
                    format!(
                        "the server's certificate is not for the host name connected to: it names {}, not {expected} \
                         (sslmode={} compares them)",
                        names.join(", "),
                        settings.mode.name()
                    )
                }
                CertificateError::NotValidForName => format!(
                    "the server's certificate is not for the host name connected to (sslmode={} compares them)",
                    settings.mode.name()
                ),
                CertificateError::UnknownIssuer | CertificateError::BadSignature => {
                    format!("the server's certificate is not signed by {root} (sslrootcert)")
                }
                CertificateError::Expired | CertificateError::ExpiredContext { .. } => {
                    "the server's certificate has expired".into()
                }
                other => format!("the server's certificate was refused: {other:?}"),
            });
        }
        source = e.source();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_env(_: &str) -> Option<String> {
        None
    }

    #[test]
    fn libpq_settings_leave_the_url_and_the_rest_stays() {
        let (url, s) = split_url(
            "postgresql://u:pw@db.plant:5433/qc?application_name=x&sslmode=verify-full&sslrootcert=%2Fetc%2Fca.pem",
            no_env,
        )
        .unwrap();
        assert_eq!(url, "postgresql://u:pw@db.plant:5433/qc?application_name=x");
        assert_eq!(s.mode, SslMode::VerifyFull);
        assert_eq!(s.root_cert.as_deref(), Some(Path::new("/etc/ca.pem")));
        let (url, s) = split_url("postgres://u@h/db", no_env).unwrap();
        assert_eq!((url.as_str(), s.mode), ("postgres://u@h/db", SslMode::Prefer), "prefer is libpq's default");
    }

    #[test]
    fn the_environment_fills_what_the_url_does_not_say() {
        let env = |k: &str| match k {
            "PGSSLMODE" => Some("require".to_string()),
            "PGSSLROOTCERT" => Some("/ca.pem".to_string()),
            _ => None,
        };
        let (_, s) = split_url("postgres://u@h/db?sslmode=verify-ca", env).unwrap();
        assert_eq!(s.mode, SslMode::VerifyCa, "the URL wins");
        assert_eq!(s.root_cert.as_deref(), Some(Path::new("/ca.pem")));
        let (_, s) = split_url("postgres://u@h/db", env).unwrap();
        assert_eq!(s.mode, SslMode::Require);
    }

    #[test]
    fn unknown_modes_and_half_identities_are_refused() {
        let e = split_url("postgres://u@h/db?sslmode=verify", no_env).unwrap_err();
        assert_eq!(e, TlsError::UnknownMode("verify".into()));
        let settings =
            TlsSettings { mode: SslMode::Require, client_cert: Some("/c.pem".into()), ..TlsSettings::default() };
        assert_eq!(client_config(&settings).unwrap_err(), TlsError::HalfClientIdentity("sslkey"));
        let missing = TlsSettings {
            mode: SslMode::VerifyFull,
            root_cert: Some("/no/such/ca.pem".into()),
            ..TlsSettings::default()
        };
        let e = client_config(&missing).unwrap_err().to_string();
        assert!(e.contains("sslrootcert /no/such/ca.pem"), "{e}");
        assert!(client_config(&TlsSettings { mode: SslMode::Disable, ..TlsSettings::default() }).unwrap().is_none());
    }
}
