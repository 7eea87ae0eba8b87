//! `GET /live/ingest`: one publisher's WebSocket (a ground station relaying a
//! drone's feed); each binary message is one JPEG frame, or one H.264 access
//! unit in Annex-B form (told apart by its first bytes), for the processor.

use super::hub::Publishing;
use super::viewer::not_a_websocket;
use crate::serve::problem::ApiError;
use crate::serve::state::{until_shutdown, AppState};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::response::Response;
use std::sync::Arc;

/// Largest JPEG frame a publisher may send.
pub const MAX_INGEST_FRAME_BYTES: usize = 16 << 20;

/// `GET /live/ingest`: a publisher's WebSocket; each binary message is one JPEG frame.
pub async fn ingest(
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
    State(state): State<Arc<AppState>>,
) -> Result<Response, ApiError> {
    let ws = ws.map_err(|e| not_a_websocket("/live/ingest", &e))?;
    if let Some(source) = &state.live.config.source {
        return Err(ApiError::Conflict(format!(
            "the live feed comes from --live-source {source}; ingest is for a server started without it"
        )));
    }
    let Some(slot) = state.live.publish() else {
        return Err(ApiError::Conflict(
            "another publisher is connected to /live/ingest; one at a time".into(),
        ));
    };
    Ok(ws
        .max_message_size(MAX_INGEST_FRAME_BYTES)
        .on_upgrade(move |socket| serve_publisher(socket, state, slot)))
}

async fn serve_publisher(mut socket: WebSocket, state: Arc<AppState>, slot: Publishing) {
    let mut shutdown = state.shutdown.subscribe();
    tracing::info!("live publisher connected");
    loop {
        tokio::select! {
            msg = socket.recv() => match msg {
                Some(Ok(Message::Binary(bytes))) if amc_video::is_annex_b(&bytes) => {
                    state.live.submit_h264(bytes)
                }
                Some(Ok(Message::Binary(bytes))) => state.live.submit_jpeg(bytes),
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
            _ = until_shutdown(&mut shutdown) => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
    tracing::info!("live publisher disconnected");
    drop(slot);
}
