//! [`ClusterError`]: what can go wrong with the job table or the object store.

use std::path::PathBuf;

/// A failure of the shared job infrastructure. [`ClusterError::unreachable`]
/// tells a dependency that is down (answered 503 with `Retry-After`, and
/// retried) from anything else.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// A setting outside its range.
    #[error("invalid --{flag}: {detail}")]
    Invalid {
        /// The setting's flag, without dashes.
        flag: &'static str,
        /// The value and what is allowed.
        detail: String,
    },
    /// A query on the job table failed.
    #[error("PostgreSQL ({what}): {source}")]
    Database {
        /// What was being done.
        what: &'static str,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// The job table's schema could not be brought up to date.
    #[error("PostgreSQL (migrating the job table): {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// A request to the object store failed.
    #[error("object store ({what} {key}): {source}")]
    Store {
        /// What was being done.
        what: &'static str,
        /// The object's key.
        key: String,
        /// Why.
        #[source]
        source: object_store::Error,
    },
    /// A local file (an upload, a result) could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

impl ClusterError {
    /// A query error, tagged with what was being done.
    pub fn db(what: &'static str) -> impl FnOnce(sqlx::Error) -> Self {
        move |source| Self::Database { what, source }
    }

    /// An object-store error, tagged with what was being done and the key.
    pub fn store(what: &'static str, key: &str) -> impl FnOnce(object_store::Error) -> Self {
        let key = key.to_string();
        move |source| Self::Store { what, key, source }
    }

    /// Whether this is a dependency being down or overloaded (connection
    /// refused or reset, a pool or request timing out, a 5xx from the store),
    /// rather than a refusal that retrying would not change.
    pub fn unreachable(&self) -> bool {
        match self {
            ClusterError::Database { source, .. } => !matches!(
                source,
                sqlx::Error::Database(_)
                    | sqlx::Error::RowNotFound
                    | sqlx::Error::ColumnNotFound(_)
                    | sqlx::Error::ColumnDecode { .. }
                    | sqlx::Error::Decode(_)
                    | sqlx::Error::TypeNotFound { .. }
            ),
            ClusterError::Migrate(sqlx::migrate::MigrateError::Execute(e)) => {
                !matches!(e, sqlx::Error::Database(_))
            }
            ClusterError::Store { source, .. } => matches!(
                source,
                object_store::Error::Generic { .. } | object_store::Error::JoinError { .. }
            ),
            _ => false,
        }
    }

    /// Whether the store said the object does not exist.
    pub fn not_found(&self) -> bool {
        matches!(
            self,
            ClusterError::Store {
                source: object_store::Error::NotFound { .. },
                ..
            }
        )
    }
}
