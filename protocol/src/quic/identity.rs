//! The server's certificate: made once, kept on disk, recognized by its SHA-256 fingerprint.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

/// File names inside the certificate directory.
pub const CERT_FILE: &str = "server-cert.pem";
/// Private key file name (written with mode 0600 on Unix).
pub const KEY_FILE: &str = "server-key.pem";
/// Names a freshly made certificate is valid for; clients that pin the fingerprint ignore names.
pub const DEFAULT_NAMES: [&str; 3] = ["localhost", "127.0.0.1", "::1"];

/// A server's certificate chain, private key and the fingerprint clients pin.
#[derive(Debug)]
pub struct ServerIdentity {
    /// End-entity certificate first.
    pub cert_chain: Vec<CertificateDer<'static>>,
    /// The end-entity certificate's private key.
    pub key: PrivateKeyDer<'static>,
    /// Lowercase hex SHA-256 of the end-entity certificate (DER), what `--trust-fingerprint` takes.
    pub fingerprint: String,
}

impl Clone for ServerIdentity {
    fn clone(&self) -> Self {
        ServerIdentity {
            cert_chain: self.cert_chain.clone(),
            key: self.key.clone_key(),
            fingerprint: self.fingerprint.clone(),
        }
    }
}

/// Why the server identity could not be loaded or made.
#[derive(Debug, thiserror::Error)]
pub enum IdentityError {
    /// A file or directory could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// A PEM file did not contain what it should.
    #[error("{path}: {what}")]
    BadPem {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// Only one of certificate and key exists, so making a new pair would silently replace the other.
    #[error("{present} exists but {missing} does not; restore it or remove both to make a new certificate")]
    HalfPresent {
        /// The file found.
        present: PathBuf,
        /// The file missing.
        missing: PathBuf,
    },
    /// rcgen failed.
    #[error("cannot generate a certificate: {0}")]
    Generate(#[from] rcgen::Error),
}

impl ServerIdentity {
    /// Loads `server-cert.pem` and `server-key.pem` from `cert_dir`, or on first start makes a self-signed
    /// certificate for [`DEFAULT_NAMES`] and stores it there, so the fingerprint clients pin stays the same.
    pub fn load_or_create(cert_dir: &Path) -> Result<ServerIdentity, IdentityError> {
        let cert_path = cert_dir.join(CERT_FILE);
        let key_path = cert_dir.join(KEY_FILE);
        match (cert_path.exists(), key_path.exists()) {
            (true, true) => Self::load(&cert_path, &key_path),
            (false, false) => {
                let (identity, pems) = Self::generate_with_pem(&DEFAULT_NAMES)?;
                fs::create_dir_all(cert_dir)
                    .map_err(|source| IdentityError::Io { path: cert_dir.to_owned(), source })?;
                write_private(&key_path, pems.key.as_bytes())?;
                fs::write(&cert_path, pems.cert).map_err(|source| IdentityError::Io { path: cert_path, source })?;
                Ok(identity)
            }
            (true, false) => Err(IdentityError::HalfPresent { present: cert_path, missing: key_path }),
            (false, true) => Err(IdentityError::HalfPresent { present: key_path, missing: cert_path }),
        }
    }

    /// Makes a self-signed certificate for `names` (DNS names or IP addresses) in memory.
    pub fn generate(names: &[&str]) -> Result<ServerIdentity, IdentityError> {
        Ok(Self::generate_with_pem(names)?.0)
    }

    fn generate_with_pem(names: &[&str]) -> Result<(ServerIdentity, Pems), IdentityError> {
        let made = rcgen::generate_simple_self_signed(names.iter().map(|n| n.to_string()).collect::<Vec<_>>())?;
        let cert = made.cert.der().clone();
        let key = PrivateKeyDer::Pkcs8(made.signing_key.serialize_der().into());
        let pems = Pems { cert: made.cert.pem(), key: made.signing_key.serialize_pem() };
        Ok((ServerIdentity { fingerprint: fingerprint_hex(&cert), cert_chain: vec![cert], key }, pems))
    }

    /// Loads a certificate chain and key from PEM files (e.g. ones issued by your own CA).
    pub fn load(cert_path: &Path, key_path: &Path) -> Result<ServerIdentity, IdentityError> {
        let cert_chain = load_certificates(cert_path)?;
        let key_pem = read(key_path)?;
        let key = PrivateKeyDer::from_pem_slice(&key_pem).map_err(|e| bad_pem(key_path, e))?;
        Ok(ServerIdentity { fingerprint: fingerprint_hex(&cert_chain[0]), cert_chain, key })
    }
}

/// PEM text of a freshly made certificate and key.
struct Pems {
    cert: String,
    key: String,
}

/// Lowercase hex SHA-256 of a DER certificate.
pub fn fingerprint_hex(cert: &CertificateDer<'_>) -> String {
    let digest = ring::digest::digest(&ring::digest::SHA256, cert);
    digest.as_ref().iter().map(|b| format!("{b:02x}")).collect()
}

/// Accepts a fingerprint as printed by the server or by `openssl x509 -fingerprint -sha256` (`AB:CD:...`)
/// and returns it as 64 lowercase hex digits, or `None` when it is not a SHA-256 fingerprint.
pub fn normalize_fingerprint(text: &str) -> Option<String> {
    let hex: String = text.trim().chars().filter(|c| *c != ':').map(|c| c.to_ascii_lowercase()).collect();
    (hex.len() == 64 && hex.chars().all(|c| c.is_ascii_hexdigit())).then_some(hex)
}

/// Every certificate in a PEM file; at least one.
pub(crate) fn load_certificates(path: &Path) -> Result<Vec<CertificateDer<'static>>, IdentityError> {
    let bytes = read(path)?;
    let certs = CertificateDer::pem_slice_iter(&bytes).collect::<Result<Vec<_>, _>>().map_err(|e| bad_pem(path, e))?;
    if certs.is_empty() {
        return Err(IdentityError::BadPem { path: path.to_owned(), what: "no CERTIFICATE block".into() });
    }
    Ok(certs)
}

fn read(path: &Path) -> Result<Vec<u8>, IdentityError> {
    fs::read(path).map_err(|source| IdentityError::Io { path: path.to_owned(), source })
}

fn bad_pem(path: &Path, error: impl std::fmt::Display) -> IdentityError {
    IdentityError::BadPem { path: path.to_owned(), what: error.to_string() }
}

/// Writes a secret readable by its owner only.
pub(super) fn write_private(path: &Path, contents: &[u8]) -> Result<(), IdentityError> {
    let io = |source| IdentityError::Io { path: path.to_owned(), source };
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
    options.open(path).and_then(|mut f| f.write_all(contents)).map_err(io)
}
