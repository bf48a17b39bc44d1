//! TLS through rustls (ring provider): the server side of `https`/`wss` and the client side
//! of `wss://` connections.

use std::path::Path;
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};
use tokio::net::TcpStream;
pub use tokio_rustls::{TlsAcceptor, TlsConnector};

use crate::io::BoxIo;
use crate::NetError;

fn provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

fn tls_error(what: String) -> impl FnOnce(rustls::Error) -> NetError {
    move |e| NetError::Tls(format!("{what}: {e}"))
}

fn pem_error(path: &Path) -> impl FnOnce(rustls::pki_types::pem::Error) -> NetError + '_ {
    move |e| NetError::Tls(format!("{}: {e}", path.display()))
}

/// A TLS acceptor serving the certificate chain in PEM file `cert` with the private key in
/// PEM file `key`.
pub fn acceptor(cert: &Path, key: &Path) -> Result<TlsAcceptor, NetError> {
    let chain = CertificateDer::pem_file_iter(cert)
        .map_err(pem_error(cert))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(pem_error(cert))?;
    if chain.is_empty() {
        return Err(NetError::Tls(format!(
            "{}: no certificate in the file",
            cert.display()
        )));
    }
    let key = PrivateKeyDer::from_pem_file(key).map_err(pem_error(key))?;
    let config = rustls::ServerConfig::builder_with_provider(provider())
        .with_safe_default_protocol_versions()
        .map_err(tls_error("TLS versions".into()))?
        .with_no_client_auth()
        .with_single_cert(chain, key)
        .map_err(tls_error("the certificate and key do not fit".into()))?;
    Ok(TlsAcceptor::from(Arc::new(config)))
}

/// A TLS connector trusting the certificates in PEM file `ca`, or else the Mozilla roots
/// (webpki-roots).
pub fn connector(ca: Option<&Path>) -> Result<TlsConnector, NetError> {
    let mut roots = rustls::RootCertStore::empty();
    match ca {
        Some(path) => {
            for cert in CertificateDer::pem_file_iter(path).map_err(pem_error(path))? {
                roots
                    .add(cert.map_err(pem_error(path))?)
                    .map_err(tls_error(format!("{}", path.display())))?;
            }
            if roots.is_empty() {
                return Err(NetError::Tls(format!(
                    "{}: no certificate in the file",
                    path.display()
                )));
            }
        }
        None => roots.extend(webpki_roots::TLS_SERVER_ROOTS.iter().cloned()),
    }
    let config = rustls::ClientConfig::builder_with_provider(provider())
        .with_safe_default_protocol_versions()
        .map_err(tls_error("TLS versions".into()))?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(TlsConnector::from(Arc::new(config)))
}

/// Client side: a TLS session over `tcp` with `host` (a DNS name or an IP address).
pub async fn connect(
    connector: &TlsConnector,
    host: &str,
    tcp: TcpStream,
) -> Result<BoxIo, NetError> {
    let name = ServerName::try_from(host.to_string())
        .map_err(|_| NetError::Tls(format!("`{host}` is no valid server name")))?;
    let stream = connector
        .connect(name, tcp)
        .await
        .map_err(|e| NetError::Tls(format!("handshake with {host}: {e}")))?;
    Ok(Box::new(stream))
}
