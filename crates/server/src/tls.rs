//! TLS for the server (rustls with ring, through tonic's `tls-ring` feature), optionally with
//! client certificates (mTLS).
//!
//! ```text
//! --tls-cert server.pem --tls-key server.key         TLS; clients verify the server's chain
//! ... --tls-client-ca clients-ca.pem                 mTLS: every client must present a
//!                                                    certificate signed by that CA, or the
//!                                                    handshake fails
//! ```
//!
//! Files are PEM: the certificate file may hold the chain (leaf first); the key is PKCS#8,
//! PKCS#1 (RSA) or SEC1 (EC). Certificates are read once at start (no reload). Without these
//! flags the server speaks plaintext HTTP/2, as before. Health and reflection are served on the
//! same port and so need TLS too when it is on.

use crate::{Error, Result};
use std::path::Path;
use tonic::transport::{Certificate, Identity, ServerTlsConfig};

/// The server's certificate and key, and the CA its clients' certificates must chain to.
#[derive(Clone)]
pub struct TlsConfig {
    /// Certificate chain, PEM.
    cert_pem: Vec<u8>,
    /// Private key, PEM.
    key_pem: Vec<u8>,
    /// mTLS: the client CA's certificate(s), PEM.
    client_ca_pem: Option<Vec<u8>>,
}

impl std::fmt::Debug for TlsConfig {
    /// Never prints the key.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TlsConfig").field("mtls", &self.client_ca_pem.is_some()).finish_non_exhaustive()
    }
}

impl TlsConfig {
    /// From PEM bytes, checked by building the rustls acceptor once.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `tls` when the certificate, key or CA do not parse or
    /// do not match.
    pub fn from_pem(cert_pem: Vec<u8>, key_pem: Vec<u8>, client_ca_pem: Option<Vec<u8>>) -> Result<Self> {
        let config = Self { cert_pem, key_pem, client_ca_pem };
        tonic::transport::Server::builder()
            .tls_config(config.server_tls())
            .map_err(|e| Error::invalid("tls", format!("unusable certificate, key or client CA: {e}")))?;
        Ok(config)
    }

    /// Reads the PEM files of `--tls-cert`, `--tls-key` and `--tls-client-ca`.
    ///
    /// # Errors
    /// [`Error::Io`] naming the file that cannot be read; those of [`TlsConfig::from_pem`].
    pub fn load(cert: &Path, key: &Path, client_ca: Option<&Path>) -> Result<Self> {
        let read = |p: &Path| {
            std::fs::read(p).map_err(|e| Error::Io(std::io::Error::new(e.kind(), format!("{}: {e}", p.display()))))
        };
        let client_ca_pem = client_ca.map(read).transpose()?;
        Self::from_pem(read(cert)?, read(key)?, client_ca_pem)
    }

    /// Whether clients must present a certificate (mTLS).
    pub fn mutual(&self) -> bool {
        self.client_ca_pem.is_some()
    }

    /// tonic's server TLS settings.
    pub(crate) fn server_tls(&self) -> ServerTlsConfig {
        let tls = ServerTlsConfig::new().identity(Identity::from_pem(&self.cert_pem, &self.key_pem));
        match &self.client_ca_pem {
            Some(ca) => tls.client_ca_root(Certificate::from_pem(ca)).client_auth_optional(false),
            None => tls,
        }
    }
}
