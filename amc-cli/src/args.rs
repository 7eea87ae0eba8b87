//! Command-line arguments: the only place clap lives. Each subcommand's
//! struct converts into the library's plain settings; the stabilizer's own
//! options come from [`crate::options::StabilizerFlags`], generated from the
//! core's one definition of each option.

use crate::error::CliError;
use crate::options::StabilizerFlags;
use amc_core::view::Mode;
use amc_core::LensSpec;
use clap::{Args, Parser, Subcommand};
use std::net::SocketAddr;
use std::path::PathBuf;

/// Artificial Microsaccade Compensation: stable video from shaking cameras.
#[derive(Parser, Debug)]
#[command(name = "amc", version, about, long_about = None)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Stabilize a video, a folder of images, or a .y4m file.
    Stabilize(StabilizeArgs),
    /// Run none / stabilize / saccade on a clip and print the paper's metrics.
    Eval(EvalArgs),
    /// Render a rotation-only shaking sequence from an equirectangular panorama.
    Synth(SynthArgs),
    /// Render a built-in shaky clip, stabilize it and say where the results are.
    Demo(DemoArgs),
    /// Run the HTTP service: REST stabilization, batch jobs, a live WebSocket feed, the web page.
    Serve(ServeArgs),
    /// Run the jobs of `amc serve --queue --store` replicas (any number of workers, anywhere).
    Worker(WorkerArgs),
    /// Compare our modes with ffmpeg's vid.stab and deshake: speed and quality, one report.
    Compare(CompareArgs),
}

/// How the input is read.
#[derive(Args, Debug, Clone)]
pub struct InputFlags {
    /// Frame rate of an image folder (default: its meta.json or gt.csv, else 30),
    /// or to override a video's timestamps.
    #[arg(long)]
    pub fps: Option<f64>,
    /// Longest time (seconds) an ffmpeg child may stall before it is killed.
    #[arg(long, default_value_t = 120)]
    pub timeout: u64,
    /// Threads of a run: 1 decodes, stabilizes and encodes on one thread; 2 or
    /// more decode and encode on threads of their own, track each frame while
    /// the previous one renders, and render rows on N threads; same output
    /// (1..=256; default: every core).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    pub threads: Option<u16>,
}

impl InputFlags {
    /// `--threads`, or every core.
    pub fn threads(&self) -> usize {
        self.threads
            .map_or_else(amc_server::engine::default_threads, usize::from)
    }
}

/// What every run over a clip takes: the lens file, the stabilizer's options
/// (with `--fov`) and how the input is read.
#[derive(Args, Debug)]
pub struct RunFlags {
    /// Lens file: the project's JSON, an OpenCV calibration (JSON/YAML) or a Gyroflow profile.
    #[arg(long, value_name = "FILE", conflicts_with = "fov")]
    pub lens: Option<PathBuf>,
    /// The stabilizer's options.
    #[command(flatten)]
    pub stabilizer: StabilizerFlags,
    /// How the input is read.
    #[command(flatten)]
    pub input: InputFlags,
}

/// `amc stabilize`.
#[derive(Args, Debug)]
pub struct StabilizeArgs {
    /// Input: any video ffmpeg reads, a folder of images (natural order), or .y4m.
    pub input: PathBuf,
    /// Output: .mp4 (H.264) / .webm / .mkv (audio copied), .y4m, or a folder for PNGs.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The lens, the stabilizer's options and how the input is read.
    #[command(flatten)]
    pub run: RunFlags,
    /// Write per-frame telemetry (CSV: frame,t,rx,ry,rz,vx,vy,vz,...).
    #[arg(long, value_name = "FILE.csv")]
    pub telemetry: Option<PathBuf>,
    /// Write the clip's metrics (JSON).
    #[arg(long, value_name = "FILE.json")]
    pub metrics: Option<PathBuf>,
    /// Video quality: x264 CRF 0..=51 for .mp4/.mkv (default 20), VP9 CRF 0..=63
    /// for .webm (default 32); lower is better and larger.
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=63))]
    pub crf: Option<u8>,
    /// No progress bar or summary.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `amc eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Input clip (as for `stabilize`).
    pub input: PathBuf,
    /// The lens, the stabilizer's options (`--mode` is ignored: every mode
    /// is run) and how the input is read.
    #[command(flatten)]
    pub run: RunFlags,
    /// Print JSON instead of a Markdown table.
    #[arg(long)]
    pub json: bool,
    /// Ground-truth orientations (`gt.csv` from `amc synth`): adds rotation errors.
    #[arg(long, value_name = "GT.csv")]
    pub gt: Option<PathBuf>,
    /// Write a per-frame plot (PNG) of angular speed and normal flow, like the paper's Figure 2.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// No progress bar.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `amc demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Folder for the demo's files.
    #[arg(short, long, default_value = "out/demo")]
    pub output: PathBuf,
    /// Equirectangular panorama to film (default: the shared Jordan Pond panorama
    /// if present, else a built-in procedural scene).
    #[arg(long)]
    pub panorama: Option<PathBuf>,
    /// RMS shake, deg/s.
    #[arg(long, default_value_t = 100.0)]
    pub shake_dps: f64,
    /// Clip length, seconds.
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
}

impl DemoArgs {
    /// The library's settings.
    pub fn config(self) -> amc_server::demo::DemoConfig {
        amc_server::demo::DemoConfig {
            output: self.output,
            panorama: self.panorama,
            shake_dps: self.shake_dps,
            seconds: self.seconds,
        }
    }
}

/// How the lens of clips is known, for commands without the stabilizer's flags.
#[derive(Args, Debug, Clone, Default)]
pub struct LensFlags {
    /// Lens file: the project's JSON, an OpenCV calibration (JSON/YAML) or a Gyroflow profile.
    #[arg(long, value_name = "FILE", conflicts_with = "fov")]
    pub lens: Option<PathBuf>,
    /// Horizontal field of view of a pinhole lens in degrees (0 < DEG <= 179), or
    /// `auto` to estimate it from the footage. Default without --lens: auto.
    #[arg(long, value_name = "DEG|auto")]
    pub fov: Option<String>,
}

impl LensFlags {
    /// The lens these flags name.
    pub fn spec(&self) -> Result<LensSpec, CliError> {
        match (&self.lens, &self.fov) {
            (Some(p), _) => Ok(LensSpec::File(p.clone())),
            (None, Some(v)) => Ok(LensSpec::parse_fov(v)?),
            (None, None) => Ok(LensSpec::Auto),
        }
    }
}

/// Parses `stabilize`, `saccade` or `none`.
pub fn parse_mode(s: &str) -> Result<Mode, String> {
    s.parse::<Mode>().map_err(|e| e.to_string())
}

fn parse_zoom(s: &str) -> Result<amc_core::Zoom, String> {
    s.parse::<amc_core::Zoom>().map_err(|e| e.to_string())
}

fn parse_roll(s: &str) -> Result<amc_core::Roll, String> {
    s.parse::<amc_core::Roll>().map_err(|e| e.to_string())
}

fn parse_floats<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated numbers ({what}), got '{s}'"
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number ({what})"))?;
    }
    Ok(out)
}

fn parse_band(s: &str) -> Result<(f64, f64), String> {
    let [lo, hi] = parse_floats::<2>(s, "LO,HI in Hz")?;
    Ok((lo, hi))
}

fn parse_k4(s: &str) -> Result<[f64; 4], String> {
    parse_floats::<4>(s, "K1,K2,K3,K4")
}

fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("'{s}' is not WxH"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| (32..=4096).contains(&n))
            .ok_or_else(|| format!("'{v}' in '{s}' is not a size (allowed: 32..=4096 pixels)"))
    };
    Ok((p(w)?, p(h)?))
}

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
    #[arg(long, default_value_t = amc_server::engine::FALLBACK_FOV_DEG, conflicts_with = "live_lens")]
    pub live_fov: f64,
    /// Lens file of the live camera (as for `amc stabilize --lens`).
    #[arg(long, value_name = "FILE")]
    pub live_lens: Option<PathBuf>,
    /// Frames averaged into each live output frame (1..=64).
    #[arg(long, default_value_t = 6)]
    pub live_n_avg: usize,
    /// Framing of the live output: auto (the least zoom that shows no border,
    /// within --live-max-crop) or none (crop --live-margin). `static` needs the
    /// whole clip and is refused.
    #[arg(long, default_value = "auto", value_name = "auto|none", value_parser = parse_zoom)]
    pub live_zoom: amc_core::Zoom,
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
    /// Log one JSON object per line (for log collectors) instead of text.
    /// The level is set with RUST_LOG (default: info).
    #[arg(long)]
    pub log_json: bool,
    /// The shared job table and bucket (optional: without them jobs are kept
    /// in this process).
    #[command(flatten)]
    pub cluster: ClusterFlags,
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

/// `amc worker` options.
#[derive(Args, Debug, Clone)]
pub struct WorkerArgs {
    /// Address of the worker's /healthz and /metrics (port 0 picks a free port;
    /// the chosen one is printed).
    #[arg(long, default_value = "127.0.0.1:9090")]
    pub addr: SocketAddr,
    /// Folder for a job's files while it runs (default: the system's temp dir).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Threads of one job's run (1..=256; default: every core). One worker per
    /// machine with every core, or one single-threaded worker per core.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    pub threads: Option<u16>,
    /// Longest a clip may take to process, seconds.
    #[arg(long, default_value_t = 3600)]
    pub job_time_limit: u64,
    /// How long a finished job's results are kept, seconds (the worker sweeps
    /// expired jobs, as the replicas do).
    #[arg(long, default_value_t = 3600)]
    pub job_ttl: u64,
    /// Longest an ffmpeg child may stall before it is killed, seconds.
    #[arg(long, default_value_t = 60)]
    pub ffmpeg_timeout: u64,
    /// This worker's name in the job table (default: host-pid-random).
    #[arg(long)]
    pub name: Option<String>,
    /// Log one JSON object per line (for log collectors) instead of text.
    #[arg(long)]
    pub log_json: bool,
    /// The shared job table and bucket (required).
    #[command(flatten)]
    pub cluster: ClusterFlags,
}

impl WorkerArgs {
    /// The library's settings.
    pub fn config(self) -> Result<amc_server::worker::WorkerConfig, CliError> {
        let cluster = self
            .cluster
            .config(self.job_ttl)?
            .ok_or(CliError::WorkerNeedsCluster)?;
        Ok(amc_server::worker::WorkerConfig {
            cluster,
            addr: self.addr,
            work_dir: self.work_dir,
            threads: self
                .threads
                .map_or_else(amc_server::engine::default_threads, usize::from),
            job_time_limit: self.job_time_limit,
            ffmpeg_timeout: self.ffmpeg_timeout,
            name: self.name,
            log_json: self.log_json,
        })
    }
}

impl ServeArgs {
    /// The library's settings.
    pub fn config(self) -> Result<amc_server::serve::ServeConfig, CliError> {
        Ok(amc_server::serve::ServeConfig {
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
            live_zoom: self.live_zoom,
            live_max_crop: self.live_max_crop,
            live_margin: self.live_margin,
            live_readout_ms: self.live_readout_ms,
            live_width: self.live_width,
            live_jpeg_quality: self.live_jpeg_quality,
            log_json: self.log_json,
        })
    }
}

/// Render a shaky synthetic clip (PNG frames, gt.csv, lens.json) from an
/// equirectangular panorama.
#[derive(Args, Debug, Clone)]
pub struct SynthArgs {
    /// Equirectangular (2:1, full-sphere) panorama, PNG or JPEG.
    pub panorama: PathBuf,

    /// Output directory (must not exist, or be empty).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,

    /// Horizontal field of view, degrees (of the fisheye with --fisheye).
    #[arg(
        long,
        default_value_t = 90.0,
        value_name = "DEG",
        allow_negative_numbers = true
    )]
    pub fov: f64,

    /// Render through a Kannala-Brandt (OpenCV fisheye) lens with these
    /// coefficients instead of a pinhole.
    #[arg(long, value_name = "K1,K2,K3,K4", value_parser = parse_k4, allow_hyphen_values = true)]
    pub fisheye: Option<[f64; 4]>,

    /// Frame width, pixels.
    #[arg(long, default_value_t = 320)]
    pub width: usize,

    /// Frame height, pixels.
    #[arg(long, default_value_t = 180)]
    pub height: usize,

    /// Frames per second.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
    pub fps: f64,

    /// Clip length, seconds.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub seconds: f64,

    /// RMS angular speed of the shake, deg/s.
    #[arg(
        long,
        default_value_t = 100.0,
        value_name = "DEG_PER_S",
        allow_negative_numbers = true
    )]
    pub shake_dps: f64,

    /// Frequency band of the shake, Hz.
    #[arg(long, default_value = "12,20", value_name = "LO,HI", value_parser = parse_band, allow_hyphen_values = true)]
    pub shake_band: (f64, f64),

    /// Seed of the shake trajectory.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,

    /// Constant yaw pan, deg/s (positive turns right).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "DEG_PER_S",
        allow_negative_numbers = true
    )]
    pub pan_dps: f64,

    /// Rolling-shutter readout time (first to last row), ms; 0 = global
    /// shutter. gt.csv holds the mid-readout orientation (row v is exposed
    /// at t + readout (v/H - 1/2)); lens.json states the readout (readout_ms).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "MS",
        allow_negative_numbers = true
    )]
    pub rolling_shutter_ms: f64,

    /// Anti-aliasing: N x N rays per output pixel.
    #[arg(long, default_value_t = 2, value_name = "N")]
    pub supersample: usize,
}

impl SynthArgs {
    /// The library's settings.
    pub fn config(self) -> amc_server::synth::SynthConfig {
        amc_server::synth::SynthConfig {
            panorama: self.panorama,
            output: self.output,
            fov: self.fov,
            fisheye: self.fisheye,
            width: self.width,
            height: self.height,
            fps: self.fps,
            seconds: self.seconds,
            shake_dps: self.shake_dps,
            shake_band: self.shake_band,
            seed: self.seed,
            pan_dps: self.pan_dps,
            rolling_shutter_ms: self.rolling_shutter_ms,
            supersample: self.supersample,
        }
    }
}

/// Compare our stabilizer with ffmpeg's vid.stab and deshake on the same clips.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Clips: videos, image folders, or folders holding `lens.json` with the images
    /// (directly or in `frames/`) and optionally `gt.csv` (as `amc synth` writes).
    pub clips: Vec<PathBuf>,
    /// Folder for the report (`README.md`, plots, `results.json`); created if missing.
    #[arg(long, value_name = "DIR")]
    pub report: PathBuf,
    /// Also render and compare the synthetic flapping-wing sequences (12-20 Hz shake,
    /// 100 and 300 deg/s, pinhole and fisheye, with and without rolling shutter).
    #[arg(long)]
    pub synthetic: bool,
    /// Length of each synthetic sequence, seconds (0.5..=60).
    #[arg(long, default_value_t = 5.0)]
    pub synthetic_seconds: f64,
    /// Size of the synthetic sequences, WxH.
    #[arg(long, default_value = "320x180", value_parser = parse_size)]
    pub synthetic_size: (usize, usize),
    /// Equirectangular panorama the synthetic sequences are rendered from.
    #[arg(long, default_value = "../shared/data/pano/pannellum_examplepano.jpg")]
    pub panorama: PathBuf,
    /// Lens of clips without a `lens.json` (default: --fov auto).
    #[command(flatten)]
    pub lens: LensFlags,
    /// Future frames of the `stabilize --lookahead` method (1..=300; default 30,
    /// as many as vid.stab's `smoothing=30` looks at on each side).
    #[arg(long, default_value_t = 30)]
    pub lookahead: usize,
    /// Frame rate of image folders without `gt.csv` timestamps (default 30).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Longest any one child process (a method on a clip) may run, seconds.
    #[arg(long, default_value_t = 1800)]
    pub timeout: u64,
    /// Text describing the machine, added to the detected CPU and memory in the report.
    #[arg(long)]
    pub machine: Option<String>,
    /// Timed runs per method (1..=10); the fastest counts (least disturbed on a shared machine).
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Also write every method's per-frame measurements (`CLIP-frames.csv`).
    #[arg(long)]
    pub per_frame: bool,
    /// No progress messages.
    #[arg(short, long)]
    pub quiet: bool,
    /// Extra peers: `paper` runs the paper's own code (github.com/prgumd/AMC) in its
    /// three modes, and ours at its settings beside it; skipped (with a note in the
    /// report) when its environment is missing.
    #[arg(long, value_enum, value_name = "paper")]
    pub peer: Vec<ExtraPeer>,
    /// The paper's environment, made by tools/paper-peer/setup.sh (default:
    /// $AMC_PAPER_PEER, else ~/.cache/amc/paper-peer).
    #[arg(long, value_name = "DIR")]
    pub paper_env: Option<PathBuf>,
}

/// Peers `amc compare` runs only when asked.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExtraPeer {
    /// The paper's own implementation (Python/JAX).
    Paper,
}

impl CompareArgs {
    /// The library's settings.
    pub fn config(self) -> Result<amc_server::compare::CompareConfig, CliError> {
        Ok(amc_server::compare::CompareConfig {
            clips: self.clips,
            report: self.report,
            synthetic: self.synthetic,
            synthetic_seconds: self.synthetic_seconds,
            synthetic_size: self.synthetic_size,
            panorama: self.panorama,
            lens: self.lens.spec()?,
            lookahead: self.lookahead,
            fps: self.fps,
            timeout: self.timeout,
            machine: self.machine,
            repeat: self.repeat,
            per_frame: self.per_frame,
            quiet: self.quiet,
            paper_env: self.peer.contains(&ExtraPeer::Paper).then(|| {
                self.paper_env
                    .unwrap_or_else(amc_server::compare::paper::default_env_dir)
            }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("amc").chain(argv.iter().copied()))
    }

    #[test]
    fn compare_runs_the_paper_only_when_asked() {
        let config = |argv: &[&str]| {
            let Command::Compare(a) = parse(argv).unwrap().command else {
                panic!("not compare")
            };
            a.config().unwrap()
        };
        assert_eq!(
            config(&["compare", "c.mp4", "--report", "r"]).paper_env,
            None
        );
        let c = config(&[
            "compare",
            "c.mp4",
            "--report",
            "r",
            "--peer",
            "paper",
            "--paper-env",
            "/env",
        ]);
        assert_eq!(c.paper_env, Some(PathBuf::from("/env")));
        // Without --paper-env: $AMC_PAPER_PEER or ~/.cache/amc/paper-peer.
        let c = config(&["compare", "c.mp4", "--report", "r", "--peer", "paper"]);
        assert_eq!(
            c.paper_env,
            Some(amc_server::compare::paper::default_env_dir())
        );
        assert!(parse(&["compare", "c.mp4", "--report", "r", "--peer", "vidstab"]).is_err());
    }

    #[test]
    fn the_job_table_and_bucket_go_together_and_are_checked() {
        // Without them, serve keeps its jobs in memory.
        let Command::Serve(a) = parse(&["serve"]).unwrap().command else {
            panic!("not serve")
        };
        assert!(a.config().unwrap().cluster.is_none());
        // One without the other is a usage error.
        for argv in [
            &["serve", "--queue", "postgres://h/db"][..],
            &["serve", "--store", "s3://amc"][..],
            &["worker", "--queue", "postgres://h/db"][..],
        ] {
            let e = parse(argv).err().unwrap().to_string();
            assert!(
                e.contains("--store") || e.contains("--queue"),
                "{argv:?}: {e}"
            );
        }
        // A worker needs both.
        let Command::Worker(a) = parse(&["worker"]).unwrap().command else {
            panic!("not worker")
        };
        let e = a.config().err().unwrap().to_string();
        assert!(e.contains("--queue") && e.contains("--store"), "{e}");
        // Both, with the flags beside them.
        let argv = [
            "worker",
            "--queue",
            "postgres://amc:pw@db:5432/amc",
            "--store",
            "s3://amc-videos/team",
            "--s3-endpoint",
            "http://127.0.0.1:8333",
            "--lease-secs",
            "10",
            "--threads",
            "1",
        ];
        let Command::Worker(a) = parse(&argv).unwrap().command else {
            panic!("not worker")
        };
        let c = a.config().unwrap();
        assert_eq!(c.cluster.store.bucket, "amc-videos");
        assert_eq!(c.cluster.store.prefix, "team");
        assert_eq!(
            c.cluster.store.endpoint.as_deref(),
            Some("http://127.0.0.1:8333")
        );
        assert_eq!(c.cluster.lease, std::time::Duration::from_secs(10));
        assert_eq!(c.threads, 1);
        // Bad values name their flag and range.
        for (queue, store, extra, expect) in [
            ("postgres://h/db", "s3://Bad_Bucket", None, "--store"),
            ("mysql://u:secret@h/db", "s3://amc", None, "--queue"),
            (
                "postgres://h/db",
                "s3://amc",
                Some(["--lease-secs", "1"]),
                "2..=3600",
            ),
            (
                "postgres://h/db",
                "s3://amc",
                Some(["--max-attempts", "0"]),
                "1..=100",
            ),
        ] {
            let mut argv = vec!["serve", "--queue", queue, "--store", store];
            argv.extend(extra.into_iter().flatten());
            let Command::Serve(a) = parse(&argv).unwrap().command else {
                panic!("not serve")
            };
            let e = a.config().err().unwrap().to_string();
            assert!(e.contains(expect) && !e.contains("secret"), "{argv:?}: {e}");
        }
    }

    #[test]
    fn live_roll_reaches_the_live_feeds_view() {
        let roll = |argv: &[&str]| {
            let Command::Serve(a) = parse(argv).unwrap().command else {
                panic!("not serve")
            };
            a.config().unwrap().live().unwrap().params.view.roll
        };
        assert_eq!(roll(&["serve"]), amc_core::Roll::Smooth);
        assert_eq!(
            roll(&["serve", "--live-roll", "lock"]),
            amc_core::Roll::Lock
        );
        let e = parse(&["serve", "--live-roll", "level"])
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("smooth, lock or follow"), "{e}");
    }

    #[test]
    fn live_readout_is_a_number_and_auto_is_refused() {
        let live = |argv: &[&str]| {
            let Command::Serve(a) = parse(argv).unwrap().command else {
                panic!("not serve")
            };
            a.config().unwrap().live()
        };
        let readout = |argv: &[&str]| live(argv).unwrap().params.shutter.readout_ms;
        assert_eq!(readout(&["serve"]), 0.0);
        assert_eq!(readout(&["serve", "--live-readout-ms", "16.5"]), 16.5);
        for (value, needle) in [("auto", "whole clip"), ("200", "0..=100"), ("x", "0..=100")] {
            let e = live(&["serve", "--live-readout-ms", value])
                .err()
                .unwrap()
                .to_string();
            assert!(
                e.contains("--live-readout-ms") && e.contains(needle),
                "{value}: {e}"
            );
        }
    }

    #[test]
    fn synth_defaults_and_lists() {
        let Command::Synth(a) = parse(&["synth", "p.jpg", "-o", "out"]).unwrap().command else {
            panic!("not synth")
        };
        let c = a.config();
        assert_eq!(
            c,
            amc_server::synth::SynthConfig::new("p.jpg".into(), "out".into())
        );
        let Command::Synth(a) = parse(&[
            "synth",
            "p.jpg",
            "-o",
            "out",
            "--fisheye",
            "-0.01,0.002,0,0",
            "--pan-dps",
            "-5",
            "--shake-band",
            "5, 9",
        ])
        .unwrap()
        .command
        else {
            panic!("not synth")
        };
        assert_eq!(a.fisheye, Some([-0.01, 0.002, 0.0, 0.0]));
        assert_eq!((a.pan_dps, a.shake_band), (-5.0, (5.0, 9.0)));
        assert!(parse(&["synth", "p.jpg"]).is_err());
        assert!(parse(&["synth", "p.jpg", "-o", "o", "--shake-band", "12"]).is_err());
        assert!(parse(&["synth", "p.jpg", "-o", "o", "--fisheye", "1,2,x,4"]).is_err());
    }

    #[test]
    fn stabilizer_flags_come_from_the_core_table() {
        let Command::Stabilize(a) = parse(&[
            "stabilize",
            "in.mp4",
            "-o",
            "out.mp4",
            "--n-avg",
            "4",
            "--rate-a",
            "0.5",
            "--mode",
            "saccade",
            "--fov",
            "90",
        ])
        .unwrap()
        .command
        else {
            panic!("not stabilize")
        };
        let o = a.run.stabilizer.options(Mode::Stabilize, None).unwrap();
        assert_eq!(o.params.render.n_avg, 4);
        assert_eq!(o.params.view.rate_a, 0.5);
        assert_eq!(o.params.view.mode, Mode::Saccade);
        assert_eq!(o.lens, LensSpec::Fov(90.0));
        // Every option of the table is a flag.
        let cmd = <Cli as clap::CommandFactory>::command();
        let stabilize = cmd.find_subcommand("stabilize").unwrap();
        for o in amc_core::options::OPTIONS {
            assert!(
                stabilize
                    .get_arguments()
                    .any(|a| a.get_long() == Some(o.flag)),
                "--{} missing",
                o.flag
            );
        }
        // A lens file and a field of view exclude each other; ranges are the core's.
        assert!(parse(&[
            "stabilize",
            "i",
            "-o",
            "o",
            "--lens",
            "l.json",
            "--fov",
            "90"
        ])
        .is_err());
        let Command::Stabilize(a) = parse(&["stabilize", "i", "-o", "o", "--n-avg", "0"])
            .unwrap()
            .command
        else {
            panic!("not stabilize")
        };
        let e = a.run.stabilizer.options(Mode::Stabilize, None).unwrap_err();
        assert!(
            e.to_string().contains("n_avg") && e.to_string().contains("1..=64"),
            "{e}"
        );
    }
}
