//! The listener around the router: at most `--max-connections` at once and
//! `--max-connections-per-ip` from one address (more are closed at once),
//! request headers within `--header-timeout` seconds (a slowloris client
//! is cut off, not waited for), HTTPS and WSS with `--tls-cert/--tls-key`
//! (rustls), the client's address for the access check, and a graceful
//! shutdown (answers in progress finish; new connections are refused).

use crate::setting::{check, InvalidSetting};
use axum::extract::ConnectInfo;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::collections::HashMap;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tokio_rustls::TlsAcceptor;
use tower_service::Service;

/// How the service takes connections (flags of `amc serve`).
#[derive(Clone, Debug)]
pub struct ListenConfig {
    /// `--tls-cert`: PEM certificate chain (with `tls_key`: HTTPS and WSS).
    pub tls_cert: Option<PathBuf>,
    /// `--tls-key`: PEM private key of `tls_cert`.
    pub tls_key: Option<PathBuf>,
    /// `--max-connections`: open connections at once.
    pub max_connections: usize,
    /// `--max-connections-per-ip`: open connections from one address.
    pub max_connections_per_ip: usize,
    /// `--header-timeout`: seconds a client has to send a request's headers
    /// (and, with TLS, to finish the handshake).
    pub header_timeout: u64,
}

impl Default for ListenConfig {
    fn default() -> Self {
        Self {
            tls_cert: None,
            tls_key: None,
            max_connections: 1024,
            max_connections_per_ip: 128,
            header_timeout: 10,
        }
    }
}

impl ListenConfig {
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        check("max-connections", self.max_connections, 1, 1_000_000)?;
        check(
            "max-connections-per-ip",
            self.max_connections_per_ip,
            1,
            self.max_connections,
        )?;
        check("header-timeout", self.header_timeout, 1, 3600)?;
        match (&self.tls_cert, &self.tls_key) {
            (Some(_), None) => Err(InvalidSetting {
                flag: "tls-key",
                detail: "missing: --tls-cert needs --tls-key (the certificate's private key, PEM)"
                    .into(),
            }),
            (None, Some(_)) => Err(InvalidSetting {
                flag: "tls-cert",
                detail: "missing: --tls-key needs --tls-cert (the certificate chain, PEM)".into(),
            }),
            _ => Ok(()),
        }
    }

    /// The TLS acceptor, when a certificate is given.
    pub fn tls(&self) -> Result<Option<TlsAcceptor>, InvalidSetting> {
        match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => tls_acceptor(cert, key).map(Some),
            _ => Ok(None),
        }
    }
}

fn tls_error(flag: &'static str, path: &Path, why: impl std::fmt::Display) -> InvalidSetting {
    InvalidSetting {
        flag,
        detail: format!("{}: {why}", path.display()),
    }
}

/// rustls with the ring provider, TLS 1.2 and 1.3, HTTP/1.1 by ALPN.
fn tls_acceptor(cert: &Path, key: &Path) -> Result<TlsAcceptor, InvalidSetting> {
    use rustls_pki_types::pem::PemObject;
    use rustls_pki_types::{CertificateDer, PrivateKeyDer};
    let certs = CertificateDer::pem_file_iter(cert)
        .map_err(|e| tls_error("tls-cert", cert, e))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| tls_error("tls-cert", cert, e))?;
    if certs.is_empty() {
        return Err(tls_error(
            "tls-cert",
            cert,
            "no certificate (PEM `CERTIFICATE` blocks)",
        ));
    }
    let key_der = PrivateKeyDer::from_pem_file(key).map_err(|e| tls_error("tls-key", key, e))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| tls_error("tls-cert", cert, e))?
        .with_no_client_auth()
        .with_single_cert(certs, key_der)
        .map_err(|e| tls_error("tls-key", key, format!("does not fit the certificate: {e}")))?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(TlsAcceptor::from(Arc::new(config)))
}

/// Connections open per client address.
#[derive(Default)]
struct PerIp(Mutex<HashMap<IpAddr, usize>>);

struct IpSlot(Arc<PerIp>, IpAddr);

impl PerIp {
    fn take(self: &Arc<Self>, ip: IpAddr, max: usize) -> Option<IpSlot> {
        let mut m = crate::poison::lock(&self.0);
        let n = m.entry(ip).or_insert(0);
        if *n >= max {
            return None;
        }
        *n += 1;
        Some(IpSlot(self.clone(), ip))
    }
}

impl Drop for IpSlot {
    fn drop(&mut self) {
        let mut m = crate::poison::lock(&self.0 .0);
        if let Some(n) = m.get_mut(&self.1) {
            *n -= 1;
            if *n == 0 {
                m.remove(&self.1);
            }
        }
    }
}

/// Serves `app` on `listener` until `shutdown` resolves, then lets the
/// answers in progress finish (at most `drain`).
pub async fn serve(
    listener: TcpListener,
    app: Router,
    config: &ListenConfig,
    tls: Option<TlsAcceptor>,
    shutdown: impl std::future::Future<Output = ()>,
    drain: Duration,
) {
    let connections = Arc::new(Semaphore::new(config.max_connections));
    let per_ip = Arc::new(PerIp::default());
    // Every connection's task, and the signal that asks them to finish the
    // answer in progress and close.
    let tasks = tokio_util::task::TaskTracker::new();
    let (stop, stopping) = tokio::sync::watch::channel(false);
    let header_timeout = Duration::from_secs(config.header_timeout);
    let mut refused_logged = std::time::Instant::now() - Duration::from_secs(60);
    tokio::pin!(shutdown);
    loop {
        let permit = tokio::select! {
            p = connections.clone().acquire_owned() => match p {
                Ok(p) => p,
                Err(_) => break,
            },
            _ = &mut shutdown => break,
        };
        let (stream, peer) = tokio::select! {
            r = listener.accept() => match r {
                Ok(x) => x,
                // Out of file descriptors and the like: wait, do not spin.
                Err(e) => {
                    tracing::warn!(error = %e, "cannot accept a connection now");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
            _ = &mut shutdown => break,
        };
        let Some(ip_slot) = per_ip.take(peer.ip(), config.max_connections_per_ip) else {
            if refused_logged.elapsed() > Duration::from_secs(10) {
                refused_logged = std::time::Instant::now();
                tracing::warn!(client = %peer.ip(), limit = config.max_connections_per_ip, "connections refused: too many open from one address (--max-connections-per-ip)");
            }
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let app = app.clone();
        let tls = tls.clone();
        let mut stopping = stopping.clone();
        tasks.spawn(async move {
            let _held = (permit, ip_slot);
            let service = hyper::service::service_fn(move |mut req: hyper::Request<Incoming>| {
                req.extensions_mut().insert(ConnectInfo(peer));
                let mut app = app.clone();
                async move { app.call(req).await }
            });
            let mut http = hyper::server::conn::http1::Builder::new();
            http.timer(TokioTimer::new())
                .header_read_timeout(header_timeout)
                .keep_alive(true);
            // One body for both transports (a macro: the two connection types differ).
            macro_rules! serve_until_stopped {
                ($io:expr) => {{
                    let conn = http
                        .serve_connection(TokioIo::new($io), service)
                        .with_upgrades();
                    let mut conn = std::pin::pin!(conn);
                    tokio::select! {
                        _ = conn.as_mut() => {}
                        _ = async { let _ = stopping.wait_for(|s| *s).await; } => {
                            conn.as_mut().graceful_shutdown();
                            let _ = conn.await;
                        }
                    }
                }};
            }
            match tls {
                Some(acceptor) => {
                    let Ok(Ok(stream)) =
                        tokio::time::timeout(header_timeout, acceptor.accept(stream)).await
                    else {
                        return;
                    };
                    serve_until_stopped!(stream)
                }
                None => serve_until_stopped!(stream),
            }
        });
    }
    drop(listener);
    stop.send_replace(true);
    tasks.close();
    if tokio::time::timeout(drain, tasks.wait()).await.is_err() {
        tracing::warn!("connections still open after the drain period; closing them");
    }
}
