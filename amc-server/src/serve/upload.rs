//! Receiving a clip: the raw request body (a video content type) or
//! `multipart/form-data` with a `video` file, an optional `lens` file and an
//! optional `gyro` log. Bytes go straight to the request's scratch folder,
//! counted against the upload limit and the disk budget as they arrive,
//! never held in memory.

use super::problem::ApiError;
use super::storage::Scratch;
use axum::body::BodyDataStream;
use axum::http::{header, HeaderMap};
use futures_util::StreamExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use tokio::io::AsyncWriteExt;

/// Longest lens file accepted (a calibration is a few kilobytes).
pub const MAX_LENS_BYTES: usize = 1 << 20;

/// Longest gyro log accepted: a 1 kHz flight-controller blackbox of a
/// quarter of an hour, or a camera's whole MP4 sent as its own log, fits.
pub const MAX_GYRO_BYTES: u64 = 64 << 20;

/// The gyro log's name in the scratch folder, before its extension. Not
/// `input.gcsv`: that is the clip's sidecar, which `gyro=auto` looks for.
const GYRO_FILE: &str = "gyro-log";

/// A received clip.
#[derive(Debug)]
pub struct Upload {
    pub video: PathBuf,
    /// The text of a lens file sent as the `lens` form field.
    pub lens: Option<String>,
    /// A gyro log sent as the `gyro` form field, in the scratch folder
    /// (with the extension the client's file name had: telemetry-parser
    /// tells some formats by it).
    pub gyro: Option<PathBuf>,
    pub bytes: u64,
}

/// Content types accepted as a raw video body besides `video/*`.
const RAW_TYPES: &[&str] = &[
    "application/octet-stream",
    "application/mp4",
    "application/x-matroska",
];

/// A file being received, enforcing the upload limit and the disk budget.
struct Incoming<'a> {
    file: tokio::fs::File,
    total: u64,
    scratch: &'a Scratch,
    max_bytes: u64,
}

fn store_error(e: std::io::Error) -> ApiError {
    ApiError::Internal(format!("cannot store the upload: {e}"))
}

impl<'a> Incoming<'a> {
    async fn create(path: &Path, scratch: &'a Scratch, max_bytes: u64) -> Result<Self, ApiError> {
        Ok(Self {
            file: tokio::fs::File::create(path).await.map_err(store_error)?,
            total: 0,
            scratch,
            max_bytes,
        })
    }

    async fn push(&mut self, chunk: &[u8]) -> Result<(), ApiError> {
        self.total += chunk.len() as u64;
        if self.total > self.max_bytes {
            return Err(ApiError::TooLarge {
                limit_mb: self.max_bytes / 1_000_000,
            });
        }
        if !self.scratch.reserve(chunk.len() as u64) {
            return Err(ApiError::Saturated(
                "the service's disk space for uploads is in use; try again shortly".into(),
            ));
        }
        self.file.write_all(chunk).await.map_err(store_error)
    }

    async fn finish(mut self) -> Result<u64, ApiError> {
        self.file.flush().await.map_err(store_error)?;
        Ok(self.total)
    }
}

fn interrupted(e: impl std::fmt::Display) -> ApiError {
    ApiError::BadRequest(format!("the upload was interrupted: {e}"))
}

/// Most of an unwanted upload read and discarded after an early answer.
pub const LINGER_BYTES: u64 = 256 << 20;
/// Longest an unwanted upload is read and discarded after an early answer.
pub const LINGER_TIME: std::time::Duration = std::time::Duration::from_secs(30);

/// Reads and discards what is left of a request body after it was answered
/// early (a bad option, 413, 503): a client still sending would otherwise
/// see the connection reset instead of the answer, as with nginx's lingering close.
pub fn linger(mut rest: BodyDataStream) {
    tokio::spawn(async move {
        let _ = tokio::time::timeout(LINGER_TIME, async {
            let mut n = 0u64;
            while let Some(Ok(chunk)) = rest.next().await {
                n += chunk.len() as u64;
                if n > LINGER_BYTES {
                    break;
                }
            }
        })
        .await;
    });
}

/// Receives the clip into `scratch`. `body` is taken once fully read; on an
/// error it is left for the caller to [`linger`] on. `gyro_off`: the query
/// said `gyro=off`, so a `gyro` field is refused as soon as it starts.
pub async fn receive(
    headers: &HeaderMap,
    body: &mut Option<BodyDataStream>,
    scratch: &Scratch,
    max_bytes: u64,
    gyro_off: bool,
) -> Result<Upload, ApiError> {
    let content_type = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    let essence = content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    // A form may carry a lens file and a gyro log beside the clip (each
    // part's own limit is checked as it arrives).
    let most = if essence == "multipart/form-data" {
        max_bytes.saturating_add(MAX_GYRO_BYTES + MAX_LENS_BYTES as u64)
    } else {
        max_bytes
    };
    if declared.is_some_and(|n| n > most) {
        return Err(ApiError::TooLarge {
            limit_mb: max_bytes / 1_000_000,
        });
    }
    let video = scratch.file("input");
    let upload = if essence == "multipart/form-data" {
        let Some(stream) = body.take() else {
            return Err(ApiError::BadRequest("the request has no body".into()));
        };
        // The form parser owns the stream while it works; on an error the
        // unread rest comes back through `shared` to be lingered on.
        let shared = SharedStream(Arc::new(Mutex::new(Some(stream))));
        let result = receive_multipart(
            &content_type,
            shared.clone(),
            scratch,
            &video,
            max_bytes,
            gyro_off,
        )
        .await;
        if result.is_err() {
            *body = shared.0.lock().unwrap_or_else(|e| e.into_inner()).take();
        }
        result?
    } else if essence.is_empty()
        || essence.starts_with("video/")
        || RAW_TYPES.contains(&essence.as_str())
    {
        let mut file = Incoming::create(&video, scratch, max_bytes).await?;
        if let Some(chunks) = body.as_mut() {
            while let Some(chunk) = chunks.next().await {
                file.push(&chunk.map_err(interrupted)?).await?;
            }
        }
        *body = None;
        let bytes = file.finish().await?;
        Upload {
            video,
            lens: None,
            gyro: None,
            bytes,
        }
    } else {
        return Err(ApiError::Unsupported(format!(
            "Content-Type {essence} is not a video: send the clip as the body with a video/* type \
             (video/mp4, video/webm, video/quicktime...) or as the `video` field of multipart/form-data"
        )));
    };
    if upload.bytes == 0 {
        return Err(ApiError::BadRequest(
            "the request has no video: send the clip as the body (Content-Type video/mp4, ...) \
             or as the `video` field of multipart/form-data"
                .into(),
        ));
    }
    Ok(upload)
}

/// A body stream that can be taken back after the form parser is done with it.
#[derive(Clone)]
struct SharedStream(Arc<Mutex<Option<BodyDataStream>>>);

impl futures_util::Stream for SharedStream {
    type Item = Result<bytes::Bytes, axum::Error>;

    fn poll_next(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Self::Item>> {
        let mut inner = self.0.lock().unwrap_or_else(|e| e.into_inner());
        match inner.as_mut() {
            Some(s) => s.poll_next_unpin(cx),
            None => std::task::Poll::Ready(None),
        }
    }
}

async fn receive_multipart(
    content_type: &str,
    stream: SharedStream,
    scratch: &Scratch,
    video: &Path,
    max_bytes: u64,
    gyro_off: bool,
) -> Result<Upload, ApiError> {
    // The form is parsed with `multer` directly: axum's `Multipart` extractor,
    // used on a request built here, would apply its default 2 MB body limit
    // (the route's `DefaultBodyLimit::disable()` lives on the original
    // request). Our own limit is enforced per chunk by `Incoming`.
    let boundary = multer::parse_boundary(content_type)
        .map_err(|e| ApiError::BadRequest(format!("invalid multipart/form-data: {e}")))?;
    let mut form = multer::Multipart::new(stream, boundary);
    let mut got_video = None;
    let mut lens = None;
    let mut gyro = None;
    let bad = |e: multer::Error| ApiError::BadRequest(format!("invalid multipart/form-data: {e}"));
    while let Some(mut field) = form.next_field().await.map_err(bad)? {
        match field.name().unwrap_or("") {
            "video" => {
                if got_video.is_some() {
                    return Err(ApiError::BadRequest("more than one `video` field".into()));
                }
                let mut file = Incoming::create(video, scratch, max_bytes).await?;
                while let Some(chunk) = field.chunk().await.map_err(interrupted)? {
                    file.push(&chunk).await?;
                }
                got_video = Some(file.finish().await?);
            }
            "lens" => {
                let mut text = Vec::new();
                while let Some(chunk) = field.chunk().await.map_err(bad)? {
                    text.extend_from_slice(&chunk);
                    if text.len() > MAX_LENS_BYTES {
                        return Err(ApiError::BadOption(format!(
                            "the lens file is larger than {} KB; send a lens JSON/YAML calibration",
                            MAX_LENS_BYTES / 1024
                        )));
                    }
                }
                lens = Some(String::from_utf8(text).map_err(|_| {
                    ApiError::BadOption("the lens file is not UTF-8 text (JSON or YAML)".into())
                })?);
            }
            "gyro" => {
                if gyro_off {
                    // Well-formed, but nothing a run could do: 422, as a log that is no log.
                    return Err(ApiError::UnusableGyro(
                        "gyro=off contradicts the `gyro` form field: send the log without \
                         gyro=off (or gyro=auto) to use it, or gyro=off without the log"
                            .into(),
                    ));
                }
                if gyro.is_some() {
                    return Err(ApiError::BadRequest("more than one `gyro` field".into()));
                }
                let path = scratch.file(&gyro_file_name(field.file_name()));
                let mut file = Incoming::create(&path, scratch, MAX_GYRO_BYTES).await?;
                while let Some(chunk) = field.chunk().await.map_err(interrupted)? {
                    file.push(&chunk).await.map_err(|e| match e {
                        ApiError::TooLarge { .. } => ApiError::GyroTooLarge {
                            limit_mib: MAX_GYRO_BYTES >> 20,
                        },
                        e => e,
                    })?;
                }
                if file.finish().await? == 0 {
                    return Err(ApiError::BadOption(
                        "the `gyro` form field is empty: send the gyro log's file".into(),
                    ));
                }
                gyro = Some(path);
            }
            other => {
                return Err(ApiError::BadRequest(format!(
                    "unknown form field {other:?} (known: video, lens, gyro)"
                )))
            }
        }
    }
    let bytes = got_video.ok_or_else(|| {
        ApiError::BadRequest("the form has no `video` field with the clip".into())
    })?;
    Ok(Upload {
        video: video.to_path_buf(),
        lens,
        gyro,
        bytes,
    })
}

/// The gyro log's scratch name: [`GYRO_FILE`] with the client's extension
/// when it is a plain one (`.gcsv`, `.bbl`, `.log`, `.csv`, `.mp4`);
/// anything else in the client's name is dropped (it names a path here).
fn gyro_file_name(client_name: Option<&str>) -> String {
    let ext = client_name
        .and_then(|n| Path::new(n).extension())
        .and_then(|e| e.to_str())
        .filter(|e| !e.is_empty() && e.len() <= 8 && e.chars().all(|c| c.is_ascii_alphanumeric()));
    match ext {
        Some(e) => format!("{GYRO_FILE}.{}", e.to_ascii_lowercase()),
        None => GYRO_FILE.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::gyro_file_name;

    #[test]
    fn gyro_file_names_keep_only_a_plain_extension() {
        assert_eq!(gyro_file_name(Some("flight.GCSV")), "gyro-log.gcsv");
        assert_eq!(gyro_file_name(Some("../../etc/x.bbl")), "gyro-log.bbl");
        assert_eq!(gyro_file_name(Some("a.b/c")), "gyro-log");
        assert_eq!(gyro_file_name(Some("x.tar-gz")), "gyro-log");
        assert_eq!(gyro_file_name(Some("noext")), "gyro-log");
        assert_eq!(gyro_file_name(None), "gyro-log");
    }
}
