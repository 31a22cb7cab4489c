//! A room's certificate authority: the servers of a room present certificates it issued, so a client that
//! trusts the CA (`--ca FILE`) trusts whichever of them it reaches, where a pinned fingerprint names one.

use std::path::Path;

use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, DistinguishedName, DnType, IsCa, KeyPair};

use super::identity::{write_private, IdentityError};

/// A CA's certificate and key, in memory.
pub struct RoomCa {
    issuer: CertifiedIssuer<'static, KeyPair>,
}

impl RoomCa {
    /// A fresh self-signed CA called `name`.
    pub fn generate(name: &str) -> Result<Self, IdentityError> {
        let mut params = CertificateParams::new(Vec::<String>::new())?;
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        let mut subject = DistinguishedName::new();
        subject.push(DnType::CommonName, name);
        params.distinguished_name = subject;
        Ok(RoomCa { issuer: CertifiedIssuer::self_signed(params, KeyPair::generate()?)? })
    }

    /// The CA certificate (PEM), what clients trust.
    pub fn cert_pem(&self) -> String {
        self.issuer.pem()
    }

    /// A server certificate for `names` (DNS names or IP addresses) signed by this CA, and its key (PEM).
    pub fn issue(&self, names: &[&str]) -> Result<(String, String), IdentityError> {
        let params = CertificateParams::new(names.iter().map(|n| n.to_string()).collect::<Vec<_>>())?;
        let key = KeyPair::generate()?;
        let cert = params.signed_by(&key, &self.issuer)?;
        Ok((cert.pem(), key.serialize_pem()))
    }

    /// Writes the CA certificate to `ca_path`, and a server certificate for `names` with its key to
    /// `cert_path` and `key_path` (the key readable by its owner only).
    pub fn write(
        &self,
        ca_path: &Path,
        names: &[&str],
        cert_path: &Path,
        key_path: &Path,
    ) -> Result<(), IdentityError> {
        let write = |path: &Path, text: String| {
            std::fs::write(path, text).map_err(|source| IdentityError::Io { path: path.to_owned(), source })
        };
        write(ca_path, self.cert_pem())?;
        let (cert, key) = self.issue(names)?;
        write_private(key_path, key.as_bytes())?;
        write(cert_path, cert)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quic::ServerIdentity;

    #[test]
    fn an_issued_certificate_loads_as_a_server_identity_distinct_per_server() {
        let dir = tempfile::tempdir().unwrap();
        let ca = RoomCa::generate("room").unwrap();
        let path = |name: &str| dir.path().join(name);
        ca.write(&path("ca.pem"), &["localhost"], &path("a.pem"), &path("a.key")).unwrap();
        ca.write(&path("ca.pem"), &["localhost"], &path("b.pem"), &path("b.key")).unwrap();
        let a = ServerIdentity::load(&path("a.pem"), &path("a.key")).unwrap();
        let b = ServerIdentity::load(&path("b.pem"), &path("b.key")).unwrap();
        assert_ne!(a.fingerprint, b.fingerprint, "two servers, two certificates");
        assert!(std::fs::read_to_string(path("ca.pem")).unwrap().contains("BEGIN CERTIFICATE"));
    }
}
