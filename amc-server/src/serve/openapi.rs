//! `GET /openapi.json`: an OpenAPI 3.1 description of every endpoint.
//! A test checks that every route of [`super::router::app`] is described here.

use super::options::all_options;
use super::stabilize::SUMMARY_HEADERS;
use amc_core::options::Allowed;
use axum::Json;
use serde_json::{json, Map, Value};

fn problem(description: &str) -> Value {
    json!({
        "description": description,
        "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
    })
}

/// The JSON Schema of an option's values (as its query parameter carries them).
fn allowed_schema(allowed: &Allowed) -> Value {
    match *allowed {
        Allowed::Words(words) => json!({"type": "string", "enum": words}),
        Allowed::Integer { min, max } => json!({"type": "integer", "minimum": min, "maximum": max}),
        Allowed::Number {
            min,
            max,
            above_min,
            words,
        } => {
            let mut number = json!({"type": "number", "maximum": max});
            number[if above_min {
                "exclusiveMinimum"
            } else {
                "minimum"
            }] = json!(min);
            if words.is_empty() {
                number
            } else {
                json!({"anyOf": [number, {"type": "string", "enum": words}]})
            }
        }
    }
}

fn query_parameters() -> Vec<Value> {
    all_options()
        .into_iter()
        .map(|(name, help, allowed)| {
            json!({"name": name, "in": "query", "required": false, "description": help,
                   "schema": allowed_schema(&allowed)})
        })
        .collect()
}

fn upload_body() -> Value {
    json!({
        "required": true,
        "description": "The clip: the raw body with a video/* content type, or multipart/form-data with a `video` file, an optional `lens` file (the project's lens JSON, an OpenCV calibration or a Gyroflow profile) and an optional `gyro` log (any format telemetry-parser reads, or a CSV of a time and three rates; used instead of the clip's own track; refused with gyro=off).",
        "content": {
            "video/*": {"schema": {"type": "string", "format": "binary", "minLength": 1}},
            "application/octet-stream": {"schema": {"type": "string", "format": "binary", "minLength": 1}},
            "multipart/form-data": {"schema": {"type": "object", "required": ["video"], "additionalProperties": false, "properties": {
                "video": {"type": "string", "format": "binary", "minLength": 1},
                "lens": {"type": "string", "description": "The lens file's text (UTF-8 JSON or YAML, at most 1 MiB)"},
                "gyro": {"type": "string", "format": "binary", "minLength": 1, "description": "A gyro log for the clip, at most 64 MiB: a camera's file (GoPro, Sony, DJI, Insta360), a flight controller's blackbox (Betaflight, ArduPilot .log), Gyroflow's .gcsv, a phone app's log, or a CSV of a time column and three rates in rad/s. Its file name's extension is kept (telemetry-parser tells some formats by it). Synchronized with the video and fused, as the CLI's --gyro FILE; reported in the job's metrics.gyro"}
            }}}
        }
    })
}

fn upload_errors(responses: &mut Map<String, Value>) {
    responses.insert("400".into(), problem("A bad option (the message names it and the allowed range), an empty body, a broken upload, or an empty `gyro` part"));
    responses.insert(
        "413".into(),
        problem("The upload is over --max-upload-mb, or the `gyro` log over 64 MiB"),
    );
    responses.insert("415".into(), problem("Not a video ffmpeg can decode"));
    responses.insert(
        "422".into(),
        problem("Over the size or duration limits, or not stabilizable; or a `gyro` log that is no gyro log, holds no gyroscope samples, or is sent with gyro=off"),
    );
    responses.insert("503".into(), json!({
        "description": "Saturated: too many clips in flight or the disk budget used up, or (with --queue/--store) the job table's database or the bucket is unreachable; retry after the Retry-After header's seconds",
        "headers": {"Retry-After": {"schema": {"type": "integer"}}},
        "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
    }));
}

/// 503 of the job endpoints when the shared job table or bucket is down.
fn unavailable() -> Value {
    json!({
        "description": "With --queue/--store: the job table's database or the bucket is unreachable; retry after the Retry-After header's seconds",
        "headers": {"Retry-After": {"schema": {"type": "integer"}}},
        "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
    })
}

fn job_state() -> Value {
    json!({"type": "string", "enum": ["queued", "running", "done", "failed", "cancelled"]})
}

fn ticket_parameter() -> Value {
    json!({"name": "ticket", "in": "query", "required": false,
           "description": "A single-use ticket from POST /live/ticket, for browsers (which cannot send the Authorization header on a WebSocket)",
           "schema": {"type": "string"}})
}

fn id_parameter() -> Value {
    json!({"name": "id", "in": "path", "required": true, "description": "Job id: 32 hex digits",
           "schema": {"type": "string", "pattern": "^[0-9a-f]{32}$"}})
}

/// The document.
pub fn spec() -> Value {
    let mut stabilize_ok = Map::new();
    let mut headers: Map<String, Value> = SUMMARY_HEADERS
        .iter()
        .map(|h| (h.to_string(), json!({"schema": {"type": "string"}})))
        .collect();
    headers.insert(
        "x-amc-warning".into(),
        json!({"schema": {"type": "string"}, "description": "What the user should know about the run (fov=auto fell back to 70 deg, readout_ms=auto fell back to 0): one X-Amc-Warning field line per warning, each a whole sentence (which may hold commas); none when there is nothing to say"}),
    );
    stabilize_ok.insert("200".into(), json!({
        "description": "The stabilized video (H.264 MP4 or VP9 WebM, the input's audio kept); the clip's summary metrics in X-Amc-* headers",
        "headers": headers,
        "content": {"video/mp4": {"schema": {"type": "string", "format": "binary"}},
                    "video/webm": {"schema": {"type": "string", "format": "binary"}}}
    }));
    upload_errors(&mut stabilize_ok);
    let mut jobs_created = Map::new();
    jobs_created.insert(
        "202".into(),
        json!({
            "description": "Queued",
            "headers": {"Location": {"schema": {"type": "string"}, "description": "/jobs/{id}"}},
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}
        }),
    );
    upload_errors(&mut jobs_created);
    let not_found = problem("No such job (unknown, expired or removed)");
    let not_done = problem("The job is not done: queued or running (its files come once it is done), or cancelled or failed (it has none, and never will; a failed job's detail says why)");
    let mut doc = json!({
        "openapi": "3.1.0",
        "info": {
            "title": "amc serve",
            "version": env!("CARGO_PKG_VERSION"),
            "description": "Artificial Microsaccade Compensation: rotation-only video stabilization for cameras that shake hard. Errors are application/problem+json."
        },
        "paths": {
            "/stabilize": {"post": {
                "operationId": "stabilizeClip",
                "summary": "Stabilize a clip and stream the result back",
                "parameters": query_parameters(),
                "requestBody": upload_body(),
                "responses": stabilize_ok
            }},
            "/jobs": {
                "post": {
                    "operationId": "createJob",
                    "summary": "Queue a clip as a job",
                    "parameters": query_parameters(),
                    "requestBody": upload_body(),
                    "responses": jobs_created
                },
                "get": {
                    "operationId": "listJobs",
                    "summary": "The jobs the service knows (queued, running and finished until they expire), newest first, one page at a time",
                    "parameters": [
                        {"name": "limit", "in": "query", "required": false, "description": "Jobs per page: 1..=100 (default 20)",
                         "schema": {"type": "integer", "minimum": 1, "maximum": 100, "default": 20}},
                        {"name": "cursor", "in": "query", "required": false, "description": "The next_cursor of the previous page (absent: the newest jobs)",
                         "schema": {"type": "string", "pattern": "^[0-9]{1,19}$"}}
                    ],
                    "responses": {
                        "200": {"description": "One page of jobs", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/JobPage"}}}},
                        "400": problem("A bad limit or cursor, or an unknown parameter"),
                        "503": unavailable()
                    }
                }
            },
            "/jobs/{id}": {
                "get": {
                    "operationId": "getJob",
                    "summary": "A job's state, progress and (when done) metrics",
                    "parameters": [id_parameter()],
                    "responses": {
                        "200": {"description": "The job", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}},
                        "404": not_found,
                        "503": unavailable()
                    }
                },
                "delete": {
                    "operationId": "deleteJob",
                    "summary": "Cancel a queued or running job (its ffmpeg children are killed and files removed), or remove a finished one",
                    "parameters": [id_parameter()],
                    "responses": {
                        "200": {"description": "Cancelled", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Job"}}}},
                        "204": {"description": "Removed with its files"},
                        "404": not_found,
                        "503": unavailable()
                    }
                }
            },
            "/jobs/{id}/output": {"get": {
                "operationId": "getJobOutput",
                "summary": "The stabilized video of a finished job",
                "parameters": [id_parameter()],
                "responses": {
                    "200": {"description": "The video", "content": {"video/mp4": {}, "video/webm": {}}},
                    "404": not_found,
                    "409": not_done,
                    "503": unavailable()
                }
            }},
            "/jobs/{id}/telemetry.csv": {"get": {
                "operationId": "getJobTelemetry",
                "summary": "Per-frame telemetry of a finished job: frame,t,rx,ry,rz,vx,vy,vz,...",
                "parameters": [id_parameter()],
                "responses": {
                    "200": {"description": "CSV", "content": {"text/csv": {}}},
                    "404": not_found,
                    "409": not_done,
                    "503": unavailable()
                }
            }},
            "/live": {"get": {
                "operationId": "watchLive",
                "parameters": [ticket_parameter(), {
                    "name": "codec", "in": "query", "required": false,
                    "description": "What each binary message holds: jpeg (default), one JPEG per frame; h264, one H.264 access unit per frame in Annex-B form, from a keyframe with its SPS and PPS on (the messages concatenated are an H.264 elementary stream), from one encoder shared by every H.264 viewer",
                    "schema": {"type": "string", "enum": ["jpeg", "h264"], "default": "jpeg"}
                }],
                "summary": "WebSocket for viewers of the live feed: per stabilized frame, one binary message (a JPEG, or an H.264 access unit with codec=h264) then one text message (LiveTelemetry JSON, its codec named). Slow viewers skip frames (H.264 viewers to the next keyframe). With no viewer the feed is paused; the first viewer resumes it.",
                "responses": {
                    "101": {"description": "Switching to the WebSocket protocol"},
                    "400": problem("An unknown codec"),
                    "426": problem("Not a WebSocket upgrade request")
                }
            }},
            "/live/ingest": {"get": {
                "operationId": "publishLive",
                "parameters": [ticket_parameter()],
                "summary": "WebSocket for one publisher: each binary message is one JPEG frame, or one H.264 access unit in Annex-B form (told apart by its first bytes), of the feed to stabilize (dropped undecoded while no viewer watches)",
                "responses": {
                    "101": {"description": "Switching to the WebSocket protocol"},
                    "426": problem("Not a WebSocket upgrade request"),
                    "409": problem("Another publisher is connected, or the feed comes from --live-source")
                }
            }},
            "/live/ticket": {"post": {
                "operationId": "createLiveTicket",
                "summary": "A single-use ticket for browsers, which cannot set headers on a WebSocket: it opens /live?ticket=... (with the role view) or /live/ingest?ticket=... (publish) once, within expires_in_s, as the key's tenant and roles",
                "responses": {
                    "200": {"description": "The ticket", "content": {"application/json": {"schema": {
                        "type": "object", "required": ["ticket", "expires_in_s"], "properties": {
                            "ticket": {"type": "string"},
                            "expires_in_s": {"type": "integer"}
                        }}}}}
                }
            }},
            "/healthz": {"get": {
                "operationId": "getHealth",
                "summary": "Health: ffmpeg runs, the work directory is writable, the --live-source (if any) can be opened, and with --queue/--store the database and the bucket answer",
                "responses": {
                    "200": {"description": "Healthy", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Health"}}}},
                    "503": {"description": "Unhealthy: `detail` says why (a live source that cannot be opened is named)", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Health"}}}}
                }
            }},
            "/metrics": {"get": {
                "operationId": "getMetrics",
                "summary": "OpenMetrics or Prometheus text, as asked: jobs by state, queue depth, retries, job durations, frames processed, processing rate, live viewers, frames dropped",
                "responses": {"200": {"description": "Metrics: OpenMetrics 1.0 (application/openmetrics-text; version=1.0.0) when the Accept header prefers it, as Prometheus' does; else Prometheus' text format 0.0.4 (text/plain; version=0.0.4)", "content": {"text/plain": {}, "application/openmetrics-text": {}}}, "503": unavailable()}
            }},
            "/openapi.json": {"get": {
                "operationId": "getOpenApi",
                "summary": "This document",
                "responses": {"200": {"description": "OpenAPI 3.1", "content": {"application/json": {}}}}
            }}
        },
        "security": [{"bearer": []}],
        "components": {
        "securitySchemes": {
            "bearer": {"type": "http", "scheme": "bearer", "description": "An API key from `amc keys new`, where the service runs with --auth-keys (without it, on loopback, none is needed)"},
            "ticket": {"type": "apiKey", "in": "query", "name": "ticket", "description": "A single-use ticket from POST /live/ticket (WebSocket endpoints only)"}
        },
        "schemas": {
            "Problem": {"type": "object", "properties": {
                "type": {"type": "string"}, "title": {"type": "string"},
                "status": {"type": "integer"}, "detail": {"type": "string"}
            }},
            "Job": {"type": "object", "required": ["id", "state", "created", "frames_done"], "properties": {
                "id": {"type": "string"},
                "state": job_state(),
                "created": {"type": "string", "format": "date-time"},
                "frames_done": {"type": "integer"},
                "frames_total": {"type": ["integer", "null"]},
                "progress": {"type": ["number", "null"], "minimum": 0, "maximum": 1},
                "format": {"type": "string", "enum": ["mp4", "webm"]},
                "error": {"type": ["string", "null"], "description": "Why it failed"},
                "metrics": {"oneOf": [{"$ref": "#/components/schemas/JobMetrics"}, {"type": "null"}], "description": "When done"},
                "motion": {"oneOf": [{"$ref": "#/components/schemas/JobMotion"}, {"type": "null"}], "description": "When done"},
                "output": {"type": ["string", "null"], "description": "URL of the video, when done"},
                "telemetry": {"type": ["string", "null"], "description": "URL of the telemetry CSV, when done"}
            }},
            "JobMetrics": {"type": "object", "properties": {
                "frames": {"type": "integer", "description": "Output frames"},
                "input_size": {"type": "array", "items": {"type": "integer"}, "description": "[width, height] of the input"},
                "output_size": {"type": "array", "items": {"type": "integer"}, "description": "[width, height] of the output"},
                "seconds": {"type": "number", "description": "Processing time"},
                "frames_per_second": {"type": "number", "description": "Processing rate"},
                "rms_normal_flow": {"type": ["number", "null"], "description": "RMS normal flow of the output, pixels per frame (null with metrics=false)"},
                "rms_frame_change": {"type": ["number", "null"], "description": "RMS luma change between consecutive outputs, 0..1 (null with metrics=false)"},
                "sharpness": {"type": ["number", "null"], "description": "RMS Sobel gradient magnitude (null with metrics=false)"},
                "valid_fraction": {"type": "number", "description": "Mean share of pixels covered by every averaged frame"},
                "min_valid_fraction": {"type": "number", "description": "Lowest per-frame share of fully covered pixels"},
                "readout_ms": {"type": "number", "minimum": 0, "maximum": 100, "description": "Rolling-shutter readout time used, ms (0 = global shutter): readout_ms, the lens file's, or the estimate of readout_ms=auto"},
                "warnings": {"type": "array", "items": {"type": "string"}, "description": "What the user should know about the run: fov=auto fell back to 70 deg, readout_ms=auto fell back to 0 (the CLI's warnings)"},
                "gyro": {"type": ["object", "null"], "description": "With a `gyro` log sent with the clip, or gyro=auto and a clip that carries its own gyro track: the log's sync and fusion as the CLI's --metrics reports them (source, samples, rate_hz, offset_s, log_time, drift_ppm, mount_rotvec, bias_rad_s, glitches, residual_rad_s, correlation, fused_frames, glitch_intervals_bridged, frames_bridged); null without one"}
            }},
            "JobMotion": {"type": "object", "properties": {
                "rms_speed_est_dps": {"type": "number", "description": "RMS angular speed of the camera (estimated), deg/s"},
                "rms_speed_view_dps": {"type": "number", "description": "RMS angular speed of the view, deg/s"},
                "saccades": {"type": "integer", "description": "Saccades made (saccade mode)"}
            }},
            "JobPage": {"type": "object", "required": ["jobs", "next_cursor"], "properties": {
                "jobs": {"type": "array", "items": {"type": "object", "required": ["id", "state", "created", "frames_done"], "properties": {
                    "id": {"type": "string"},
                    "state": job_state(),
                    "created": {"type": "string", "format": "date-time"},
                    "frames_done": {"type": "integer"},
                    "frames_total": {"type": ["integer", "null"]},
                    "progress": {"type": ["number", "null"], "minimum": 0, "maximum": 1}
                }}},
                "next_cursor": {"type": ["string", "null"], "description": "Pass as cursor for the next page; null on the last"}
            }},
            "Health": {"type": "object", "properties": {
                "status": {"type": "string", "enum": ["ok", "unavailable"]},
                "detail": {"type": ["string", "null"]},
                "version": {"type": "string"},
                "workers": {"type": "integer"},
                "busy": {"type": "integer"},
                "live": {"type": "object", "properties": {
                    "source": {"type": "string"},
                    "state": {"type": "string", "enum": ["running", "paused", "unavailable", "waiting for a publisher"]},
                    "viewers": {"type": "integer"}
                }}
            }},
            "LiveTelemetry": {"type": "object", "properties": {
                "frame": {"type": "integer"}, "t": {"type": "number"},
                "speed_est_dps": {"type": "number"}, "speed_view_dps": {"type": "number"},
                "valid": {"type": "number"}, "saccade": {"type": "boolean"},
                "latency_ms": {"type": "number", "description": "From the source frame's arrival to this message's frame being ready to send (stabilized and encoded), ms"},
                "width": {"type": "integer"}, "height": {"type": "integer"},
                "codec": {"type": "string", "enum": ["jpeg", "h264"], "description": "What the binary message before it holds"},
                "unit": {"type": "integer", "description": "H.264 only: the access unit's number in the encoder's stream; a gap in it (not in frame, which the encoder may leave out when behind) is pictures this viewer skipped"}
            }}
        }}
    });
    // The alias answers exactly as the `.csv` path does.
    let mut alias = doc["paths"]["/jobs/{id}/telemetry.csv"].clone();
    alias["get"]["operationId"] = "getJobTelemetryAlias".into();
    alias["get"]["summary"] = "The same as /jobs/{id}/telemetry.csv".into();
    doc["paths"]["/jobs/{id}/telemetry"] = alias;
    declare_access(&mut doc);
    doc
}

/// The answers of the access check on every operation but `/healthz`
/// (which needs no key): 401, 403 (a key without the role; a WebSocket
/// from another site's page) and 429 (failed keys, a key's rate, a tenant's
/// jobs). The WebSocket endpoints take a ticket as well as a key.
fn declare_access(doc: &mut Value) {
    let Some(paths) = doc.get_mut("paths").and_then(Value::as_object_mut) else {
        return;
    };
    for (path, item) in paths.iter_mut() {
        let Some(ops) = item.as_object_mut() else {
            continue;
        };
        for op in ops.values_mut() {
            if path == "/healthz" {
                op["security"] = json!([]);
                continue;
            }
            if path == "/live" || path == "/live/ingest" {
                op["security"] = json!([{"bearer": []}, {"ticket": []}]);
            }
            let Some(responses) = op.get_mut("responses").and_then(Value::as_object_mut) else {
                continue;
            };
            responses.insert(
                "401".into(),
                json!({
                    "description": "No key, or a wrong key or ticket (with --auth-keys)",
                    "headers": {"WWW-Authenticate": {"schema": {"type": "string"}, "description": "Bearer realm=\"amc\""}},
                    "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
                }),
            );
            if path != "/openapi.json" {
                responses.insert(
                    "403".into(),
                    problem("The key lacks the role this endpoint needs (the detail names it), or a WebSocket upgrade from another site's page"),
                );
            }
            responses.insert(
                "429".into(),
                json!({
                    "description": "Too many wrong keys from this address (--auth-failures), this key over --key-rate, or its tenant at --max-jobs-per-tenant",
                    "headers": {"Retry-After": {"schema": {"type": "integer"}, "description": "Seconds to wait"}},
                    "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
                }),
            );
        }
    }
}

pub async fn document() -> Json<Value> {
    Json(spec())
}
