//! The router driven in process (no socket): routing, errors, a small job.

use super::*;
use axum::body::{to_bytes, Body};
use axum::http::{header, Request, StatusCode};
use axum::Router;
use std::sync::Arc;
use std::time::Duration;
use tower::ServiceExt;

fn state(dir: &std::path::Path) -> Arc<AppState> {
    let limits = Limits {
        workers: 1,
        queue: 1,
        ..Limits::default()
    };
    AppState::new(
        limits,
        dir.join("work"),
        dir.join("no-web"),
        LiveConfig::default(),
        None,
        Arc::new(
            crate::auth::Auth::new(
                crate::auth::AuthConfig::default(),
                crate::auth::Tickets::local(),
            )
            .unwrap(),
        ),
    )
    .unwrap()
}

async fn call(app: &Router, req: Request<Body>) -> (StatusCode, String, serde_json::Value) {
    let res = app.clone().oneshot(req).await.unwrap();
    let status = res.status();
    let ctype = res
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let body = to_bytes(res.into_body(), 1 << 24).await.unwrap();
    let json = serde_json::from_slice(&body).unwrap_or(serde_json::Value::Null);
    (status, ctype, json)
}

fn get(uri: &str) -> Request<Body> {
    Request::get(uri).body(Body::empty()).unwrap()
}

fn delete(uri: &str) -> Request<Body> {
    Request::delete(uri).body(Body::empty()).unwrap()
}

/// A `multipart/form-data` request of `parts` (name, file name, bytes).
fn form(uri: &str, parts: &[(&str, &str, &[u8])]) -> Request<Body> {
    let mut body = Vec::new();
    for (name, file, bytes) in parts {
        body.extend_from_slice(
            format!("--XyZ\r\nContent-Disposition: form-data; name=\"{name}\"; filename=\"{file}\"\r\nContent-Type: application/octet-stream\r\n\r\n")
                .as_bytes(),
        );
        body.extend_from_slice(bytes);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(b"--XyZ--\r\n");
    Request::post(uri)
        .header("content-type", "multipart/form-data; boundary=XyZ")
        .body(Body::from(body))
        .unwrap()
}

/// A `gyro` form field that cannot be used is refused naming why (400 for a
/// broken form, 422 for a file that is no gyro log or a log with gyro=off),
/// before the clip is
/// looked at, and leaves nothing in the scratch space.
#[tokio::test]
async fn gyro_fields_that_cannot_be_used_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(state(dir.path()));
    for (uri, gyro, status, says) in [
        (
            "/stabilize?gyro=off",
            &b"t,gx,gy,gz\n"[..],
            StatusCode::UNPROCESSABLE_ENTITY,
            "gyro=off",
        ),
        (
            "/jobs",
            &b"not a log\n1,2\n"[..],
            StatusCode::UNPROCESSABLE_ENTITY,
            "no gyro log telemetry-parser knows",
        ),
        ("/jobs", &b""[..], StatusCode::BAD_REQUEST, "is empty"),
    ] {
        let req = form(
            uri,
            &[
                ("video", "v.mp4", b"not checked yet"),
                ("gyro", "f.gcsv", gyro),
            ],
        );
        let (s, ctype, j) = call(&app, req).await;
        assert_eq!(s, status, "{uri}: {j}");
        assert_eq!(ctype, "application/problem+json");
        let detail = j["detail"].as_str().unwrap();
        assert!(detail.contains(says), "{uri}: {detail}");
        assert!(!detail.contains("req-"), "{uri}: {detail}");
    }
    let left = std::fs::read_dir(dir.path().join("work")).unwrap().count();
    assert_eq!(left, 0, "scratch folders left");
}

#[tokio::test]
async fn routes_and_errors() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(state(dir.path()));
    let (s, _, j) = call(&app, get("/healthz")).await;
    assert_eq!(s, StatusCode::OK, "{j}");
    assert_eq!(j["status"], "ok");

    let (s, ctype, j) = call(
        &app,
        Request::post("/stabilize?n_avg=0")
            .header("content-type", "video/mp4")
            .body(Body::from("x"))
            .unwrap(),
    )
    .await;
    assert_eq!(s, StatusCode::BAD_REQUEST);
    assert_eq!(ctype, "application/problem+json");
    assert!(j["detail"].as_str().unwrap().contains("n_avg"), "{j}");

    // The smoothing options come from amc-core's table: a bad value is named.
    let (s, _, j) = call(
        &app,
        Request::post("/jobs?rate_a=-1")
            .header("content-type", "video/mp4")
            .body(Body::from("x"))
            .unwrap(),
    )
    .await;
    assert_eq!(s, StatusCode::BAD_REQUEST, "{j}");
    assert!(j["detail"].as_str().unwrap().contains("rate_a"), "{j}");

    // The readout too: a number in 0..=100 ms, or auto.
    for q in ["readout_ms=abc", "readout_ms=200"] {
        let (s, _, j) = call(
            &app,
            Request::post(format!("/stabilize?{q}"))
                .header("content-type", "video/mp4")
                .body(Body::from("x"))
                .unwrap(),
        )
        .await;
        assert_eq!(s, StatusCode::BAD_REQUEST, "{q}: {j}");
        let detail = j["detail"].as_str().unwrap();
        assert!(
            detail.contains("readout_ms") && detail.contains("0..=100"),
            "{q}: {j}"
        );
    }

    let (s, _, _) = call(&app, get("/jobs/abc")).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    let (s, ctype, _) = call(&app, get("/nothing/here")).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    assert_eq!(ctype, "application/problem+json");
    let (s, _, j) = call(&app, get("/jobs")).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(j["jobs"].as_array().map(Vec::len), Some(0), "{j}");
    assert!(j["next_cursor"].is_null(), "{j}");
    for q in ["limit=0", "limit=101", "limit=x", "cursor=abc", "page=2"] {
        let (s, ctype, j) = call(&app, get(&format!("/jobs?{q}"))).await;
        assert_eq!(s, StatusCode::BAD_REQUEST, "{q}");
        assert_eq!(ctype, "application/problem+json", "{q}");
        let name = q.split('=').next().unwrap();
        assert!(j["detail"].as_str().unwrap().contains(name), "{q}: {j}");
    }
    let (s, _, _) = call(&app, Request::put("/jobs").body(Body::empty()).unwrap()).await;
    assert_eq!(s, StatusCode::METHOD_NOT_ALLOWED);
    // The WebSocket endpoints answer a plain request with problem+json 426.
    for path in ["/live", "/live/ingest"] {
        let (s, ctype, j) = call(&app, get(path)).await;
        assert_eq!(s, StatusCode::UPGRADE_REQUIRED, "{path}");
        assert_eq!(ctype, "application/problem+json", "{path}");
        assert!(j["detail"].as_str().unwrap().contains("WebSocket"), "{j}");
    }
    let (s, ctype, _) = call(&app, get("/")).await;
    assert_eq!(s, StatusCode::OK);
    assert!(ctype.starts_with("text/html"));
    let (s, _, doc) = call(&app, get("/openapi.json")).await;
    assert_eq!(s, StatusCode::OK);
    // The spec names exactly the router's paths (router.rs), each operation once.
    let mut paths: Vec<&str> = doc["paths"]
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    paths.sort_unstable();
    assert_eq!(
        paths,
        [
            "/healthz",
            "/jobs",
            "/jobs/{id}",
            "/jobs/{id}/output",
            "/jobs/{id}/telemetry",
            "/jobs/{id}/telemetry.csv",
            "/live",
            "/live/ingest",
            "/live/ticket",
            "/metrics",
            "/openapi.json",
            "/stabilize",
        ]
    );
    assert_eq!(operation_ids(&doc).len(), 14);
}

/// Every operation's `operationId`, checked present, camelCase and unique.
fn operation_ids(doc: &serde_json::Value) -> Vec<String> {
    let mut ids = Vec::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let id = op["operationId"]
                .as_str()
                .unwrap_or_else(|| panic!("{method} {path} has no operationId"));
            assert!(
                id.chars().next().is_some_and(|c| c.is_ascii_lowercase())
                    && id.chars().all(|c| c.is_ascii_alphanumeric()),
                "{method} {path}: operationId {id:?} is not camelCase"
            );
            assert!(!ids.contains(&id.to_string()), "operationId {id} twice");
            ids.push(id.to_string());
        }
    }
    ids
}

#[tokio::test]
async fn every_stabilizer_option_is_documented_with_its_help() {
    let doc = openapi::spec();
    for op in ["/stabilize", "/jobs"] {
        let params = doc["paths"][op]["post"]["parameters"].as_array().unwrap();
        for o in amc_core::options::OPTIONS {
            let p = params
                .iter()
                .find(|p| p["name"] == o.name)
                .unwrap_or_else(|| panic!("POST {op} lacks the option {}", o.name));
            assert_eq!(p["description"], o.help, "{}", o.name);
            assert_eq!(p["in"], "query");
        }
    }
}

/// Every operation but `/healthz` is behind the bearer scheme and says so,
/// with the access check's 401 and 429 (and 403 where a role is needed).
#[tokio::test]
async fn every_operation_declares_the_bearer_scheme_and_its_refusals() {
    let doc = openapi::spec();
    assert_eq!(
        doc["components"]["securitySchemes"]["bearer"]["scheme"],
        "bearer"
    );
    assert_eq!(doc["security"], serde_json::json!([{"bearer": []}]));
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let r = &op["responses"];
            if path == "/healthz" {
                assert_eq!(op["security"], serde_json::json!([]), "{path}");
                assert!(r.get("401").is_none(), "{path}");
                continue;
            }
            for code in ["401", "429"] {
                assert!(r.get(code).is_some(), "{method} {path} lacks {code}");
            }
            assert_eq!(
                r.get("403").is_some(),
                path != "/openapi.json",
                "{method} {path}: 403"
            );
        }
    }
    assert!(doc["paths"]["/live/ticket"]["post"]["responses"]["200"].is_object());
}

/// The schema says what the service accepts (what schemathesis found it did
/// not): option ranges and words, the cursor's form, a non-empty video, a
/// text lens field and no other form fields.
#[tokio::test]
async fn the_schema_states_what_is_accepted() {
    let doc = openapi::spec();
    let post = &doc["paths"]["/stabilize"]["post"];
    let param = |name: &str| {
        post["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap()["schema"]
            .clone()
    };
    assert_eq!(
        param("n_avg"),
        serde_json::json!({"type": "integer", "minimum": 1, "maximum": 64})
    );
    assert_eq!(
        param("mode")["enum"],
        serde_json::json!(["stabilize", "saccade", "lock", "none"])
    );
    assert_eq!(
        param("zoom")["enum"],
        serde_json::json!(["auto", "static", "none"])
    );
    assert_eq!(param("format")["enum"], serde_json::json!(["mp4", "webm"]));
    assert_eq!(
        param("metrics")["enum"],
        serde_json::json!(["true", "false"])
    );
    let fov = param("fov");
    assert_eq!(fov["anyOf"][0]["exclusiveMinimum"], 0.0, "{fov}");
    assert_eq!(fov["anyOf"][0]["maximum"], 179.0, "{fov}");
    assert_eq!(
        fov["anyOf"][1]["enum"],
        serde_json::json!(["auto"]),
        "{fov}"
    );
    assert_eq!(param("margin")["minimum"], 0.0);
    let body = &post["requestBody"]["content"];
    assert_eq!(body["video/*"]["schema"]["minLength"], 1);
    let form = &body["multipart/form-data"]["schema"];
    assert_eq!(form["additionalProperties"], false, "{form}");
    assert_eq!(form["properties"]["lens"]["type"], "string");
    assert!(form["properties"]["lens"].get("format").is_none(), "{form}");
    assert_eq!(form["properties"]["gyro"]["format"], "binary", "{form}");
    let list = doc["paths"]["/jobs"]["get"]["parameters"]
        .as_array()
        .unwrap();
    let cursor = list.iter().find(|p| p["name"] == "cursor").unwrap();
    assert_eq!(cursor["schema"]["pattern"], "^[0-9]{1,19}$");
    // Each stated bound is what the service does: the edges pass, one past fails.
    let dir = tempfile::tempdir().unwrap();
    let app = app(state(dir.path()));
    for (query, ok) in [
        ("n_avg=64", true),
        ("n_avg=65", false),
        ("fov=179", true),
        ("fov=0", false),
    ] {
        let (s, _, j) = call(
            &app,
            Request::post(format!("/stabilize?{query}"))
                .header("content-type", "video/mp4")
                .body(Body::from("not a video"))
                .unwrap(),
        )
        .await;
        // A valid option gets as far as the body (415: not a video).
        let want = if ok {
            StatusCode::UNSUPPORTED_MEDIA_TYPE
        } else {
            StatusCode::BAD_REQUEST
        };
        assert_eq!(s, want, "{query}: {j}");
    }
}

#[test]
fn job_times_are_rfc3339() {
    use std::time::{SystemTime, UNIX_EPOCH};
    let at = |s: u64| jobs::rfc3339(UNIX_EPOCH + Duration::from_secs(s));
    assert_eq!(at(0), "1970-01-01T00:00:00Z");
    assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
    assert_eq!(at(1_795_983_845), "2026-11-29T20:24:05Z");
    assert!(jobs::rfc3339(SystemTime::now()).starts_with("20"));
}

/// A 1 s, 160x90, 30 fps H.264 clip in `dir`.
fn small_clip(dir: &std::path::Path) -> std::path::PathBuf {
    let clip = dir.join("clip.mp4");
    amc_e2e::fixtures::silent_test_clip(&clip, 160, 90, 30, 1.0, &[]);
    clip
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_small_job_runs_to_done_and_its_files_go_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path());
    let st = state(dir.path());
    let app = app(st.clone());
    let (s, _, j) = call(
        &app,
        Request::post("/jobs?fov=60&n_avg=3&rate_a=0.5&rate_b=10&readout_ms=auto")
            .header("content-type", "video/mp4")
            .body(Body::from(std::fs::read(&clip).unwrap()))
            .unwrap(),
    )
    .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{j}");
    let id = j["id"].as_str().unwrap().to_string();
    let mut last = serde_json::Value::Null;
    for _ in 0..600 {
        let (_, _, j) = call(&app, get(&format!("/jobs/{id}"))).await;
        if j["state"] == "done" || j["state"] == "failed" {
            last = j;
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(last["state"], "done", "{last}");
    assert_eq!(last["frames_done"], 30);
    // One flat metrics object and one motion object, each value once.
    let m = &last["metrics"];
    for key in [
        "frames",
        "rms_normal_flow",
        "rms_frame_change",
        "sharpness",
        "valid_fraction",
        "min_valid_fraction",
        "frames_per_second",
        "readout_ms",
    ] {
        assert!(m[key].is_number(), "metrics.{key}: {last}");
    }
    assert!(
        m.get("metrics").is_none() && m.get("motion").is_none(),
        "{last}"
    );
    // readout_ms=auto: the estimate, or 0 with a warning the client sees.
    let warnings = m["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .all(|w| w.as_str().unwrap().contains("readout")),
        "{last}"
    );
    if !warnings.is_empty() {
        assert_eq!(m["readout_ms"], 0.0, "{last}");
    }
    for key in ["rms_speed_est_dps", "rms_speed_view_dps", "saccades"] {
        assert!(last["motion"][key].is_number(), "motion.{key}: {last}");
        assert!(m.get(key).is_none(), "{key} twice: {last}");
    }
    // The listing shows it.
    let (s, _, list) = call(&app, get("/jobs?limit=5")).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(list["jobs"][0]["id"], id.as_str(), "{list}");
    assert_eq!(list["jobs"][0]["state"], "done");
    assert_eq!(list["jobs"][0]["progress"], 1.0);
    assert!(list["jobs"][0]["created"].as_str().unwrap().ends_with('Z'));
    assert!(
        st.disk.used() > 0,
        "the output is counted against the disk budget"
    );
    let (s, _, _) = call(&app, delete(&format!("/jobs/{id}"))).await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    assert_eq!(st.disk.used(), 0);
    let left: Vec<_> = std::fs::read_dir(dir.path().join("work"))
        .unwrap()
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

/// A panic in a worker (the test-only trigger) costs that request or job
/// only: `POST /stabilize` answers 500 problem+json, a job fails with the
/// reason, nothing is left on disk, and the next clip goes through.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_panicking_worker_fails_its_request_and_the_service_carries_on() {
    use std::sync::atomic::Ordering;
    let dir = tempfile::tempdir().unwrap();
    let clip = std::fs::read(small_clip(dir.path())).unwrap();
    let st = state(dir.path());
    let app = app(st.clone());
    let post = |path: &str| {
        Request::post(path)
            .header("content-type", "video/mp4")
            .body(Body::from(clip.clone()))
            .unwrap()
    };
    st.panic_in_workers.store(true, Ordering::SeqCst);

    let (s, ctype, j) = call(&app, post("/stabilize?metrics=false")).await;
    assert_eq!(s, StatusCode::INTERNAL_SERVER_ERROR, "{j}");
    assert_eq!(ctype, "application/problem+json");
    assert_eq!(j["status"], 500, "{j}");
    assert_eq!(j["detail"], panics::PANICKED, "{j}");

    let (s, _, j) = call(&app, post("/jobs?metrics=false")).await;
    assert_eq!(s, StatusCode::ACCEPTED, "{j}");
    let id = j["id"].as_str().unwrap().to_string();
    let mut last = serde_json::Value::Null;
    for _ in 0..600 {
        let (_, _, j) = call(&app, get(&format!("/jobs/{id}"))).await;
        if j["state"] != "queued" && j["state"] != "running" {
            last = j;
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(last["state"], "failed", "{last}");
    assert_eq!(last["error"], panics::PANICKED, "{last}");
    let (s, ctype, _) = call(&app, get(&format!("/jobs/{id}/output"))).await;
    assert_eq!(s, StatusCode::CONFLICT);
    assert_eq!(ctype, "application/problem+json");

    // The service carries on.
    st.panic_in_workers.store(false, Ordering::SeqCst);
    let (s, _, j) = call(&app, get("/healthz")).await;
    assert_eq!(s, StatusCode::OK, "{j}");
    // (readout_ms=auto: the estimate's first pass, then the run.)
    let (s, _, _) = call(&app, post("/stabilize?metrics=false&readout_ms=auto")).await;
    assert_eq!(s, StatusCode::OK);
    let (s, _, _) = call(&app, delete(&format!("/jobs/{id}"))).await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    // Nothing of the three requests is left on disk.
    for _ in 0..100 {
        if std::fs::read_dir(dir.path().join("work")).unwrap().count() == 0 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let left: Vec<_> = std::fs::read_dir(dir.path().join("work"))
        .unwrap()
        .collect();
    assert!(left.is_empty(), "{left:?}");
    assert_eq!(st.disk.used(), 0);
}

/// A panic in a handler is answered with a 500 problem+json by the router's
/// catch-panic layer (the connection is not just dropped).
#[tokio::test]
async fn a_panicking_handler_is_answered_with_problem_json() {
    let res = panics::panic_response(Box::new("boom"));
    assert_eq!(res.status(), StatusCode::INTERNAL_SERVER_ERROR);
    let app: Router = Router::new()
        .route(
            "/boom",
            axum::routing::get(|| async {
                if std::hint::black_box(true) {
                    panic!("test-only trigger: a handler panicked");
                }
                "unreachable"
            }),
        )
        .layer(tower_http::catch_panic::CatchPanicLayer::custom(
            panics::panic_response,
        ));
    let (s, ctype, j) = call(&app, get("/boom")).await;
    assert_eq!(s, StatusCode::INTERNAL_SERVER_ERROR);
    assert_eq!(ctype, "application/problem+json");
    assert_eq!(j["detail"], panics::PANICKED, "{j}");
}
