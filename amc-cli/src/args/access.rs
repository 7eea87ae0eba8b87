//! Who may ask what, and how connections are taken: the flags of `amc
//! serve` (and the keys flags `amc worker` shares) that fill
//! `amc_server::auth::AuthConfig` and `amc_server::serve::ListenConfig`.

use amc_server::auth::AuthConfig;
use amc_server::serve::ListenConfig;
use clap::Args;
use std::path::PathBuf;

/// The keys file and its escape hatch (`amc serve` and `amc worker`).
#[derive(Args, Debug, Clone)]
pub struct KeysFlags {
    /// API keys: a file of lines `TENANT ROLES SHA256HEX` (ROLES: a comma list
    /// of submit, view, publish, admin; make a key with `amc keys new`).
    /// Requests then need `Authorization: Bearer KEY`. Without it the service
    /// listens only on a loopback address. The file is read again when it changes.
    #[arg(long, value_name = "FILE")]
    pub auth_keys: Option<PathBuf>,
    /// Serve a non-loopback --addr without keys, for a gateway in front that
    /// checks who is asking. Anyone who reaches the port may use every endpoint.
    #[arg(long, conflicts_with = "auth_keys")]
    pub insecure_no_auth: bool,
}

/// `amc serve`'s access and connection flags.
#[derive(Args, Debug, Clone)]
pub struct AccessFlags {
    #[command(flatten)]
    pub keys: KeysFlags,
    /// Requests per second one key may send (bursts of twice as many); more get 429.
    #[arg(long, default_value_t = AuthConfig::default().key_rate)]
    pub key_rate: u32,
    /// Wrong keys a minute from one client address before it gets 429 for a while.
    #[arg(long, default_value_t = AuthConfig::default().auth_failures)]
    pub auth_failures: u32,
    /// Jobs one tenant may have queued, running or uploading at once (with --auth-keys); more get 429.
    #[arg(long, default_value_t = AuthConfig::default().max_jobs_per_tenant)]
    pub max_jobs_per_tenant: usize,
    /// An origin (https://host[:port]) whose pages may call the API from the
    /// browser (CORS) and open its WebSockets; repeat for more. Default: none,
    /// only the service's own page.
    #[arg(long, value_name = "ORIGIN")]
    pub cors_origin: Vec<String>,
    /// Certificate chain (PEM) to serve HTTPS and WSS with (needs --tls-key).
    #[arg(long, value_name = "PEM", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// Private key (PEM) of --tls-cert.
    #[arg(long, value_name = "PEM", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Connections open at once; more wait to be accepted.
    #[arg(long, default_value_t = ListenConfig::default().max_connections)]
    pub max_connections: usize,
    /// Connections open at once from one client address; more are closed.
    #[arg(long, default_value_t = ListenConfig::default().max_connections_per_ip)]
    pub max_connections_per_ip: usize,
    /// Seconds a client has to send a request's headers (and finish the TLS
    /// handshake); a slower one is disconnected.
    #[arg(long, default_value_t = ListenConfig::default().header_timeout)]
    pub header_timeout: u64,
}

impl KeysFlags {
    pub fn config(self) -> AuthConfig {
        AuthConfig {
            keys_file: self.auth_keys,
            insecure_no_auth: self.insecure_no_auth,
            ..AuthConfig::default()
        }
    }
}

impl AccessFlags {
    /// The library's settings.
    pub fn config(self) -> (AuthConfig, ListenConfig) {
        let auth = AuthConfig {
            key_rate: self.key_rate,
            auth_failures: self.auth_failures,
            max_jobs_per_tenant: self.max_jobs_per_tenant,
            cors_origins: self.cors_origin,
            ..self.keys.config()
        };
        let listen = ListenConfig {
            tls_cert: self.tls_cert,
            tls_key: self.tls_key,
            max_connections: self.max_connections,
            max_connections_per_ip: self.max_connections_per_ip,
            header_timeout: self.header_timeout,
        };
        (auth, listen)
    }
}
