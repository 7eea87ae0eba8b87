//! `POST /live/ticket`: a browser trades its key (the `Authorization`
//! header) for a single-use ticket that opens `/live?ticket=...` (or
//! `/live/ingest?ticket=...`) within 30 seconds, with the key's tenant and
//! roles. Without `--auth-keys` the ticket is issued too, and not needed.

use crate::auth::gate::principal;
use crate::auth::TICKET_TTL;
use crate::serve::problem::ApiError;
use crate::serve::state::AppState;
use axum::extract::{Request, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::sync::Arc;

/// `POST /live/ticket`.
pub async fn ticket(
    State(state): State<Arc<AppState>>,
    request: Request,
) -> Result<Response, ApiError> {
    let who = principal(&request)?;
    let ticket = state.auth.tickets.issue(&who).await?;
    let mut res = Json(serde_json::json!({
        "ticket": ticket,
        "expires_in_s": TICKET_TTL.as_secs(),
    }))
    .into_response();
    res.headers_mut().insert(
        header::CACHE_CONTROL,
        header::HeaderValue::from_static("no-store"),
    );
    Ok(res)
}
