//! Locking a mutex whose holder panicked: the service's shared state (job
//! tables, counters, key tables, tickets) stays valid through a panic, and a
//! panic costs one request, never the service, so a poisoned lock is taken.

use std::sync::{Mutex, MutexGuard};

/// Locks `m`, poisoned or not.
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
