//! `GET /live`: a viewer's WebSocket. Each frame is a JPEG (binary) then its
//! telemetry (text), flow-controlled with pings so a slow viewer skips
//! frames instead of queueing them. With `?codec=h264` each binary message
//! is an H.264 access unit (Annex-B) of the feed's shared encoder, starting
//! at a keyframe; a viewer that falls behind skips to the next keyframe.

use crate::serve::problem::ApiError;
use crate::serve::state::{until_shutdown, AppState};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{RawQuery, State};
use axum::response::Response;
use bytes::Bytes;
use std::sync::Arc;

/// Frames a viewer may have unread before it is skipped ahead (about 0.2 s
/// at 30 frames/s: enough for a round trip on a slow link, little staleness).
const VIEWER_IN_FLIGHT: u64 = 6;
/// The same for H.264, where falling behind costs up to a second (the wait
/// for the next keyframe): half a second at 60 frames/s.
const H264_IN_FLIGHT: u64 = 30;

/// `GET /live`: a viewer's WebSocket.
pub async fn viewer(
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
    State(state): State<Arc<AppState>>,
    RawQuery(query): RawQuery,
) -> Result<Response, ApiError> {
    let codec = codec(query.as_deref())?;
    let ws = ws.map_err(|e| not_a_websocket("/live", &e))?;
    Ok(match codec {
        Codec::Jpeg => ws.on_upgrade(move |socket| serve_viewer(socket, state)),
        Codec::H264 => ws.on_upgrade(move |socket| serve_h264_viewer(socket, state)),
    })
}

/// What a viewer's binary messages hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Codec {
    Jpeg,
    H264,
}

/// `?codec=jpeg|h264` (default jpeg: clients without a video decoder).
fn codec(query: Option<&str>) -> Result<Codec, ApiError> {
    let asked = form_urlencoded::parse(query.unwrap_or("").as_bytes())
        .find(|(k, _)| k == "codec")
        .map(|(_, v)| v.into_owned());
    match asked.as_deref() {
        None | Some("jpeg") => Ok(Codec::Jpeg),
        Some("h264") => Ok(Codec::H264),
        Some(other) => Err(ApiError::BadOption(format!(
            "codec={:?} (allowed: jpeg or h264)",
            other.chars().take(40).collect::<String>()
        ))),
    }
}

/// A plain request to a WebSocket endpoint: 426 (problem+json) saying how to connect.
pub fn not_a_websocket(path: &str, e: &WebSocketUpgradeRejection) -> ApiError {
    ApiError::UpgradeRequired(format!(
        "{path} is a WebSocket endpoint: connect with a WebSocket client (ws://HOST{path}); {}",
        e.body_text().trim_end_matches('.').to_lowercase()
    ))
}

async fn serve_viewer(mut socket: WebSocket, state: Arc<AppState>) {
    // Counted while connected: the first viewer resumes a paused feed.
    let _viewing = state.live.watch();
    let mut frames = state.live.subscribe();
    let mut shutdown = state.shutdown.subscribe();
    let mut last: Option<u64> = None;
    // Flow control: each frame is followed by a ping carrying its number;
    // the viewer's pong says it has read that far. A viewer that has not
    // read the last VIEWER_IN_FLIGHT frames gets none until it has, so
    // what it sees is never more than that many frames old.
    let mut sent = 0u64;
    let mut acked = 0u64;
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(frame) = frames.borrow_and_update().clone() else { continue };
                if sent - acked >= VIEWER_IN_FLIGHT {
                    continue;
                }
                if let Some(prev) = last {
                    if frame.frame > prev + 1 {
                        state.metrics.live_dropped.inc_by(frame.frame - prev - 1);
                    }
                }
                last = Some(frame.frame);
                if !send_frame(&mut socket, &frame.jpeg, &frame.meta, sent).await {
                    break;
                }
                sent += 1;
            }
            msg = socket.recv() => if !read_ack(msg, &mut acked, sent) {
                break;
            },
            _ = until_shutdown(&mut shutdown) => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
}

/// Sends a frame (binary), its telemetry (text) and a ping carrying its
/// number, which the viewer's pong acknowledges; `false` once it has left.
async fn send_frame(socket: &mut WebSocket, data: &Bytes, meta: &str, number: u64) -> bool {
    socket.send(Message::Binary(data.clone())).await.is_ok()
        && socket
            .send(Message::Text(meta.to_owned().into()))
            .await
            .is_ok()
        && socket
            .send(Message::Ping(Bytes::copy_from_slice(&number.to_be_bytes())))
            .await
            .is_ok()
}

/// A viewer's message: a pong moves `acked` on (never past `sent`); `false`
/// when the viewer left.
fn read_ack(msg: Option<Result<Message, axum::Error>>, acked: &mut u64, sent: u64) -> bool {
    match msg {
        Some(Ok(Message::Pong(payload))) => {
            if let Ok(n) = <[u8; 8]>::try_from(payload.as_ref()) {
                *acked = (*acked).max(u64::from_be_bytes(n) + 1).min(sent);
            }
            true
        }
        Some(Ok(Message::Close(_))) | None | Some(Err(_)) => false,
        Some(Ok(_)) => true,
    }
}

/// An H.264 viewer: access units from the shared encoder, from a keyframe
/// on; flow control as for JPEGs, but a viewer that falls behind (or lags
/// the broadcast) waits for the next keyframe, since a decoder cannot skip
/// the pictures in between.
async fn serve_h264_viewer(mut socket: WebSocket, state: Arc<AppState>) {
    let _viewing = state.live.watch();
    let (mut units, _h264) = state.live.watch_h264();
    let mut shutdown = state.shutdown.subscribe();
    let mut need_key = true;
    let mut sent = 0u64;
    let mut acked = 0u64;
    loop {
        tokio::select! {
            unit = units.recv() => {
                let unit = match unit {
                    Ok(u) => u,
                    Err(tokio::sync::broadcast::error::RecvError::Lagged(n)) => {
                        state.metrics.live_dropped.inc_by(n);
                        need_key = true;
                        continue;
                    }
                    Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
                };
                let behind = sent - acked >= H264_IN_FLIGHT;
                need_key |= behind;
                if behind || (need_key && !unit.key) {
                    state.metrics.live_dropped.inc();
                    continue;
                }
                need_key = false;
                if !send_frame(&mut socket, &unit.data, &unit.meta, sent).await {
                    break;
                }
                sent += 1;
            }
            msg = socket.recv() => if !read_ack(msg, &mut acked, sent) {
                break;
            },
            _ = until_shutdown(&mut shutdown) => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codec_is_jpeg_unless_h264_is_asked_for() {
        assert_eq!(codec(None).unwrap(), Codec::Jpeg);
        assert_eq!(codec(Some("ticket=abc")).unwrap(), Codec::Jpeg);
        assert_eq!(codec(Some("codec=jpeg")).unwrap(), Codec::Jpeg);
        assert_eq!(codec(Some("ticket=t&codec=h264")).unwrap(), Codec::H264);
        assert!(codec(Some("codec=vp9")).is_err());
    }
}
