//! `GET /live`: a viewer's WebSocket. Each frame is a JPEG (binary) then its
//! telemetry (text), flow-controlled with pings so a slow viewer skips
//! frames instead of queueing them.

use crate::serve::problem::ApiError;
use crate::serve::state::{until_shutdown, AppState};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::response::Response;
use bytes::Bytes;
use std::sync::Arc;

/// Frames a viewer may have unread before it is skipped ahead (about 0.2 s
/// at 30 frames/s: enough for a round trip on a slow link, little staleness).
const VIEWER_IN_FLIGHT: u64 = 6;

/// `GET /live`: a viewer's WebSocket.
pub async fn viewer(
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
    State(state): State<Arc<AppState>>,
) -> Result<Response, ApiError> {
    let ws = ws.map_err(|e| not_a_websocket("/live", &e))?;
    Ok(ws.on_upgrade(move |socket| serve_viewer(socket, state)))
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
                if socket.send(Message::Binary(frame.jpeg.clone())).await.is_err()
                    || socket.send(Message::Text(frame.meta.clone().into())).await.is_err()
                    || socket.send(Message::Ping(Bytes::copy_from_slice(&sent.to_be_bytes()))).await.is_err()
                {
                    break;
                }
                sent += 1;
            }
            msg = socket.recv() => match msg {
                Some(Ok(Message::Pong(payload))) => {
                    if let Ok(n) = <[u8; 8]>::try_from(payload.as_ref()) {
                        acked = acked.max(u64::from_be_bytes(n) + 1).min(sent);
                    }
                }
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
            _ = until_shutdown(&mut shutdown) => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
}
