//! `ffprobe`: size, rate, length and audio of a video file.

use crate::error::VideoError;
use crate::process::run_capture;
use crate::spec::{VideoInfo, DEFAULT_IMAGE_FPS};
use serde_json::Value;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, SystemTime};

/// What ffprobe says about a file.
#[derive(Clone, Debug)]
pub(crate) struct Probe {
    pub info: VideoInfo,
    /// Index (among all streams) of the video stream to decode.
    pub video_index: u64,
    /// Codec of the first audio stream (`aac`, `opus`, ...), if any.
    pub audio_codec: Option<String>,
    /// The data streams (GoPro's `gpmd` telemetry, timecode, ...), in order.
    pub data_tracks: Vec<DataTrack>,
    /// The video stream's start timecode (`HH:MM:SS:FF`), if it has one.
    pub timecode: Option<String>,
    /// ffmpeg's name for the container (`mov,mp4,m4a,3gp,3g2,mj2`, `png_pipe`, ...).
    pub format_name: String,
    /// The video stream's 8-bit 4:2:0 frames as its decoder gives them, when
    /// it does: planar frames then come from ffmpeg unconverted.
    pub native_420: Option<Native420>,
}

/// A data stream of a file: telemetry (GoPro's `gpmd`), timecode (`tmcd`), ...
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct DataTrack {
    /// Index among all the file's streams.
    pub index: u64,
    /// ffmpeg's codec (`bin_data` for GoPro's telemetry; `unknown` when it has none).
    pub codec: String,
    /// The container's four-character tag (`gpmd`, `tmcd`, `fdsc`).
    pub tag: String,
}

impl DataTrack {
    /// Whether ffmpeg can copy it into an MP4: a codec it knows (GoPro's
    /// `gpmd` is `bin_data`). Timecode needs no copy: the MP4 muxer writes
    /// its own `tmcd` track from the input's timecode.
    pub fn copies_into_mp4(&self) -> bool {
        self.codec == "bin_data"
    }
}

/// An 8-bit 4:2:0 video stream's frames as its decoder gives them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Native420 {
    /// The pixel format to ask ffmpeg for: the decoder's own (`yuv420p` or
    /// `yuvj420p`), so that ffmpeg inserts no scaler.
    pub pix_fmt: &'static str,
    /// Full range (Y 0..=255): `yuvj420p`, or `yuv420p` tagged `pc`.
    pub full_range: bool,
}

impl Native420 {
    /// The stream's, from ffprobe's `pix_fmt` and `color_range`.
    fn of(pix_fmt: Option<&str>, color_range: Option<&str>) -> Option<Self> {
        match pix_fmt? {
            "yuv420p" => Some(Self {
                pix_fmt: "yuv420p",
                full_range: color_range == Some("pc"),
            }),
            "yuvj420p" => Some(Self {
                pix_fmt: "yuvj420p",
                full_range: true,
            }),
            _ => None,
        }
    }
}

/// Probes `path`. A file ffprobe cannot open, or one without a video stream,
/// is [`VideoError::NotAVideo`].
///
/// The container's own frame count (MP4, MOV) is taken as it is; only a file
/// without one (MKV, WebM) is probed again counting its packets, which
/// demuxes the whole file (~0.1 s for a 10 s 720p clip).
pub(crate) fn probe(path: &Path, timeout: Duration) -> Result<Probe, VideoError> {
    let quick = probe_with(path, timeout, false)?;
    if quick.info.frame_count.is_some() {
        return Ok(quick);
    }
    probe_with(path, timeout, true)
}

/// What identifies a regular file's content for [`RECENT`]: a file rewritten
/// since it was probed has another length, time or inode.
#[derive(Clone, Debug, PartialEq, Eq)]
struct FileKey {
    path: PathBuf,
    len: u64,
    modified: SystemTime,
    #[cfg(unix)]
    inode: (u64, u64),
}

impl FileKey {
    /// The key of `path`, when it is a regular file with a modification time.
    fn of(path: &Path) -> Option<Self> {
        let meta = std::fs::metadata(path).ok().filter(|m| m.is_file())?;
        Some(Self {
            path: path.to_path_buf(),
            len: meta.len(),
            modified: meta.modified().ok()?,
            #[cfg(unix)]
            inode: {
                use std::os::unix::fs::MetadataExt;
                (meta.dev(), meta.ino())
            },
        })
    }
}

/// The latest probes of files, each with whether it counted packets: a run
/// asks about its input up to three times (its frame size for the lens,
/// opening it, its audio for the output; the service once more on upload),
/// and each ffprobe takes ~0.1 s before the first frame.
static RECENT: Mutex<Vec<(FileKey, bool, Probe)>> = Mutex::new(Vec::new());

/// Probes kept in [`RECENT`].
const RECENT_PROBES: usize = 4;

/// Probes `path`; `count_packets` demuxes the whole input for a frame count
/// (never for a live stream, which has no end).
pub(crate) fn probe_with(
    path: &Path,
    timeout: Duration,
    count_packets: bool,
) -> Result<Probe, VideoError> {
    let mut args: Vec<OsString> = vec![
        "-hide_banner".into(),
        "-loglevel".into(),
        "level+error".into(),
    ];
    if count_packets {
        // Counting packets demuxes the file (no decoding: fast) and gives a
        // frame count for containers without one in their header (mkv, webm).
        args.push("-count_packets".into());
    }
    args.extend(
        [
            "-show_entries",
            "stream=index,codec_type,codec_name,codec_tag_string,width,height,pix_fmt,color_range,\
             avg_frame_rate,r_frame_rate,nb_frames,nb_read_packets,duration:stream_side_data=rotation:stream_tags=rotate,timecode:\
             stream_disposition=attached_pic:format=duration,format_name",
            "-of",
            "json",
        ]
        .iter()
        .map(OsString::from),
    );
    args.push(path.as_os_str().to_owned());
    let key = FileKey::of(path);
    let recent = |k: &FileKey| {
        let recent = RECENT.lock().unwrap_or_else(|e| e.into_inner());
        // A probe that counted packets answers one that does not need to.
        recent
            .iter()
            .find(|(key, counted, _)| key == k && (*counted || !count_packets))
            .map(|(_, _, p)| p.clone())
    };
    if let Some(p) = key.as_ref().and_then(recent) {
        return Ok(p);
    }
    crate::caps::prefetch_caps();
    let probed = run_probe(path, &args, timeout)?;
    // Kept only if the file did not change while it was probed.
    if let Some(key) = key.filter(|k| FileKey::of(path).as_ref() == Some(k)) {
        let mut recent = RECENT.lock().unwrap_or_else(|e| e.into_inner());
        recent.retain(|(k, _, _)| *k != key);
        if recent.len() == RECENT_PROBES {
            recent.remove(0);
        }
        recent.push((key, count_packets, probed.clone()));
    }
    Ok(probed)
}

/// Probes a capture device opened with ffmpeg format `format` (`v4l2`, ...).
pub(crate) fn probe_device(
    path: &Path,
    format: &str,
    timeout: Duration,
) -> Result<Probe, VideoError> {
    let args: Vec<OsString> = [
        "-hide_banner",
        "-loglevel",
        "level+error",
        "-f",
        format,
        "-show_entries",
        "stream=index,codec_type,codec_name,width,height,pix_fmt,color_range,avg_frame_rate,\
         r_frame_rate:format=format_name",
        "-of",
        "json",
    ]
    .iter()
    .map(OsString::from)
    .chain([path.as_os_str().to_owned()])
    .collect();
    run_probe(path, &args, timeout)
}

/// Runs ffprobe with `args`; anything it reports as an error means "not a video".
fn run_probe(path: &Path, args: &[OsString], timeout: Duration) -> Result<Probe, VideoError> {
    let (_, out, err) = run_capture("ffprobe", args, path, timeout)?;
    if let Some(detail) = err {
        return Err(VideoError::NotAVideo {
            path: path.to_path_buf(),
            detail,
        });
    }
    parse(path, &out)
}

/// Interprets ffprobe's JSON.
fn parse(path: &Path, json: &[u8]) -> Result<Probe, VideoError> {
    let not_video = |detail: &str| VideoError::NotAVideo {
        path: path.to_path_buf(),
        detail: detail.to_string(),
    };
    let root: Value = serde_json::from_slice(json)
        .map_err(|e| not_video(&format!("unexpected ffprobe output ({e})")))?;
    let streams = root["streams"].as_array().cloned().unwrap_or_default();
    let is_type = |s: &Value, t: &str| s["codec_type"].as_str() == Some(t);
    // Cover art is a "video" stream of one picture; `-map 0:v:0` would pick it
    // if it came first, but it is not what anyone wants stabilized, so the
    // decoder maps the stream chosen here by its index.
    let video = streams
        .iter()
        .filter(|s| is_type(s, "video"))
        .find(|s| s["disposition"]["attached_pic"].as_i64() != Some(1))
        .ok_or_else(|| not_video("it has no video stream"))?;
    let audio_codec = streams
        .iter()
        .find(|s| is_type(s, "audio"))
        .map(|s| s["codec_name"].as_str().unwrap_or("unknown").to_string());
    let data_tracks = streams
        .iter()
        .filter(|s| is_type(s, "data"))
        .map(|s| DataTrack {
            index: s["index"].as_u64().unwrap_or(0),
            codec: s["codec_name"].as_str().unwrap_or("unknown").to_string(),
            tag: s["codec_tag_string"]
                .as_str()
                .unwrap_or_default()
                .to_string(),
        })
        .collect();

    let dim = |key: &str| video[key].as_u64().filter(|&v| v > 0).map(|v| v as usize);
    let (Some(mut width), Some(mut height)) = (dim("width"), dim("height")) else {
        return Err(not_video("its video stream has no frame size"));
    };
    // ffmpeg applies the rotation flag of phone videos when decoding, so a
    // quarter turn swaps the size the frames come out with.
    if quarter_turn(video) {
        std::mem::swap(&mut width, &mut height);
    }
    let fps = [
        video["avg_frame_rate"].as_str(),
        video["r_frame_rate"].as_str(),
    ]
    .into_iter()
    .flatten()
    .filter_map(parse_rate)
    .next()
    .unwrap_or(DEFAULT_IMAGE_FPS);
    let number = |v: &Value| -> Option<f64> {
        match v {
            Value::String(s) => s.parse().ok(),
            Value::Number(n) => n.as_f64(),
            _ => None,
        }
    };
    let frame_count = [&video["nb_frames"], &video["nb_read_packets"]]
        .into_iter()
        .filter_map(number)
        .find(|&n| n >= 1.0)
        .map(|n| n as u64);
    let duration_s = [&video["duration"], &root["format"]["duration"]]
        .into_iter()
        .filter_map(number)
        .find(|d| d.is_finite() && *d > 0.0);
    Ok(Probe {
        info: VideoInfo {
            width,
            height,
            fps,
            frame_count,
            duration_s,
            has_audio: audio_codec.is_some(),
            fps_assumed: false,
        },
        audio_codec,
        data_tracks,
        timecode: video["tags"]["timecode"].as_str().map(str::to_string),
        format_name: root["format"]["format_name"]
            .as_str()
            .unwrap_or_default()
            .to_string(),
        video_index: video["index"].as_u64().unwrap_or(0),
        native_420: Native420::of(video["pix_fmt"].as_str(), video["color_range"].as_str()),
    })
}

/// `"30000/1001"` -> 29.97; `None` for `0/0` and nonsense.
fn parse_rate(s: &str) -> Option<f64> {
    let (n, d) = s.split_once('/').unwrap_or((s, "1"));
    let r = n.trim().parse::<f64>().ok()? / d.trim().parse::<f64>().ok()?;
    (r.is_finite() && r > 0.0 && r <= 10_000.0).then_some(r)
}

/// Whether the stream is flagged to be displayed rotated by 90 or 270 degrees.
fn quarter_turn(stream: &Value) -> bool {
    let from_side_data = stream["side_data_list"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|sd| sd["rotation"].as_f64());
    let from_tag = stream["tags"]["rotate"]
        .as_str()
        .and_then(|s| s.parse::<f64>().ok());
    from_side_data
        .chain(from_tag)
        .next()
        .map(|r| (r.round() as i64).rem_euclid(180) == 90)
        .unwrap_or(false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rates_and_rotation() {
        assert!((parse_rate("30000/1001").unwrap() - 29.97).abs() < 0.01);
        assert_eq!(parse_rate("0/0"), None);
        assert_eq!(parse_rate("25"), Some(25.0));
        let json = br#"{"streams":[{"codec_type":"video","width":640,"height":480,
            "avg_frame_rate":"0/0","r_frame_rate":"25/1",
            "side_data_list":[{"rotation":-90}]}],"format":{"duration":"2.0"}}"#;
        let p = parse(Path::new("x.mov"), json).unwrap();
        assert_eq!((p.info.width, p.info.height), (480, 640));
        assert_eq!(p.info.fps, 25.0);
        assert_eq!(p.info.duration_s, Some(2.0));
        assert_eq!(p.info.frame_count, None);
        assert!(!p.info.has_audio);
        let json = br#"{"streams":[{"codec_type":"audio","codec_name":"mp3"}]}"#;
        let e = parse(Path::new("x.mp3"), json).unwrap_err();
        assert!(e.to_string().contains("no video stream"), "{e}");
    }
}
