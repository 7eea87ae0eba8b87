//! Batch jobs: the job table ([`store`]) and the `/jobs` endpoints
//! ([`handlers`]).

mod handlers;
mod store;

pub use handlers::{create, delete, get, list, output, telemetry};
#[cfg(test)]
pub use store::rfc3339;
pub use store::{JobState, JobStore};
