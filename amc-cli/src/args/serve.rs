//! `amc serve`'s flags, and the cluster flags it shares with `amc worker`.

use super::common::{parse_mode, parse_roll, parse_zoom};
use crate::error::CliError;
use amc_core::view::Mode;
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;

/// `amc serve` options.
#[derive(Args, Debug, Clone)]
pub struct ServeArgs {
    /// Address to listen on (port 0 picks a free port; the chosen one is printed).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Folder of the web page served at `/` (built by `bash web/build.sh`).
    #[arg(long, default_value = "web/dist")]
    pub web_dir: PathBuf,
    /// Folder for uploads and results (default: a new folder in the system's temp dir,
    /// removed on exit).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Largest upload, megabytes.
    #[arg(long, default_value_t = 2000)]
    pub max_upload_mb: u64,
    /// Widest video accepted, pixels.
    #[arg(long, default_value_t = 3840)]
    pub max_width: usize,
    /// Tallest video accepted, pixels.
    #[arg(long, default_value_t = 2160)]
    pub max_height: usize,
    /// Longest video accepted, seconds.
    #[arg(long, default_value_t = 1800.0)]
    pub max_duration: f64,
    /// Clips processed at once (default: the number of CPU cores).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Clips accepted beyond those being processed (they wait); more get 503.
    /// (With --queue, this bounds uploads being received by this replica.)
    #[arg(long, default_value_t = 8)]
    pub max_queued: usize,
    /// Longest a clip may take to process, seconds.
    #[arg(long, default_value_t = 3600)]
    pub job_time_limit: u64,
    /// How long a finished job's results are kept, seconds.
    #[arg(long, default_value_t = 3600)]
    pub job_ttl: u64,
    /// Disk space uploads and results may use together, megabytes.
    #[arg(long, default_value_t = 20_000)]
    pub max_disk_mb: u64,
    /// Longest an ffmpeg child may stall before it is killed, seconds.
    #[arg(long, default_value_t = 60)]
    pub ffmpeg_timeout: u64,
    /// Live feed source: a file, an RTSP/UDP/SRT URL or a device (anything ffmpeg opens).
    /// Without it, the feed comes from a publisher on /live/ingest. It is read only while
    /// a viewer watches /live. One that cannot be opened does not stop the service: it is
    /// logged, retried, and /healthz answers 503 naming it until it works.
    #[arg(long, value_name = "SOURCE")]
    pub live_source: Option<String>,
    /// Replay a file --live-source forever.
    #[arg(long)]
    pub live_loop: bool,
    /// ffmpeg input format of --live-source (e.g. v4l2 for /dev/video0).
    #[arg(long, value_name = "FMT")]
    pub live_format: Option<String>,
    /// Live feed mode: stabilize or saccade.
    #[arg(long, default_value = "stabilize", value_parser = parse_mode)]
    pub live_mode: Mode,
    /// The live view's roll in stabilize mode: smooth, lock (the horizon held
    /// level with the first frame) or follow (the camera's).
    #[arg(long, default_value = "smooth", value_name = "smooth|lock|follow", value_parser = parse_roll)]
    pub live_roll: amc_core::Roll,
    /// Horizontal field of view of the live camera, degrees (a pinhole).
    #[arg(long, default_value_t = amc_engine::FALLBACK_FOV_DEG, conflicts_with = "live_lens")]
    pub live_fov: f64,
    /// Lens file of the live camera (as for `amc stabilize --lens`).
    #[arg(long, value_name = "FILE")]
    pub live_lens: Option<PathBuf>,
    /// Frames averaged into each live output frame (1..=64).
    #[arg(long, default_value_t = 6)]
    pub live_n_avg: usize,
    /// Ghost-free averaging of the live feed (as `amc stabilize --deghost`):
    /// auto, off or 0..=64 levels. Off by default: on two cores it costs a
    /// 720p60 feed its rate (50 against 60 frames/s, docs/speed.md).
    #[arg(long, default_value = "off", value_name = "auto|off|LEVELS")]
    pub live_deghost: String,
    /// Framing of the live output: auto (the least zoom that shows no border,
    /// within --live-max-crop) or none (crop --live-margin). `static` needs the
    /// whole clip and is refused. Default: auto; none with --live-mode saccade
    /// (a fixed crop for a fixed view, as `amc stabilize --mode saccade`).
    #[arg(long, value_name = "auto|none", value_parser = parse_zoom)]
    pub live_zoom: Option<amc_core::Zoom>,
    /// Crop budget of --live-zoom auto: the largest share of the width cropped (0..=0.5).
    #[arg(long, default_value_t = 0.15)]
    pub live_max_crop: f64,
    /// With --live-zoom none: share cropped from each side of the live output (0..=0.45).
    #[arg(long, default_value_t = 0.125)]
    pub live_margin: f64,
    /// Rolling-shutter readout time of the live camera (first row to last),
    /// milliseconds, 0..=100 (0 = global shutter; default: the --live-lens
    /// file's readout, else 0). `auto` needs a whole clip and is refused.
    #[arg(long, value_name = "MS")]
    pub live_readout_ms: Option<String>,
    /// Width of the live output in pixels (default: the cropped input width).
    #[arg(long)]
    pub live_width: Option<usize>,
    /// JPEG quality of live frames (1..=100).
    #[arg(long, default_value_t = 80)]
    pub live_jpeg_quality: u8,
    /// Most kilobits per second of the H.264 live stream (`/live?codec=h264`,
    /// 100..=100000), held over every half second; a simpler picture takes less.
    #[arg(long, value_name = "KBPS", default_value_t = amc_server::serve::LiveConfig::default().bitrate_kbps)]
    pub live_bitrate: u32,
    /// Log one JSON object per line (for log collectors) instead of text.
    /// The level is set with RUST_LOG (default: info).
    #[arg(long)]
    pub log_json: bool,
    /// The shared job table and bucket (optional: without them jobs are kept
    /// in this process).
    #[command(flatten)]
    pub cluster: ClusterFlags,
    /// Keys, tenants, rates, CORS, TLS, connection limits.
    #[command(flatten)]
    pub access: super::AccessFlags,
}

/// Where jobs are kept when the service runs on several machines: one
/// definition of each flag for `amc serve` and `amc worker`.
#[derive(Args, Debug, Clone)]
pub struct ClusterFlags {
    /// PostgreSQL URL of the shared job table (postgres://USER[:PASS]@HOST:PORT/DB).
    /// With --store, jobs live there and `amc worker`s run them; any replica
    /// answers for any job. The schema is created or updated at start-up.
    #[arg(long, value_name = "URL", requires = "store")]
    pub queue: Option<String>,
    /// S3-compatible bucket of uploads and results: s3://BUCKET[/PREFIX].
    /// Credentials come from --s3-access-key-id/--s3-secret-access-key or
    /// AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY (and the other AWS_* variables).
    #[arg(long, value_name = "s3://BUCKET[/PREFIX]", requires = "queue")]
    pub store: Option<String>,
    /// Endpoint of an S3-compatible server other than AWS (e.g.
    /// http://127.0.0.1:8333 for SeaweedFS; default: AWS_ENDPOINT_URL, else AWS).
    #[arg(long, value_name = "URL")]
    pub s3_endpoint: Option<String>,
    /// Region of the bucket (default: AWS_REGION, else us-east-1).
    #[arg(long, value_name = "REGION")]
    pub s3_region: Option<String>,
    /// Path-style requests (ENDPOINT/BUCKET/KEY), as SeaweedFS and MinIO need
    /// (default: true with --s3-endpoint, false for AWS).
    #[arg(long, value_name = "BOOL")]
    pub s3_path_style: Option<bool>,
    /// Access key id (default: AWS_ACCESS_KEY_ID).
    #[arg(long, value_name = "ID")]
    pub s3_access_key_id: Option<String>,
    /// Secret access key (default: AWS_SECRET_ACCESS_KEY, which other users
    /// of the machine cannot read in the process list).
    #[arg(long, value_name = "KEY")]
    pub s3_secret_access_key: Option<String>,
    /// Seconds a worker's claim on a job lasts unless renewed (2..=3600); a
    /// job whose worker died is retried this long after it stopped answering.
    #[arg(long, default_value_t = amc_server::cluster::ClusterConfig::LEASE_SECS)]
    pub lease_secs: u64,
    /// Claims of one job before it is failed (1..=100).
    #[arg(long, default_value_t = amc_server::cluster::ClusterConfig::MAX_ATTEMPTS)]
    pub max_attempts: u32,
}

impl ClusterFlags {
    /// The library's settings, when --queue and --store are given.
    pub fn config(
        self,
        job_ttl: u64,
    ) -> Result<Option<amc_server::cluster::ClusterConfig>, amc_server::cluster::ClusterError> {
        let (Some(queue_url), Some(store)) = (self.queue, self.store) else {
            return Ok(None);
        };
        let store = amc_server::cluster::StoreConfig {
            endpoint: self.s3_endpoint,
            region: self.s3_region,
            path_style: self.s3_path_style,
            access_key_id: self.s3_access_key_id,
            secret_access_key: self.s3_secret_access_key,
            ..amc_server::cluster::StoreConfig::from_url(&store)?
        };
        let config = amc_server::cluster::ClusterConfig {
            queue_url,
            store,
            lease: std::time::Duration::from_secs(self.lease_secs),
            max_attempts: self.max_attempts,
            job_ttl: std::time::Duration::from_secs(job_ttl),
        };
        config.validate()?;
        Ok(Some(config))
    }
}

impl ServeArgs {
    /// The library's settings.
    pub fn config(self) -> Result<amc_server::serve::ServeConfig, CliError> {
        let (auth, listen) = self.access.config();
        Ok(amc_server::serve::ServeConfig {
            auth,
            listen,
            cluster: self.cluster.config(self.job_ttl)?,
            addr: self.addr,
            web_dir: self.web_dir,
            work_dir: self.work_dir,
            max_upload_mb: self.max_upload_mb,
            max_width: self.max_width,
            max_height: self.max_height,
            max_duration: self.max_duration,
            workers: self.workers,
            max_queued: self.max_queued,
            job_time_limit: self.job_time_limit,
            job_ttl: self.job_ttl,
            max_disk_mb: self.max_disk_mb,
            ffmpeg_timeout: self.ffmpeg_timeout,
            live_source: self.live_source,
            live_loop: self.live_loop,
            live_format: self.live_format,
            live_mode: self.live_mode,
            live_roll: self.live_roll,
            live_fov: self.live_fov,
            live_lens: self.live_lens,
            live_n_avg: self.live_n_avg,
            live_deghost: self.live_deghost,
            live_zoom: self.live_zoom,
            live_max_crop: self.live_max_crop,
            live_margin: self.live_margin,
            live_readout_ms: self.live_readout_ms,
            live_width: self.live_width,
            live_jpeg_quality: self.live_jpeg_quality,
            live_bitrate: self.live_bitrate,
            log_json: self.log_json,
        })
    }
}
