//! Batch jobs: what the endpoints answer ([`view`]), the in-process job
//! table ([`store`]), the shared one's side of the endpoints ([`shared`],
//! with `--queue`/`--store`) and the `/jobs` endpoints ([`handlers`]).

mod handlers;
mod shared;
mod store;
mod view;

pub use handlers::{create, delete, get, list, output, telemetry};
pub use store::JobStore;
#[cfg(test)]
pub use view::rfc3339;
pub use view::{JobFile, JobMetrics, JobMotion, JobState};
