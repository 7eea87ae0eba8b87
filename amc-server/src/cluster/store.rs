//! [`Store`]: uploads and results as objects in an S3-compatible bucket
//! (AWS S3, SeaweedFS, MinIO, ...) through the `object_store` crate.
//!
//! Keys, under the configured prefix:
//! - `jobs/{id}/input`: the upload, written once by the replica that took it;
//! - `jobs/{id}/gyro.{ext}`: a gyro log sent with it (the `gyro` form
//!   field), written and removed with the upload;
//! - `jobs/{id}/{attempt}/output.{ext}` and `.../telemetry.csv`: one
//!   worker's results. Each claim writes under its own attempt number, so a
//!   worker that was presumed dead cannot overwrite another's output, and
//!   the row names the one attempt whose output counts. A single PUT (or a
//!   completed multipart upload) makes an object appear whole or not at all.

use super::config::StoreConfig;
use super::error::ClusterError;
use bytes::Bytes;
use futures_util::stream::BoxStream;
use futures_util::StreamExt;
use object_store::aws::{AmazonS3Builder, AmazonS3ConfigKey};
use object_store::buffered::BufWriter;
use object_store::path::Path as Key;
use object_store::{ClientOptions, ObjectStore, ObjectStoreExt, RetryConfig};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::AsyncWriteExt;

/// The bucket (and prefix) the service keeps its videos in.
#[derive(Clone)]
pub struct Store {
    inner: Arc<dyn ObjectStore>,
    prefix: String,
    /// `s3://BUCKET/PREFIX`, for logs.
    pub location: String,
}

impl Store {
    /// A client of the configured bucket (nothing is sent until it is used).
    pub fn new(config: &StoreConfig) -> Result<Self, ClusterError> {
        let invalid = |e: object_store::Error| ClusterError::Invalid {
            flag: "store",
            detail: e.to_string(),
        };
        // A store that is down must be answered quickly (503), not after
        // minutes of retries; a large object may take long to stream. (The
        // client options go first: setting them replaces `allow_http`.)
        let mut builder = AmazonS3Builder::from_env()
            .with_client_options(
                ClientOptions::new()
                    .with_connect_timeout(Duration::from_secs(3))
                    .with_timeout(Duration::from_secs(3600)),
            )
            .with_retry(RetryConfig {
                max_retries: 2,
                retry_timeout: Duration::from_secs(5),
                ..RetryConfig::default()
            })
            .with_bucket_name(&config.bucket);
        if let Some(endpoint) = &config.endpoint {
            builder = builder.with_endpoint(endpoint);
        }
        let endpoint = config
            .endpoint
            .clone()
            .or_else(|| builder.get_config_value(&AmazonS3ConfigKey::Endpoint));
        if let Some(e) = &endpoint {
            // A self-hosted server on plain HTTP (a loopback test server, a
            // cluster-internal one) is the user's choice, made by its URL.
            builder = builder.with_allow_http(e.starts_with("http://"));
        }
        let path_style = config.path_style.unwrap_or(endpoint.is_some());
        builder = builder.with_virtual_hosted_style_request(!path_style);
        let region = config
            .region
            .clone()
            .or_else(|| builder.get_config_value(&AmazonS3ConfigKey::Region))
            .unwrap_or_else(|| "us-east-1".into());
        builder = builder.with_region(region);
        if let Some(k) = &config.access_key_id {
            builder = builder.with_access_key_id(k);
        }
        if let Some(k) = &config.secret_access_key {
            builder = builder.with_secret_access_key(k);
        }
        let inner = builder.build().map_err(invalid)?;
        let location = if config.prefix.is_empty() {
            format!("s3://{}", config.bucket)
        } else {
            format!("s3://{}/{}", config.bucket, config.prefix)
        };
        Ok(Self {
            inner: Arc::new(inner),
            prefix: config.prefix.clone(),
            location,
        })
    }

    fn key(&self, rel: &str) -> String {
        if self.prefix.is_empty() {
            rel.to_string()
        } else {
            format!("{}/{rel}", self.prefix)
        }
    }

    /// A job's objects sit under its tenant's prefix (tenant names are
    /// checked to be safe as path segments: `auth::valid_tenant`).
    fn job_key(&self, tenant: &str, id: &str, rel: &str) -> String {
        self.key(&format!("tenants/{tenant}/jobs/{id}{rel}"))
    }

    /// Where a job's upload goes.
    pub fn input_key(&self, tenant: &str, id: &str) -> String {
        self.job_key(tenant, id, "/input")
    }

    /// Where a job's gyro log goes: `gyro.EXT` (`gyro` without one), the
    /// extension the worker's copy needs for telemetry-parser.
    pub fn gyro_key(&self, tenant: &str, id: &str, extension: Option<&str>) -> String {
        match extension {
            Some(ext) => self.job_key(tenant, id, &format!("/gyro.{ext}")),
            None => self.job_key(tenant, id, "/gyro"),
        }
    }

    /// Where one claim of a job writes its output.
    pub fn output_key(&self, tenant: &str, id: &str, attempt: i32, extension: &str) -> String {
        self.job_key(tenant, id, &format!("/{attempt}/output.{extension}"))
    }

    /// Where one claim of a job writes its telemetry.
    pub fn telemetry_key(&self, tenant: &str, id: &str, attempt: i32) -> String {
        self.job_key(tenant, id, &format!("/{attempt}/telemetry.csv"))
    }

    /// Streams a local file into `key` (a multipart upload when it is large).
    pub async fn put_file(&self, key: &str, path: &Path) -> Result<u64, ClusterError> {
        let io = |source| ClusterError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut file = tokio::fs::File::open(path).await.map_err(io)?;
        let mut writer = BufWriter::new(self.inner.clone(), Key::from(key));
        let finished = match tokio::io::copy(&mut file, &mut writer).await {
            Ok(n) => writer.shutdown().await.map(|()| n),
            Err(e) => {
                // A multipart upload under way is cancelled (its parts
                // removed); after a failed `shutdown` the writer cannot be
                // aborted, and S3 drops unfinished uploads by itself.
                let _ = writer.abort().await;
                Err(e)
            }
        };
        // The writer reports the store's errors as io::Errors.
        finished.map_err(|e| ClusterError::Store {
            what: "uploading",
            key: key.to_string(),
            source: object_store::Error::Generic {
                store: "S3",
                source: Box::new(e),
            },
        })
    }

    /// Downloads `key` into a local file.
    pub async fn download(&self, key: &str, path: &Path) -> Result<u64, ClusterError> {
        let io = |source| ClusterError::Io {
            path: path.to_path_buf(),
            source,
        };
        let (_, mut stream) = self.open(key).await?;
        let mut file = tokio::fs::File::create(path).await.map_err(io)?;
        let mut n = 0u64;
        while let Some(chunk) = stream.next().await {
            let chunk = chunk.map_err(ClusterError::store("downloading", key))?;
            n += chunk.len() as u64;
            file.write_all(&chunk).await.map_err(io)?;
        }
        file.flush().await.map_err(io)?;
        Ok(n)
    }

    /// The object's size and its bytes as a stream.
    pub async fn open(
        &self,
        key: &str,
    ) -> Result<(u64, BoxStream<'static, object_store::Result<Bytes>>), ClusterError> {
        let got = self
            .inner
            .get(&Key::from(key))
            .await
            .map_err(ClusterError::store("reading", key))?;
        Ok((got.meta.size, got.into_stream()))
    }

    /// Deletes one object (one that is already gone is fine).
    pub async fn delete(&self, key: &str) -> Result<(), ClusterError> {
        match self.inner.delete(&Key::from(key)).await {
            Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(ClusterError::store("deleting", key)(e)),
        }
    }

    /// Deletes every object of a job (its upload and every attempt's results).
    pub async fn delete_job(&self, tenant: &str, id: &str) -> Result<usize, ClusterError> {
        let prefix = self.job_key(tenant, id, "");
        let keys: Vec<_> = self
            .inner
            .list(Some(&Key::from(prefix.as_str())))
            .collect()
            .await;
        let mut n = 0;
        for meta in keys {
            let meta = meta.map_err(ClusterError::store("listing", &prefix))?;
            self.delete(meta.location.as_ref()).await?;
            n += 1;
        }
        Ok(n)
    }

    /// Answers when the bucket does: a missing probe object is an answer.
    pub async fn ping(&self) -> Result<(), ClusterError> {
        let key = self.key("healthz-probe");
        match self.inner.head(&Key::from(key.as_str())).await {
            Ok(_) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(ClusterError::store("checking", &key)(e)),
        }
    }
}
