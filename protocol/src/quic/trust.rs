//! How a client decides to trust a server: a CA file, or a pinned certificate fingerprint. There is
//! deliberately no "accept anything" mode.

use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;

use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::{ring as ring_provider, CryptoProvider, WebPkiSupportedAlgorithms};
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use rustls::{CertificateError, DigitallySignedStruct, RootCertStore, SignatureScheme};

use super::identity::{fingerprint_hex, load_certificates, normalize_fingerprint, IdentityError};

/// What a client trusts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Trust {
    /// Certificates issued by a CA in this PEM file (a self-signed server certificate file works too); the
    /// server name must match the certificate.
    CaFile(PathBuf),
    /// Exactly the certificate with this SHA-256 fingerprint (hex, colons allowed), whatever its name or
    /// dates, like SSH host keys.
    Fingerprint(String),
}

/// Why a [`Trust`] could not be turned into a TLS configuration.
#[derive(Debug, thiserror::Error)]
pub enum TrustError {
    /// The CA file could not be used.
    #[error("CA file: {0}")]
    CaFile(#[from] IdentityError),
    /// A certificate in the CA file was refused as a trust anchor.
    #[error("CA file {path}: {source}")]
    BadAnchor {
        /// The file.
        path: PathBuf,
        /// Why.
        source: rustls::Error,
    },
    /// The fingerprint is not 64 hex digits.
    #[error("{0:?} is not a SHA-256 fingerprint (64 hex digits, colons allowed)")]
    BadFingerprint(String),
    /// rustls refused the configuration.
    #[error("TLS configuration: {0}")]
    Tls(#[from] rustls::Error),
}

/// The ring provider, explicitly: no process-wide default is needed, and aws-lc is never pulled in.
pub(crate) fn crypto_provider() -> Arc<CryptoProvider> {
    Arc::new(ring_provider::default_provider())
}

impl Trust {
    /// A TLS 1.3 client configuration that trusts what `self` says and offers `alpn_protocols`.
    pub(crate) fn client_crypto(&self, alpn_protocols: &[Vec<u8>]) -> Result<rustls::ClientConfig, TrustError> {
        let provider = crypto_provider();
        let builder = rustls::ClientConfig::builder_with_provider(provider.clone())
            .with_protocol_versions(&[&rustls::version::TLS13])?;
        let mut config = match self {
            Trust::CaFile(path) => {
                let mut roots = RootCertStore::empty();
                for cert in load_certificates(path)? {
                    roots.add(cert).map_err(|source| TrustError::BadAnchor { path: path.clone(), source })?;
                }
                builder.with_root_certificates(roots).with_no_client_auth()
            }
            Trust::Fingerprint(text) => {
                let expected = normalize_fingerprint(text).ok_or_else(|| TrustError::BadFingerprint(text.clone()))?;
                let verifier = PinnedFingerprint { expected, algorithms: provider.signature_verification_algorithms };
                builder.dangerous().with_custom_certificate_verifier(Arc::new(verifier)).with_no_client_auth()
            }
        };
        config.alpn_protocols = alpn_protocols.to_vec();
        Ok(config)
    }
}

/// Accepts exactly one end-entity certificate, by SHA-256 of its DER. Handshake signatures are still verified
/// with ring's algorithms, so only the holder of that certificate's key can complete the handshake.
#[derive(Debug)]
struct PinnedFingerprint {
    expected: String,
    algorithms: WebPkiSupportedAlgorithms,
}

impl ServerCertVerifier for PinnedFingerprint {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        let got = fingerprint_hex(end_entity);
        if got == self.expected {
            return Ok(ServerCertVerified::assertion());
        }
        let mismatch = FingerprintMismatch { expected: self.expected.clone(), got };
        Err(rustls::Error::InvalidCertificate(CertificateError::Other(rustls::OtherError(Arc::new(mismatch)))))
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

/// The server presented another certificate than the pinned one.
///
/// rustls and quinn carry a verifier's error to the application only as text (the QUIC close reason, where
/// rustls prints this type with `Debug`), so `Debug` writes a fixed marker that [`FingerprintMismatch::find_in`]
/// reads back.
#[derive(Clone, PartialEq, Eq, thiserror::Error)]
#[error("server certificate fingerprint {got} does not match the pinned {expected}")]
pub struct FingerprintMismatch {
    /// Pinned fingerprint.
    pub expected: String,
    /// Fingerprint of the certificate the server presented.
    pub got: String,
}

const MISMATCH_MARKER: &str = "kinloop-fingerprint-mismatch";

impl fmt::Debug for FingerprintMismatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{MISMATCH_MARKER} expected={} got={}", self.expected, self.got)
    }
}

impl FingerprintMismatch {
    /// Finds a mismatch written by `Debug` inside a longer text (a QUIC close reason).
    pub fn find_in(text: &str) -> Option<FingerprintMismatch> {
        let rest = &text[text.find(MISMATCH_MARKER)? + MISMATCH_MARKER.len()..];
        let mut words = rest.split(|c: char| !(c.is_ascii_alphanumeric() || c == '='));
        let mut value = |key: &str| words.find_map(|w| w.strip_prefix(key)).map(str::to_owned);
        let expected = value("expected=")?;
        let got = value("got=")?;
        Some(FingerprintMismatch { expected, got })
    }
}
