//! Live tickets (`POST /live/ticket`): browsers cannot set a header on a
//! WebSocket, so a page trades its key for a short-lived, single-use ticket
//! and opens `/live?ticket=...`. A ticket is bound to its key's tenant and
//! roles and is kept only as its SHA-256: in this process, or in the shared
//! job table's database with `--queue` (so any replica redeems it, once).

use super::keys::{hash_key, Principal};
use super::Roles;
use crate::cluster::queue::Queue;
use crate::cluster::ClusterError;
use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How long a ticket may wait before it is redeemed.
pub const TICKET_TTL: Duration = Duration::from_secs(30);

/// Most tickets outstanding in one process; older ones beyond this are
/// dropped (each needs a valid key, and keys are rate limited).
const MAX_LOCAL: usize = 10_000;

/// Where tickets are kept.
pub enum Tickets {
    Local(Mutex<HashMap<[u8; 32], (Principal, Instant)>>),
    Shared(Queue),
}

fn new_ticket() -> String {
    use rand::RngCore;
    let mut bytes = [0u8; 32];
    rand::rngs::OsRng.fill_bytes(&mut bytes);
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl Tickets {
    pub fn local() -> Self {
        Tickets::Local(Mutex::new(HashMap::new()))
    }

    /// A new ticket for `who`.
    pub async fn issue(&self, who: &Principal) -> Result<String, ClusterError> {
        let ticket = new_ticket();
        let hash = hash_key(&ticket);
        match self {
            Tickets::Local(map) => {
                let mut map = crate::poison::lock(map);
                let now = Instant::now();
                map.retain(|_, (_, expires)| *expires > now);
                if map.len() >= MAX_LOCAL {
                    if let Some(oldest) = map.iter().min_by_key(|(_, (_, e))| *e).map(|(k, _)| *k) {
                        map.remove(&oldest);
                    }
                }
                map.insert(hash, (who.clone(), now + TICKET_TTL));
            }
            Tickets::Shared(queue) => {
                queue
                    .insert_ticket(
                        &hash,
                        &who.tenant,
                        &who.roles.to_string(),
                        who.key,
                        TICKET_TTL,
                    )
                    .await?
            }
        }
        Ok(ticket)
    }

    /// The ticket's principal, once: a redeemed or expired ticket is `None`.
    pub async fn redeem(&self, ticket: &str) -> Result<Option<Principal>, ClusterError> {
        if ticket.len() != 64 || !ticket.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Ok(None);
        }
        let hash = hash_key(&ticket.to_ascii_lowercase());
        match self {
            Tickets::Local(map) => {
                let mut map = crate::poison::lock(map);
                Ok(map
                    .remove(&hash)
                    .filter(|(_, expires)| *expires > Instant::now())
                    .map(|(who, _)| who))
            }
            Tickets::Shared(queue) => {
                Ok(queue
                    .redeem_ticket(&hash)
                    .await?
                    .and_then(|(tenant, roles, key)| {
                        Some(Principal {
                            tenant,
                            roles: Roles::parse(&roles).ok()?,
                            key,
                        })
                    }))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_ticket_is_redeemed_once_and_carries_its_keys_tenant() {
        let t = Tickets::local();
        let who = Principal {
            tenant: "alice".into(),
            roles: Roles::VIEW,
            key: Some(3),
        };
        let ticket = t.issue(&who).await.unwrap();
        assert_eq!(ticket.len(), 64);
        assert!(t.redeem("0".repeat(64).as_str()).await.unwrap().is_none());
        assert!(t.redeem("not hex").await.unwrap().is_none());
        assert_eq!(t.redeem(&ticket).await.unwrap(), Some(who));
        assert!(t.redeem(&ticket).await.unwrap().is_none());
    }

    #[tokio::test]
    async fn an_expired_ticket_is_refused() {
        let t = Tickets::local();
        let ticket = t.issue(&Principal::local()).await.unwrap();
        if let Tickets::Local(map) = &t {
            for (_, exp) in map.lock().unwrap().values_mut() {
                *exp = Instant::now() - Duration::from_secs(1);
            }
        }
        assert!(t.redeem(&ticket).await.unwrap().is_none());
    }
}
