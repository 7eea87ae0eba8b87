//! The middleware every request passes ([`check`]): what the endpoint
//! needs ([`Need`]), the caller's key (`Authorization: Bearer KEY`) or live
//! ticket (`?ticket=`, on the two WebSocket endpoints only), the failure
//! and rate limits, the role, and the `Origin` of WebSocket upgrades. The
//! request goes on with its [`Principal`] in its extensions.
//!
//! Nothing here logs or echoes a key, a ticket or the `Authorization`
//! header; errors say what was wrong, never what was sent.

use super::limits::retry_secs;
use super::{Auth, Need, Principal};
use crate::serve::problem::ApiError;
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderMap};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;

/// What the request presented.
enum Credential<'a> {
    None,
    Key(&'a str),
    Ticket(String),
    /// An `Authorization` header that is not `Bearer <token>`.
    Malformed,
}

fn credential<'a>(headers: &'a HeaderMap, query: Option<&str>, need: Need) -> Credential<'a> {
    if let Some(v) = headers.get(header::AUTHORIZATION) {
        let Ok(v) = v.to_str() else {
            return Credential::Malformed;
        };
        let mut parts = v.splitn(2, ' ');
        let scheme = parts.next().unwrap_or("");
        let token = parts.next().unwrap_or("").trim();
        if !scheme.eq_ignore_ascii_case("bearer") || token.is_empty() {
            return Credential::Malformed;
        }
        return Credential::Key(token);
    }
    if matches!(need, Need::View | Need::Publish) {
        let ticket = form_urlencoded::parse(query.unwrap_or("").as_bytes())
            .find(|(k, _)| k == "ticket")
            .map(|(_, v)| v.into_owned());
        if let Some(t) = ticket {
            return Credential::Ticket(t);
        }
    }
    Credential::None
}

/// The client's address (the listener's `ConnectInfo`; a request without
/// one, as in the router's tests, counts as 0.0.0.0).
fn peer(request: &Request) -> IpAddr {
    request
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |c| c.0.ip())
}

fn unauthorized(detail: &str) -> Response {
    ApiError::Unauthorized(detail.to_string()).into_response()
}

fn too_many(detail: String, wait: std::time::Duration) -> Response {
    ApiError::TooManyRequests {
        detail,
        retry_after_s: retry_secs(wait),
    }
    .into_response()
}

/// A WebSocket upgrade's `Origin` must be this service's own (same host as
/// the `Host` header) or one of `--cors-origin`: a page on another site
/// cannot open the feed with a visitor's ticket (cross-site WebSocket
/// hijacking). Clients that send no `Origin` (tools) are not browsers.
fn origin_allowed(headers: &HeaderMap, allowed: &[String]) -> Result<(), String> {
    let Some(origin) = headers.get(header::ORIGIN) else {
        return Ok(());
    };
    let origin = origin.to_str().unwrap_or("");
    if allowed.iter().any(|a| a == origin) {
        return Ok(());
    }
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or("");
    let origin_host = origin
        .strip_prefix("https://")
        .or_else(|| origin.strip_prefix("http://"))
        .unwrap_or("");
    if !host.is_empty() && origin_host.eq_ignore_ascii_case(host) {
        return Ok(());
    }
    Err(format!(
        "a WebSocket from origin {:?} is refused: only this service's own page{} may open it",
        origin.chars().take(100).collect::<String>(),
        if allowed.is_empty() {
            String::new()
        } else {
            format!(" and {}", allowed.join(", "))
        }
    ))
}

/// The middleware: `axum::middleware::from_fn_with_state(auth, check)`.
pub async fn check(State(auth): State<Arc<Auth>>, mut request: Request, next: Next) -> Response {
    let need = Need::of(request.method(), request.uri().path());
    if need == Need::Public {
        return next.run(request).await;
    }
    if matches!(need, Need::View | Need::Publish) {
        if let Err(why) = origin_allowed(request.headers(), &auth.config.cors_origins) {
            return ApiError::Forbidden(why).into_response();
        }
    }
    if !auth.enabled() {
        request.extensions_mut().insert(Principal::local());
        return next.run(request).await;
    }
    let ip = peer(&request);
    let cred = credential(request.headers(), request.uri().query(), need);
    let who = match cred {
        Credential::None => {
            return unauthorized(
                "this service needs an API key, sent as a bearer token (RFC 6750); \
                 browsers opening /live: `?ticket=` from POST /live/ticket",
            )
        }
        Credential::Malformed => None,
        Credential::Key(key) => auth.lookup(key),
        Credential::Ticket(t) => match auth.tickets.redeem(&t).await {
            Ok(who) => who,
            Err(e) => return ApiError::from(e).into_response(),
        },
    };
    // A right key is served even from an address that is over its failure
    // budget: otherwise a stranger behind the same NAT or proxy could lock
    // the real users out. Keys are 256-bit random, so guessing is not what
    // this limit is for; it bounds the work and log lines failures cost.
    let Some(who) = who else {
        let wait = auth.failures.blocked(ip).or_else(|| auth.failures.fail(ip));
        if let Some(wait) = wait {
            return too_many(
                format!(
                    "too many wrong keys from this address (allowed: {} a minute, --auth-failures)",
                    auth.config.auth_failures
                ),
                wait,
            );
        }
        return unauthorized(
            "the key (or ticket) is not valid: tickets are single-use and expire after 30 s",
        );
    };
    if let Some(line) = who.key {
        if let Some(wait) = auth.rates.check(line) {
            return too_many(
                format!(
                    "this key sent more than {} requests a second (--key-rate); slow down",
                    auth.config.key_rate
                ),
                wait,
            );
        }
    }
    if !need.met_by(who.roles) {
        return ApiError::Forbidden(format!(
            "this key (tenant {:?}, roles {}) may not use {}: it needs the role {}",
            who.tenant,
            if who.roles.names().is_empty() {
                "none".to_string()
            } else {
                who.roles.to_string()
            },
            request.uri().path(),
            need.describe()
        ))
        .into_response();
    }
    request.extensions_mut().insert(who);
    next.run(request).await
}

/// The caller a handler serves (put there by [`check`]).
pub fn principal(request: &Request) -> Result<Principal, ApiError> {
    request
        .extensions()
        .get::<Principal>()
        .cloned()
        .ok_or_else(|| ApiError::Internal("the request passed no access check".into()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn headers(pairs: &[(header::HeaderName, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(k.clone(), HeaderValue::from_str(v).unwrap());
        }
        h
    }

    #[test]
    fn websockets_from_other_sites_are_refused() {
        let same = headers(&[
            (header::HOST, "amc.example:8080"),
            (header::ORIGIN, "https://amc.example:8080"),
        ]);
        assert!(origin_allowed(&same, &[]).is_ok());
        let tool = headers(&[(header::HOST, "amc.example")]);
        assert!(origin_allowed(&tool, &[]).is_ok());
        let evil = headers(&[
            (header::HOST, "amc.example"),
            (header::ORIGIN, "https://evil.example"),
        ]);
        assert!(origin_allowed(&evil, &[]).is_err());
        assert!(origin_allowed(&evil, &["https://evil.example".to_string()]).is_ok());
        let lookalike = headers(&[
            (header::HOST, "amc.example"),
            (header::ORIGIN, "https://amc.example.evil.example"),
        ]);
        assert!(origin_allowed(&lookalike, &[]).is_err());
    }

    #[test]
    fn only_bearer_tokens_are_keys_and_tickets_only_open_sockets() {
        let bearer = headers(&[(header::AUTHORIZATION, "Bearer abc")]);
        assert!(matches!(
            credential(&bearer, None, Need::Jobs),
            Credential::Key("abc")
        ));
        let basic = headers(&[(header::AUTHORIZATION, "Basic abc")]);
        assert!(matches!(
            credential(&basic, None, Need::Jobs),
            Credential::Malformed
        ));
        let none = HeaderMap::new();
        assert!(matches!(
            credential(&none, Some("ticket=t"), Need::View),
            Credential::Ticket(_)
        ));
        assert!(matches!(
            credential(&none, Some("ticket=t"), Need::Jobs),
            Credential::None
        ));
    }
}
