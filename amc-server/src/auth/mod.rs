//! Who is asking (docs/security.md): API keys from `--auth-keys FILE`
//! ([`keys`]), roles per endpoint ([`roles`]), single-use live tickets for
//! browsers ([`tickets`]), limits on failures, rates and jobs ([`limits`]),
//! and the middleware that applies them to every request ([`gate`]).
//! Without `--auth-keys` every request is the `local` tenant with every
//! role: allowed only on a loopback address (or `--insecure-no-auth`).

pub mod gate;
pub mod keys;
pub mod limits;
pub mod roles;
pub mod tickets;

pub use keys::{new_key, valid_tenant, KeyTable, KeysError, Principal};
pub use roles::{Need, Roles};
pub use tickets::{Tickets, TICKET_TTL};

use crate::setting::{check, InvalidSetting};
use limits::{FailureGate, KeyRates, TenantSlots};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, RwLock};
use std::time::SystemTime;

/// The access settings of `amc serve` (and of `amc worker`'s `/metrics`).
#[derive(Clone, Debug)]
pub struct AuthConfig {
    /// `--auth-keys`: the keys file (`TENANT ROLES SHA256HEX` per line).
    pub keys_file: Option<PathBuf>,
    /// `--insecure-no-auth`: serve a non-loopback address without keys
    /// (a gateway in front checks who is asking).
    pub insecure_no_auth: bool,
    /// `--key-rate`: requests per second per key (bursts of twice as many).
    pub key_rate: u32,
    /// `--auth-failures`: failed keys per minute from one client address
    /// before it gets 429.
    pub auth_failures: u32,
    /// `--max-jobs-per-tenant`: a tenant's jobs queued or running, and
    /// uploads being received, at once.
    pub max_jobs_per_tenant: usize,
    /// `--cors-origin`: origins whose pages may call the API (none: CORS closed).
    pub cors_origins: Vec<String>,
}

impl Default for AuthConfig {
    fn default() -> Self {
        Self {
            keys_file: None,
            insecure_no_auth: false,
            key_rate: 50,
            auth_failures: 20,
            max_jobs_per_tenant: 8,
            cors_origins: Vec::new(),
        }
    }
}

impl AuthConfig {
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        check("key-rate", self.key_rate, 1, 100_000)?;
        check("auth-failures", self.auth_failures, 1, 10_000)?;
        check("max-jobs-per-tenant", self.max_jobs_per_tenant, 1, 100_000)?;
        for o in &self.cors_origins {
            if !valid_origin(o) {
                return Err(InvalidSetting {
                    flag: "cors-origin",
                    detail: format!(
                        "{o:?} (allowed: an origin, scheme://host[:port], e.g. https://app.example.com, no path)"
                    ),
                });
            }
        }
        if self.keys_file.is_some() && self.insecure_no_auth {
            return Err(InvalidSetting {
                flag: "insecure-no-auth",
                detail: "given with --auth-keys (allowed: one or the other)".into(),
            });
        }
        Ok(())
    }
}

/// `scheme://host[:port]`, http or https, nothing after.
fn valid_origin(o: &str) -> bool {
    let rest = o
        .strip_prefix("https://")
        .or_else(|| o.strip_prefix("http://"));
    rest.is_some_and(|r| {
        !r.is_empty()
            && r.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b".-:[]".contains(&b))
    })
}

/// The keys file as last read, and when it was written.
struct Loaded {
    path: PathBuf,
    table: RwLock<Arc<KeyTable>>,
    modified: Mutex<Option<SystemTime>>,
}

/// Access control shared by every request.
pub struct Auth {
    pub config: AuthConfig,
    keys: Option<Loaded>,
    pub tickets: Tickets,
    pub failures: FailureGate,
    pub rates: KeyRates,
    pub slots: TenantSlots,
}

fn modified(path: &std::path::Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

impl Auth {
    /// Reads the keys file (if any); tickets live in `tickets`.
    pub fn new(config: AuthConfig, tickets: Tickets) -> Result<Self, KeysError> {
        let keys = match &config.keys_file {
            Some(path) => Some(Loaded {
                modified: Mutex::new(modified(path)),
                table: RwLock::new(Arc::new(KeyTable::load(path)?)),
                path: path.clone(),
            }),
            None => None,
        };
        Ok(Self {
            failures: FailureGate::new(config.auth_failures),
            rates: KeyRates::new(config.key_rate),
            slots: TenantSlots::default(),
            tickets,
            keys,
            config,
        })
    }

    /// Whether requests need a key.
    pub fn enabled(&self) -> bool {
        self.keys.is_some()
    }

    /// Keys in the file now.
    pub fn key_count(&self) -> usize {
        self.keys.as_ref().map_or(0, |k| self.table(k).len())
    }

    fn table(&self, k: &Loaded) -> Arc<KeyTable> {
        k.table.read().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// The key's principal (`None`: wrong key). Without keys, everyone is local.
    pub fn lookup(&self, key: &str) -> Option<Principal> {
        match &self.keys {
            Some(k) => self.table(k).lookup(key),
            None => Some(Principal::local()),
        }
    }

    /// Reads the keys file again when it changed (keys added or revoked
    /// without a restart); a file that no longer parses keeps the old keys.
    pub fn reload_if_changed(&self) {
        let Some(k) = &self.keys else { return };
        let now = modified(&k.path);
        let mut seen = crate::poison::lock(&k.modified);
        if now == *seen {
            return;
        }
        *seen = now;
        match KeyTable::load(&k.path) {
            Ok(table) => {
                let n = table.len();
                *k.table.write().unwrap_or_else(|e| e.into_inner()) = Arc::new(table);
                tracing::info!(keys = n, file = %k.path.display(), "keys file read again");
            }
            Err(e) => {
                tracing::error!(error = %e, "the keys file changed but cannot be used; the previous keys stay in force")
            }
        }
    }

    /// The once-a-second housekeeping.
    pub fn tick(&self) {
        self.failures.tidy();
        self.rates.tidy();
        self.reload_if_changed();
    }

    /// A tenant's slot for a job or upload; 429 at `--max-jobs-per-tenant`
    /// (only with keys: without them there is one tenant, bounded by
    /// `--workers` and `--max-queued`).
    pub fn take_slot(
        &self,
        who: &Principal,
    ) -> Result<Option<limits::TenantSlot>, crate::serve::problem::ApiError> {
        if !self.enabled() {
            return Ok(None);
        }
        let max = self.config.max_jobs_per_tenant;
        self.slots
            .take(&who.tenant, max)
            .map(Some)
            .map_err(|held| too_many_jobs(&who.tenant, held as u64, max))
    }
}

/// 429 for a tenant at its limit of jobs.
pub fn too_many_jobs(tenant: &str, held: u64, max: usize) -> crate::serve::problem::ApiError {
    crate::serve::problem::ApiError::TooManyRequests {
        detail: format!(
            "tenant {tenant:?} has {held} jobs queued, running or uploading (allowed: {max} at once, \
             --max-jobs-per-tenant); try again when one has finished"
        ),
        retry_after_s: crate::serve::problem::RETRY_AFTER_SECS,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origins_are_scheme_host_and_port_only() {
        assert!(valid_origin("https://app.example.com"));
        assert!(valid_origin("http://localhost:5173"));
        assert!(!valid_origin("app.example.com"));
        assert!(!valid_origin("https://app.example.com/"));
        assert!(!valid_origin("*"));
    }

    #[test]
    fn a_changed_keys_file_is_read_again_and_a_broken_one_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("keys");
        let (k1, l1) = new_key("a", "submit").unwrap();
        let (k2, l2) = new_key("b", "view").unwrap();
        std::fs::write(&path, format!("{l1}\n")).unwrap();
        let auth = Auth::new(
            AuthConfig {
                keys_file: Some(path.clone()),
                ..AuthConfig::default()
            },
            Tickets::local(),
        )
        .unwrap();
        assert!(auth.lookup(&k1).is_some() && auth.lookup(&k2).is_none());
        std::fs::write(&path, format!("{l2}\n")).unwrap();
        // Some filesystems keep whole-second times: force a different one.
        let later = SystemTime::now() + std::time::Duration::from_secs(5);
        std::fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(later)
            .unwrap();
        auth.reload_if_changed();
        assert!(auth.lookup(&k1).is_none() && auth.lookup(&k2).is_some());
        std::fs::write(&path, "garbage\n").unwrap();
        std::fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(later + std::time::Duration::from_secs(5))
            .unwrap();
        auth.reload_if_changed();
        assert!(
            auth.lookup(&k2).is_some(),
            "a broken file keeps the old keys"
        );
    }
}
