//! The router driven in process (no socket): routing, errors, a small job.

use super::*;
use axum::body::{to_bytes, Body};
use axum::http::Request;
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

    let (s, _, _) = call(&app, get("/jobs/abc")).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    let (s, ctype, _) = call(&app, get("/nothing/here")).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    assert_eq!(ctype, "application/problem+json");
    let (s, _, _) = call(&app, get("/jobs")).await;
    assert_eq!(s, StatusCode::METHOD_NOT_ALLOWED);
    let (s, ctype, _) = call(&app, get("/")).await;
    assert_eq!(s, StatusCode::OK);
    assert!(ctype.starts_with("text/html"));
    let (s, _, doc) = call(&app, get("/openapi.json")).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(doc["paths"].as_object().unwrap().len(), 10);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_small_job_runs_to_done_and_its_files_go_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("clip.mp4");
    let ok = std::process::Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-f",
            "lavfi",
            "-i",
            "testsrc2=size=160x90:rate=30",
            "-t",
            "1",
        ])
        .args([
            "-c:v",
            "libx264",
            "-preset",
            "ultrafast",
            "-pix_fmt",
            "yuv420p",
        ])
        .arg(&clip)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    assert!(ok, "ffmpeg could not make a test clip");
    let st = state(dir.path());
    let app = app(st.clone());
    let (s, _, j) = call(
        &app,
        Request::post("/jobs?fov=60&n_avg=3")
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
    assert!(
        st.disk.used() > 0,
        "the output is counted against the disk budget"
    );
    let res = app
        .clone()
        .oneshot(
            Request::delete(format!("/jobs/{id}"))
                .body(Body::empty())
                .unwrap(),
        )
        .await
        .unwrap();
    assert_eq!(res.status(), StatusCode::NO_CONTENT);
    assert_eq!(st.disk.used(), 0);
    let left: Vec<_> = std::fs::read_dir(dir.path().join("work"))
        .unwrap()
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
