//! Entry points for the fuzz targets (`fuzz/`, cargo-fuzz) and for the
//! stable regression tests that replay what they found: each runs one of the
//! service's parsers on arbitrary input exactly as a request would and returns
//! what the client would get (a status and a message). Not an API: hidden
//! from the docs and free to change with the targets.

use super::live::decode_ingest_frame;
use super::options::JobOptions;
use super::problem::ApiError;
use super::storage::{DiskBudget, Scratch};
use super::upload;
use amc_core::{Frame, PixelFormat};
use axum::body::Body;
use axum::http::{header, HeaderMap, HeaderValue};
use std::path::Path;
use std::sync::Arc;

/// What a request got: its status and the problem's detail.
pub type Refusal = (u16, String);

fn refusal(e: ApiError) -> Refusal {
    (e.status().as_u16(), e.to_string())
}

/// `POST /stabilize?QUERY`'s options.
pub fn query_options(query: &str) -> Result<JobOptions, Refusal> {
    JobOptions::from_query(Some(query)).map_err(refusal)
}

/// What an accepted upload held.
#[derive(Debug)]
pub struct Received {
    /// Bytes of the video stored.
    pub bytes: u64,
    /// The `lens` form field's text.
    pub lens: Option<String>,
    /// Entries left in the scratch folder's parent after the request ended
    /// (must be 0: nothing a client sent stays on disk).
    pub left_on_disk: usize,
}

/// Receives `body` (sent in `chunks`, as a network would split it) with
/// `content_type` into a fresh scratch folder under `root`, as the intake of
/// `POST /stabilize` does, with an upload limit of `max_bytes`. The scratch
/// folder is dropped before returning, as at the end of a request, and what is
/// left under `root` is counted.
pub fn receive_upload(
    root: &Path,
    content_type: &str,
    chunks: Vec<Vec<u8>>,
    max_bytes: u64,
) -> Result<Received, Refusal> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| (500, format!("runtime: {e}")))?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(content_type) {
        headers.insert(header::CONTENT_TYPE, v);
    }
    let stream = futures_util::stream::iter(
        chunks
            .into_iter()
            .map(|c| Ok::<_, std::io::Error>(bytes::Bytes::from(c))),
    );
    let body = Body::from_stream(stream).into_data_stream();
    let budget = Arc::new(DiskBudget::new(max_bytes.saturating_mul(2).max(1)));
    let result = runtime.block_on(async {
        let scratch = Scratch::new(root, budget.clone()).map_err(|e| (500, e.to_string()))?;
        let mut body = Some(body);
        let received = upload::receive(&headers, &mut body, &scratch, max_bytes, false).await;
        drop(scratch);
        received.map_err(refusal)
    });
    let left_on_disk = std::fs::read_dir(root).map(|d| d.count()).unwrap_or(0);
    if budget.used() != 0 {
        return Err((
            500,
            format!("{} bytes of the disk budget not given back", budget.used()),
        ));
    }
    result.map(|u| Received {
        bytes: u.bytes,
        lens: u.lens,
        left_on_disk,
    })
}

/// A `/live/ingest` message as the live processor takes it: decoded (within
/// the live feed's size limits) into an RGB frame.
pub fn ingest_frame(bytes: &[u8]) -> Result<Frame, String> {
    let mut frame = Frame::new(0, 0, PixelFormat::Rgb8);
    decode_ingest_frame(bytes, &mut frame).map_err(|e| e.to_string())?;
    Ok(frame)
}
