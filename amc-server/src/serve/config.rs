//! `amc serve`'s settings: the command line's flags ([`ServeConfig`]), their
//! checks, and what they turn into ([`Limits`], the live feed's [`LiveConfig`]).

use super::live::LiveConfig;
use amc_core::view::Mode;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// `amc serve` settings (the command line's flags, one field each).
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Address to listen on (port 0 picks a free port; the chosen one is printed).
    pub addr: SocketAddr,
    /// Folder of the web page served at `/` (built by `bash web/build.sh`).
    pub web_dir: PathBuf,
    /// Folder for uploads and results (default: a new folder in the system's temp dir,
    /// removed on exit).
    pub work_dir: Option<PathBuf>,
    /// Largest upload, megabytes.
    pub max_upload_mb: u64,
    /// Widest video accepted, pixels.
    pub max_width: usize,
    /// Tallest video accepted, pixels.
    pub max_height: usize,
    /// Longest video accepted, seconds.
    pub max_duration: f64,
    /// Clips processed at once (default: the number of CPU cores).
    pub workers: Option<usize>,
    /// Clips accepted beyond those being processed (they wait); more get 503.
    pub max_queued: usize,
    /// Longest a clip may take to process, seconds.
    pub job_time_limit: u64,
    /// How long a finished job's results are kept, seconds.
    pub job_ttl: u64,
    /// Disk space uploads and results may use together, megabytes.
    pub max_disk_mb: u64,
    /// Longest an ffmpeg child may stall before it is killed, seconds.
    pub ffmpeg_timeout: u64,
    /// Live feed source: a file, an RTSP/UDP/SRT URL or a device (anything ffmpeg opens).
    /// Without it, the feed comes from a publisher on /live/ingest. Read only while a
    /// viewer watches; one that cannot be opened makes /healthz answer 503, nothing more.
    pub live_source: Option<String>,
    /// Replay a file --live-source forever.
    pub live_loop: bool,
    /// ffmpeg input format of --live-source (e.g. v4l2 for /dev/video0).
    pub live_format: Option<String>,
    /// Live feed mode: stabilize or saccade.
    pub live_mode: Mode,
    /// The live view's roll in stabilize mode: smooth, lock (the horizon held
    /// level with the first frame) or follow (the camera's).
    pub live_roll: amc_core::Roll,
    /// Horizontal field of view of the live camera, degrees (a pinhole).
    pub live_fov: f64,
    /// Lens file of the live camera (as for `amc stabilize --lens`).
    pub live_lens: Option<PathBuf>,
    /// Frames averaged into each live output frame (1..=64).
    pub live_n_avg: usize,
    /// `--live-deghost`: auto, off or levels.
    pub live_deghost: String,
    /// Framing of the live output: auto or none (static needs the whole clip: refused);
    /// unset, the framing `live_mode` has in `amc stabilize` (none in saccade mode).
    pub live_zoom: Option<amc_core::Zoom>,
    /// Crop budget of `live_zoom` auto (0..=0.5).
    pub live_max_crop: f64,
    /// With `live_zoom` none: share cropped from each side of the live output (0..=0.45).
    pub live_margin: f64,
    /// Rolling-shutter readout of the live camera as given (`--live-readout-ms`:
    /// milliseconds, 0..=100; `auto` needs a whole clip and is refused); none:
    /// the `live_lens` file's readout, else 0.
    pub live_readout_ms: Option<String>,
    /// Width of the live output in pixels (default: the cropped input width).
    pub live_width: Option<usize>,
    /// JPEG quality of live frames (1..=100).
    pub live_jpeg_quality: u8,
    /// `--live-bitrate`: the H.264 live stream's kilobits per second.
    pub live_bitrate: u32,
    /// Log one JSON object per line (for log collectors) instead of text.
    /// The level is set with RUST_LOG (default: info).
    pub log_json: bool,
    /// Keep jobs in a shared PostgreSQL table and S3-compatible bucket
    /// (`--queue`, `--store`) for `amc worker`s to run, instead of in this
    /// process: any replica then answers for any job.
    pub cluster: Option<crate::cluster::ClusterConfig>,
    /// Keys, tenants and their limits, CORS (docs/security.md).
    pub auth: crate::auth::AuthConfig,
    /// Connections: limits, header timeout, TLS.
    pub listen: super::listen::ListenConfig,
}

/// The service's limits, from the flags.
#[derive(Clone, Debug)]
pub struct Limits {
    pub max_upload_bytes: u64,
    pub max_width: usize,
    pub max_height: usize,
    pub max_duration_s: f64,
    pub workers: usize,
    pub queue: usize,
    pub job_time_limit: Duration,
    pub job_ttl: Duration,
    pub max_disk_bytes: u64,
    pub ffmpeg_timeout: Duration,
    /// Threads of one clip's run (decode, track, render rows, encode).
    pub threads: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_upload_bytes: 2_000_000_000,
            max_width: 3840,
            max_height: 2160,
            max_duration_s: 1800.0,
            workers: default_workers(),
            queue: 8,
            job_time_limit: Duration::from_secs(3600),
            job_ttl: Duration::from_secs(3600),
            max_disk_bytes: 20_000_000_000,
            ffmpeg_timeout: Duration::from_secs(60),
            threads: amc_engine::default_threads(),
        }
    }
}

fn default_workers() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get())
}

/// Why `amc serve` or `amc worker` could not start, or stopped with an
/// error: the failures the two share (all of the worker's, which calls this
/// type [`crate::worker::WorkerError`]).
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// A setting outside its range.
    #[error("invalid --{flag}: {detail}")]
    Invalid {
        /// The setting's flag, without dashes.
        flag: &'static str,
        /// The value and what is allowed.
        detail: String,
    },
    /// ffmpeg is missing.
    #[error(transparent)]
    Video(#[from] amc_video::VideoError),
    /// The shared job table or bucket cannot be used.
    #[error(transparent)]
    Cluster(#[from] crate::cluster::ClusterError),
    /// A file or folder the service or worker needs cannot be used.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The keys file cannot be used.
    #[error(transparent)]
    Keys(#[from] crate::auth::KeysError),
    /// A non-loopback address without keys.
    #[error(
        "refusing to serve {addr} without keys: anyone who can reach it could use every endpoint \
         (jobs, the live feed, metrics). Give --auth-keys FILE (lines `TENANT ROLES SHA256HEX`; \
         make a key with `amc keys new TENANT ROLES`), or --insecure-no-auth if a gateway in front \
         of the service checks who is asking, or listen on a loopback address (127.0.0.1)"
    )]
    Unprotected {
        /// The address asked for.
        addr: SocketAddr,
    },
    /// The listening socket or the runtime failed.
    #[error("{what}: {source}")]
    Network {
        /// What was being done.
        what: String,
        /// Why it failed.
        source: std::io::Error,
    },
}

/// Why the service could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A failure `amc worker` can have too.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The live camera's parameters or lens are refused by the core.
    #[error(transparent)]
    Core(#[from] amc_core::AmcError),
}

impl From<amc_video::VideoError> for ServeError {
    fn from(e: amc_video::VideoError) -> Self {
        Self::Service(e.into())
    }
}

impl From<crate::cluster::ClusterError> for ServeError {
    fn from(e: crate::cluster::ClusterError) -> Self {
        Self::Service(e.into())
    }
}

/// `value` within `lo..=hi`, else [`ServiceError::Invalid`] naming `--flag`.
pub(crate) fn check<T: PartialOrd + std::fmt::Display>(
    flag: &'static str,
    value: T,
    lo: T,
    hi: T,
) -> Result<(), ServiceError> {
    Ok(crate::setting::check(flag, value, lo, hi)?)
}

impl From<crate::setting::InvalidSetting> for ServiceError {
    fn from(e: crate::setting::InvalidSetting) -> Self {
        Self::Invalid {
            flag: e.flag,
            detail: e.detail,
        }
    }
}

impl From<crate::setting::InvalidSetting> for ServeError {
    fn from(e: crate::setting::InvalidSetting) -> Self {
        Self::Service(e.into())
    }
}

impl ServeConfig {
    /// Checks the access and connection flags: keys (or a loopback
    /// address, or `--insecure-no-auth`), limits, TLS files both or neither.
    pub fn check_access(&self) -> Result<(), ServiceError> {
        self.auth.validate()?;
        self.listen.validate()?;
        if self.auth.keys_file.is_none()
            && !self.auth.insecure_no_auth
            && !self.addr.ip().is_loopback()
        {
            return Err(ServiceError::Unprotected { addr: self.addr });
        }
        Ok(())
    }

    /// Checks the flags and turns them into limits.
    pub fn limits(&self) -> Result<Limits, ServeError> {
        let workers = self.workers.unwrap_or_else(default_workers);
        check("max-upload-mb", self.max_upload_mb, 1, 1_000_000)?;
        check("max-width", self.max_width, 16, 16384)?;
        check("max-height", self.max_height, 16, 16384)?;
        check("max-duration", self.max_duration, 0.1, 86_400.0)?;
        check("workers", workers, 1, 256)?;
        check("max-queued", self.max_queued, 0, 10_000)?;
        check("job-time-limit", self.job_time_limit, 1, 604_800)?;
        check("job-ttl", self.job_ttl, 1, 2_592_000)?;
        check("max-disk-mb", self.max_disk_mb, 1, 1_000_000_000)?;
        check("ffmpeg-timeout", self.ffmpeg_timeout, 1, 86_400)?;
        if self.max_disk_mb < self.max_upload_mb {
            return Err(ServiceError::Invalid {
                flag: "max-disk-mb",
                detail: format!(
                    "{} (allowed: at least --max-upload-mb, {})",
                    self.max_disk_mb, self.max_upload_mb
                ),
            }
            .into());
        }
        Ok(Limits {
            max_upload_bytes: self.max_upload_mb * 1_000_000,
            max_width: self.max_width,
            max_height: self.max_height,
            max_duration_s: self.max_duration,
            workers,
            queue: self.max_queued,
            job_time_limit: Duration::from_secs(self.job_time_limit),
            job_ttl: Duration::from_secs(self.job_ttl),
            max_disk_bytes: self.max_disk_mb * 1_000_000,
            ffmpeg_timeout: Duration::from_secs(self.ffmpeg_timeout),
            threads: amc_engine::default_threads(),
        })
    }

    /// The live camera's readout: `--live-readout-ms`, else the lens file's
    /// (`lens_ms`), else 0. `auto` is refused: the estimate needs a clip's
    /// first seconds before the first frame is shown.
    fn live_readout(&self, lens_ms: Option<f64>) -> Result<f64, ServiceError> {
        let spec = match &self.live_readout_ms {
            Some(v) => amc_core::ReadoutSpec::parse(v).map_err(|_| ServiceError::Invalid {
                flag: "live-readout-ms",
                detail: format!("{v:?} (allowed: 0..=100 milliseconds, 0 = global shutter)"),
            })?,
            None => amc_core::ReadoutSpec::FromLens,
        };
        spec.given(lens_ms).ok_or_else(|| ServiceError::Invalid {
            flag: "live-readout-ms",
            detail: "auto (estimating the readout needs a whole clip first; allowed: 0..=100 milliseconds)"
                .into(),
        })
    }

    /// The live feed's configuration.
    pub fn live(&self) -> Result<LiveConfig, ServeError> {
        check("live-jpeg-quality", self.live_jpeg_quality, 1, 100)?;
        check("live-bitrate", self.live_bitrate, 100, 100_000)?;
        // The same range as every other field of view (`fov`).
        if amc_core::LensSpec::parse_fov(&self.live_fov.to_string()).is_err() {
            return Err(ServiceError::Invalid {
                flag: "live-fov",
                detail: format!("{} (allowed: 0 < DEG <= 179)", self.live_fov),
            }
            .into());
        }
        let mut params = amc_core::StabilizerParams::default();
        params.view.mode = self.live_mode;
        params.view.roll = self.live_roll;
        params.render.n_avg = self.live_n_avg;
        params.render.deghost =
            self.live_deghost
                .parse()
                .map_err(|e: amc_core::AmcError| ServiceError::Invalid {
                    flag: "live-deghost",
                    detail: e.to_string(),
                })?;
        params.render.margin = self.live_margin;
        let zoom = self
            .live_zoom
            .unwrap_or_else(|| amc_core::StabilizerOptions::default_zoom(self.live_mode));
        if zoom == amc_core::Zoom::Static {
            return Err(ServiceError::Invalid {
                flag: "live-zoom",
                detail:
                    "static (one zoom for a whole clip needs the clip first; allowed: auto or none)"
                        .into(),
            }
            .into());
        }
        params.framing.zoom = zoom;
        params.framing.max_crop = self.live_max_crop;
        params.render.output_width = self.live_width;
        let lens = match &self.live_lens {
            Some(p) => {
                let text = std::fs::read_to_string(p).map_err(|source| ServiceError::Io {
                    path: p.clone(),
                    source,
                })?;
                Some(amc_core::lens::parse_lens_file(&text).map_err(amc_core::AmcError::from)?)
            }
            None => None,
        };
        params.shutter.readout_ms = self.live_readout(lens.as_ref().and_then(|l| l.readout_ms))?;
        params.validate()?;
        let lens = lens.map(|l| l.camera);
        Ok(LiveConfig {
            source: self.live_source.clone(),
            format: self.live_format.clone(),
            looped: self.live_loop,
            params,
            lens,
            fov_deg: self.live_fov,
            jpeg_quality: self.live_jpeg_quality,
            bitrate_kbps: self.live_bitrate,
            ffmpeg_timeout: Duration::from_secs(self.ffmpeg_timeout),
        })
    }
}
