//! Limits on who asks how often: failed keys per client address (then 429
//! for a while), requests per key, and jobs per tenant.
//! The rates are `governor`'s GCRA; the per-tenant counts are plain.

use crate::poison::lock;
use governor::clock::{Clock, DefaultClock};
use governor::state::keyed::DefaultKeyedStateStore;
use governor::{Quota, RateLimiter};
use std::collections::HashMap;
use std::net::IpAddr;
use std::num::NonZeroU32;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

type Keyed<K> = RateLimiter<K, DefaultKeyedStateStore<K>, DefaultClock>;

/// Most client addresses remembered as blocked; beyond it the soonest to
/// be released are forgotten first.
const MAX_BLOCKED: usize = 100_000;

fn nz(n: u32) -> NonZeroU32 {
    NonZeroU32::new(n.max(1)).unwrap_or(NonZeroU32::MIN)
}

/// Whole seconds to wait, at least 1 (for `Retry-After`).
pub fn retry_secs(d: Duration) -> u64 {
    d.as_secs() + u64::from(d.subsec_nanos() > 0)
}

/// Failed keys from one address: `per_minute` allowed (a burst of as many),
/// then every wrong key or ticket from it is answered 429 until a failure
/// is allowed again (right keys are still served: see the gate).
pub struct FailureGate {
    failures: Keyed<IpAddr>,
    blocked: Mutex<HashMap<IpAddr, Instant>>,
    clock: DefaultClock,
}

impl FailureGate {
    pub fn new(per_minute: u32) -> Self {
        Self {
            failures: RateLimiter::keyed(Quota::per_minute(nz(per_minute))),
            blocked: Mutex::new(HashMap::new()),
            clock: DefaultClock::default(),
        }
    }

    /// How long `ip` must still wait, if it is blocked.
    pub fn blocked(&self, ip: IpAddr) -> Option<Duration> {
        let mut blocked = lock(&self.blocked);
        let until = *blocked.get(&ip)?;
        let now = Instant::now();
        if until > now {
            return Some(until - now);
        }
        blocked.remove(&ip);
        None
    }

    /// Counts a failed key from `ip`; `Some(wait)` when that was one too many.
    pub fn fail(&self, ip: IpAddr) -> Option<Duration> {
        let wait = match self.failures.check_key(&ip) {
            Ok(()) => return None,
            Err(not_until) => not_until.wait_time_from(self.clock.now()),
        }
        .max(Duration::from_secs(1));
        let mut blocked = lock(&self.blocked);
        if blocked.len() >= MAX_BLOCKED {
            let now = Instant::now();
            blocked.retain(|_, until| *until > now);
        }
        if blocked.len() < MAX_BLOCKED {
            blocked.insert(ip, Instant::now() + wait);
        }
        Some(wait)
    }

    /// Forgets addresses whose budget is full again (the once-a-second tick).
    pub fn tidy(&self) {
        self.failures.retain_recent();
        let now = Instant::now();
        lock(&self.blocked).retain(|_, until| *until > now);
    }
}

/// Requests per key: `per_second` sustained, bursts of twice as many.
pub struct KeyRates {
    rates: Keyed<usize>,
    clock: DefaultClock,
}

impl KeyRates {
    pub fn new(per_second: u32) -> Self {
        let quota = Quota::per_second(nz(per_second)).allow_burst(nz(per_second.saturating_mul(2)));
        Self {
            rates: RateLimiter::keyed(quota),
            clock: DefaultClock::default(),
        }
    }

    /// `Some(wait)` when the key (its line in the keys file) is over its rate.
    pub fn check(&self, key: usize) -> Option<Duration> {
        self.rates
            .check_key(&key)
            .err()
            .map(|n| n.wait_time_from(self.clock.now()))
    }

    pub fn tidy(&self) {
        self.rates.retain_recent();
    }
}

/// Jobs and uploads a tenant has in this process at once.
#[derive(Default)]
pub struct TenantSlots {
    held: Arc<Mutex<HashMap<String, usize>>>,
}

/// One of a tenant's slots, given back when dropped.
pub struct TenantSlot {
    held: Arc<Mutex<HashMap<String, usize>>>,
    tenant: String,
}

impl Drop for TenantSlot {
    fn drop(&mut self) {
        let mut held = lock(&self.held);
        if let Some(n) = held.get_mut(&self.tenant) {
            *n -= 1;
            if *n == 0 {
                held.remove(&self.tenant);
            }
        }
    }
}

impl TenantSlots {
    /// A slot of `tenant`, or `Err(held)` when it already holds `max`.
    pub fn take(&self, tenant: &str, max: usize) -> Result<TenantSlot, usize> {
        let mut held = lock(&self.held);
        let n = held.entry(tenant.to_string()).or_insert(0);
        if *n >= max {
            return Err(*n);
        }
        *n += 1;
        Ok(TenantSlot {
            held: self.held.clone(),
            tenant: tenant.to_string(),
        })
    }

    pub fn held(&self, tenant: &str) -> usize {
        lock(&self.held).get(tenant).copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failures_beyond_the_budget_block_the_address_and_only_it() {
        let gate = FailureGate::new(10);
        let a: IpAddr = "192.0.2.1".parse().unwrap();
        let b: IpAddr = "192.0.2.2".parse().unwrap();
        for _ in 0..10 {
            assert!(gate.fail(a).is_none());
        }
        let wait = gate.fail(a).expect("the 11th failure is one too many");
        assert!(
            wait >= Duration::from_secs(1) && wait <= Duration::from_secs(7),
            "{wait:?}"
        );
        assert!(gate.blocked(a).is_some());
        assert!(gate.blocked(b).is_none());
        assert!(gate.fail(b).is_none());
    }

    #[test]
    fn a_key_over_its_rate_waits_and_others_do_not() {
        let rates = KeyRates::new(5);
        let over = (0..11).filter(|_| rates.check(0).is_some()).count();
        assert_eq!(over, 1, "a burst of 10 passes, the 11th waits");
        assert!(rates.check(1).is_none());
    }

    #[test]
    fn tenant_slots_are_given_back_when_dropped() {
        let slots = TenantSlots::default();
        let a = slots.take("a", 2).unwrap();
        let _b = slots.take("a", 2).unwrap();
        assert_eq!(slots.take("a", 2).err(), Some(2));
        assert!(slots.take("b", 2).is_ok());
        drop(a);
        assert_eq!(slots.held("a"), 1);
        assert!(slots.take("a", 2).is_ok());
    }

    #[test]
    fn retry_after_rounds_up() {
        assert_eq!(retry_secs(Duration::from_millis(1)), 1);
        assert_eq!(retry_secs(Duration::from_secs(6)), 6);
        assert_eq!(retry_secs(Duration::from_millis(6001)), 7);
    }
}
