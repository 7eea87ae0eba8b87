//! Settings of the shared job infrastructure: where the job table and the
//! objects live, and how long a worker's claim on a job lasts.

use super::error::ClusterError;
use std::time::Duration;

/// Where the job table and the videos live, and the job life's timings
/// (`--queue`, `--store` and the flags beside them, shared by `amc serve`
/// and `amc worker`).
#[derive(Clone, Debug)]
pub struct ClusterConfig {
    /// PostgreSQL URL of the job table (`postgres://USER[:PASS]@HOST[:PORT]/DB`).
    pub queue_url: String,
    /// The object store.
    pub store: StoreConfig,
    /// How long a worker's claim on a job lasts without being renewed
    /// (2..=3600 s; default 30). A worker renews it twice a second; a job
    /// whose worker died is retried once its lease has run out.
    pub lease: Duration,
    /// Claims of one job before it is failed (1..=100; default 3): a job
    /// whose workers keep dying (its input crashes them, or the machine is
    /// too small) is not retried forever.
    pub max_attempts: u32,
    /// How long a finished job's row and objects are kept.
    pub job_ttl: Duration,
}

impl ClusterConfig {
    /// Default lease, seconds.
    pub const LEASE_SECS: u64 = 30;
    /// Default claims of one job.
    pub const MAX_ATTEMPTS: u32 = 3;

    /// Checks every setting; the error names the flag, the value and the range.
    pub fn validate(&self) -> Result<(), ClusterError> {
        let url = &self.queue_url;
        if !(url.starts_with("postgres://") || url.starts_with("postgresql://")) {
            return Err(ClusterError::Invalid {
                flag: "queue",
                detail: format!(
                    "{:?} (allowed: a PostgreSQL URL, postgres://USER@HOST:PORT/DATABASE)",
                    redact(url)
                ),
            });
        }
        let lease = self.lease.as_secs();
        if !(2..=3600).contains(&lease) {
            return Err(ClusterError::Invalid {
                flag: "lease-secs",
                detail: format!("{lease} (allowed: 2..=3600)"),
            });
        }
        if !(1..=100).contains(&self.max_attempts) {
            return Err(ClusterError::Invalid {
                flag: "max-attempts",
                detail: format!("{} (allowed: 1..=100)", self.max_attempts),
            });
        }
        Ok(())
    }
}

/// An S3-compatible bucket. Unset fields come from the usual `AWS_*`
/// environment variables (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
/// `AWS_SESSION_TOKEN`, `AWS_REGION`/`AWS_DEFAULT_REGION`, `AWS_ENDPOINT_URL`).
#[derive(Clone, Debug, Default)]
pub struct StoreConfig {
    /// The bucket, from `s3://BUCKET[/PREFIX]`.
    pub bucket: String,
    /// Key prefix inside the bucket (no leading or trailing `/`; may be empty).
    pub prefix: String,
    /// Endpoint of a server other than AWS (`http://127.0.0.1:8333`).
    pub endpoint: Option<String>,
    /// Region (default: `AWS_REGION`, else `us-east-1`).
    pub region: Option<String>,
    /// Path-style requests (`ENDPOINT/BUCKET/KEY`), as SeaweedFS and MinIO
    /// need (default: on when an endpoint is given, off for AWS).
    pub path_style: Option<bool>,
    /// Access key id (default: `AWS_ACCESS_KEY_ID`).
    pub access_key_id: Option<String>,
    /// Secret access key (default: `AWS_SECRET_ACCESS_KEY`).
    pub secret_access_key: Option<String>,
}

impl StoreConfig {
    /// Parses `s3://BUCKET[/PREFIX]`.
    pub fn from_url(url: &str) -> Result<Self, ClusterError> {
        let bad = |why: &str| ClusterError::Invalid {
            flag: "store",
            detail: format!("{url:?}: {why} (allowed: s3://BUCKET or s3://BUCKET/PREFIX)"),
        };
        let rest = url
            .strip_prefix("s3://")
            .ok_or_else(|| bad("not an s3:// URL"))?;
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        // S3's bucket naming rules: 3-63 of a-z, 0-9, '.', '-'.
        let valid_bucket = (3..=63).contains(&bucket.len())
            && bucket
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'.' || b == b'-');
        if !valid_bucket {
            return Err(bad("the bucket name must be 3-63 of a-z, 0-9, '.' and '-'"));
        }
        let prefix = prefix.trim_matches('/');
        if prefix
            .split('/')
            .any(|part| part == "." || part == ".." || (part.is_empty() && !prefix.is_empty()))
        {
            return Err(bad("the prefix has an empty, '.' or '..' part"));
        }
        Ok(Self {
            bucket: bucket.to_string(),
            prefix: prefix.to_string(),
            ..Self::default()
        })
    }
}

/// A URL with its password replaced by `***` (for messages and logs).
pub fn redact(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let (authority, tail) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
    match authority.rsplit_once('@') {
        Some((userinfo, host)) => match userinfo.split_once(':') {
            Some((user, _)) => format!("{scheme}://{user}:***@{host}{tail}"),
            None => url.to_string(),
        },
        None => url.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn store_urls_name_a_bucket_and_a_clean_prefix() {
        let s = StoreConfig::from_url("s3://amc-videos").unwrap();
        assert_eq!((s.bucket.as_str(), s.prefix.as_str()), ("amc-videos", ""));
        let s = StoreConfig::from_url("s3://amc/team/a/").unwrap();
        assert_eq!((s.bucket.as_str(), s.prefix.as_str()), ("amc", "team/a"));
        for bad in [
            "amc",
            "http://amc",
            "s3://",
            "s3://AB",
            "s3://Bucket",
            "s3://amc/a//b",
            "s3://amc/../x",
        ] {
            let e = StoreConfig::from_url(bad).unwrap_err().to_string();
            assert!(e.contains("--store") && e.contains("allowed"), "{bad}: {e}");
        }
    }

    #[test]
    fn passwords_never_reach_a_message() {
        assert_eq!(
            redact("postgres://amc:secret@db:5432/amc"),
            "postgres://amc:***@db:5432/amc"
        );
        assert_eq!(redact("postgres://amc@db/amc"), "postgres://amc@db/amc");
        let config = ClusterConfig {
            queue_url: "mysql://u:hunter2@h/db".into(),
            store: StoreConfig::default(),
            lease: Duration::from_secs(30),
            max_attempts: 3,
            job_ttl: Duration::from_secs(60),
        };
        let e = config.validate().unwrap_err().to_string();
        assert!(e.contains("--queue") && !e.contains("hunter2"), "{e}");
        let e = ClusterConfig {
            queue_url: "postgres://h/db".into(),
            lease: Duration::from_secs(1),
            ..config.clone()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("--lease-secs") && e.contains("2..=3600"), "{e}");
        let e = ClusterConfig {
            queue_url: "postgres://h/db".into(),
            max_attempts: 0,
            ..config
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("--max-attempts"), "{e}");
    }
}
