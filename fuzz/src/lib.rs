//! The bodies of the fuzz targets, one function per parser of ours. Each
//! takes arbitrary bytes and must return: any panic, hang or allocation over
//! the documented limits is a bug. Where a parse succeeds, what it produced is
//! used the way the product uses it (a frame read is stabilized, a lens
//! drives a stabilizer) and the invariants a caller relies on are asserted.
//!
//! `fuzz_targets/*.rs` wrap these for libFuzzer (nightly, `fuzz/run.sh`);
//! `tests/fuzz_regressions.rs` includes this file on stable and replays
//! `fuzz/regressions/<target>/*` (every crash found) through the same bodies.

use amc_core::camera::CameraModel;
use amc_core::{Frame, FrameRef, PixelFormat, Stabilizer, StabilizerParams};
use amc_server::serve::fuzzing;
use amc_wasm::args::{self, LensArg};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A private folder for the targets that go through files (kept for the
/// process's life, on tmpfs where there is one; `fuzz/run.sh` and the
/// regression replay remove it when done).
pub fn scratch_root() -> &'static Path {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let base = Path::new("/dev/shm");
        let base = if base.is_dir() {
            base.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("amc-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("fuzz scratch folder");
        dir
    })
}

/// A textured `w x h` frame in `format`, moved by `shift` pixels.
fn pattern(w: usize, h: usize, format: PixelFormat, shift: usize) -> Vec<u8> {
    let len = format.buffer_len(w, h).expect("a small frame");
    (0..len)
        .map(|i| {
            let (x, y) = ((i % w.max(1)) + shift, i / w.max(1));
            ((x * 37) ^ (y * 91)).wrapping_mul(13) as u8
        })
        .collect()
}

/// Runs `params` the way a clip would: a few frames of `w x h` through a
/// stabilizer for `camera`, then the frames held back. Errors are answers;
/// only a panic (or a wrong-sized output) is a failure.
fn run_stabilizer(camera: &CameraModel, w: usize, h: usize, params: StabilizerParams) {
    let frames = (params.render.n_avg + params.view.lookahead + 3).min(24);
    let Ok(mut stab) = Stabilizer::new(camera, w, h, params) else {
        return;
    };
    for j in 0..frames {
        let data = pattern(w, h, PixelFormat::Rgb8, j);
        let frame = FrameRef::new(w, h, PixelFormat::Rgb8, &data).expect("sized frame");
        if let Ok(Some(_)) = stab.push(frame, j as f64 / 30.0) {
            check_output(&stab);
        }
    }
    while stab.finish().is_some() {
        check_output(&stab);
    }
}

fn check_output(stab: &Stabilizer) {
    let out = stab.output();
    assert_eq!(
        Some(out.data.len()),
        out.format.buffer_len(out.width, out.height),
        "output buffer of the wrong length"
    );
}

/// The YUV4MPEG2 reader: a `.y4m` file of these bytes, opened as YUV 4:2:0
/// and as RGB, read frame by frame.
pub fn y4m(data: &[u8]) {
    let path = scratch_root().join("input.y4m");
    std::fs::write(&path, data).expect("write the fuzz input");
    for format in [PixelFormat::Yuv420p, PixelFormat::Rgb8] {
        let opts = amc_video::InputOptions {
            pixel_format: format,
            ..Default::default()
        };
        let Ok(mut source) = amc_video::open_input(&path, &opts) else {
            continue;
        };
        let mut frame = Frame::new(0, 0, format);
        let mut last_t = f64::NEG_INFINITY;
        for _ in 0..16 {
            match source.next_frame(&mut frame) {
                Ok(Some(t)) => {
                    assert!(t > last_t, "timestamps must increase: {t} after {last_t}");
                    last_t = t;
                    let info = source.info();
                    assert_eq!((frame.width, frame.height), (info.width, info.height));
                    assert!(
                        frame.data.len() >= format.buffer_len(frame.width, frame.height).unwrap()
                    );
                }
                Ok(None) | Err(_) => break,
            }
        }
    }
    let _ = std::fs::remove_file(&path);
}

/// Lens files in every format (`parse_lens` tells them apart): a camera that
/// parses must project and unproject, and drive a stabilizer at a small size
/// of its aspect ratio.
pub fn lens(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(camera) = amc_core::lens::parse_lens(text) else {
        return;
    };
    let (w, h) = (camera.width as f64, camera.height as f64);
    for i in 0..=4 {
        for j in 0..=4 {
            let px = nalgebra::Vector2::new(w * i as f64 / 4.0, h * j as f64 / 4.0);
            if let Some(ray) = camera.unproject(&px) {
                let _ = camera.project(&ray);
            }
        }
    }
    let _ = camera.try_hfov_deg();
    let small_h = ((64.0 * h / w).round() as usize).clamp(1, 256);
    run_stabilizer(&camera, 64, small_h, StabilizerParams::default());
}

/// `StabilizerParams` from JSON (the WASM API's and the page's form): what
/// validates must run.
pub fn params_json(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(params) = args::parse_params(text) {
        let camera = CameraModel::pinhole_hfov(64, 48, 60.0).expect("camera");
        run_stabilizer(&camera, 64, 48, params);
    }
}

/// The REST query string of `POST /stabilize` and `POST /jobs`: refusals
/// are 400s, and what is accepted must run.
pub fn params_query(data: &[u8]) {
    let query = String::from_utf8_lossy(data);
    match fuzzing::query_options(&query) {
        Ok(options) => {
            let fov = match options.stabilizer.lens {
                amc_core::LensSpec::Fov(deg) => deg,
                _ => 60.0,
            };
            if let Ok(camera) = CameraModel::pinhole_hfov(64, 48, fov) {
                run_stabilizer(&camera, 64, 48, options.stabilizer.params);
            }
        }
        Err((status, message)) => {
            assert_eq!(status, 400, "a bad query is a 400: {message}");
            assert!(!message.is_empty());
        }
    }
}

/// The upload intake: the first line is the `Content-Type`, the rest the
/// body, sent in chunks whose size the input's length picks. Refusals are
/// 4xx (or 503), never 500, and nothing is left on disk either way.
pub fn multipart(data: &[u8]) {
    let (content_type, body) = match data.iter().position(|&b| b == b'\n') {
        Some(i) => (
            String::from_utf8_lossy(&data[..i]).into_owned(),
            &data[i + 1..],
        ),
        None => ("multipart/form-data; boundary=B".to_string(), data),
    };
    let chunk = 1 + data.len() % 97;
    let chunks: Vec<Vec<u8>> = body.chunks(chunk).map(<[u8]>::to_vec).collect();
    let root = scratch_root().join("uploads");
    std::fs::create_dir_all(&root).expect("uploads folder");
    let max_bytes = 1 << 16;
    match fuzzing::receive_upload(&root, &content_type, chunks, max_bytes) {
        Ok(got) => {
            assert!(got.bytes > 0 && got.bytes <= max_bytes, "{got:?}");
            assert_eq!(got.left_on_disk, 0, "the upload was left on disk");
        }
        Err((status, message)) => {
            assert!(
                (400..500).contains(&status) || status == 503,
                "status {status}: {message}"
            );
        }
    }
    let left = std::fs::read_dir(&root).map(|d| d.count()).unwrap_or(0);
    assert_eq!(left, 0, "a refused upload was left on disk");
}

/// A `/live/ingest` message: decoded within the live feed's limits, then
/// stabilized as the live processor would (a stabilizer for its size).
pub fn ingest_frame(data: &[u8]) {
    let Ok(frame) = fuzzing::ingest_frame(data) else {
        return;
    };
    assert_eq!(frame.data.len(), frame.width * frame.height * 3);
    if frame.width * frame.height <= 1 << 18 {
        if let Ok(camera) = CameraModel::pinhole_hfov(frame.width, frame.height, 60.0) {
            let mut params = StabilizerParams::default();
            params.render.n_avg = 2;
            if let Ok(mut stab) = Stabilizer::new(&camera, frame.width, frame.height, params) {
                for j in 0..3 {
                    let _ = stab.push(frame.as_ref(), j as f64 / 30.0);
                }
            }
        }
    }
}

/// Reads the fuzz input as the arguments of a WASM call.
struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn byte(&mut self) -> u8 {
        let (b, rest) = self.0.split_first().map_or((0, &[][..]), |(b, r)| (*b, r));
        self.0 = rest;
        b
    }

    /// A JS number: usually a small integer (what real calls pass), sometimes any f64.
    fn number(&mut self) -> f64 {
        match self.byte() {
            0 => {
                let mut b = [0u8; 8];
                for x in &mut b {
                    *x = self.byte();
                }
                f64::from_le_bytes(b)
            }
            1 => 16384.0 + f64::from(self.byte()),
            tag => f64::from(tag - 2) + f64::from(self.byte() % 4) * 0.25,
        }
    }

    fn string(&mut self) -> String {
        let n = usize::from(self.byte()).min(self.0.len());
        let (s, rest) = self.0.split_at(n);
        self.0 = rest;
        String::from_utf8_lossy(s).into_owned()
    }
}

/// The WASM API's argument checks: `new Stabilizer(width, height,
/// paramsJson, lens, format)` then `push(data, t)` with buffers of the right
/// or a wrong length and any timestamps. Errors are answers; a panic (a trap
/// in the browser) is the failure.
pub fn wasm_args(data: &[u8]) {
    let mut r = Reader(data);
    let width = r.number();
    let height = r.number();
    let format = match r.byte() % 5 {
        0 => None,
        1 => Some("RGBA".to_string()),
        2 => Some("I420".to_string()),
        3 => Some("NV12".to_string()),
        _ => Some(r.string()),
    };
    let params = match r.byte() % 3 {
        0 => String::new(),
        1 => "{}".to_string(),
        _ => r.string(),
    };
    let text;
    let lens = match r.byte() % 3 {
        0 => LensArg::Fov(r.number()),
        1 => {
            text = r.string();
            LensArg::Text(&text)
        }
        _ => LensArg::Other,
    };
    // Frames of the size a real page sends are a few MB; bigger sizes are
    // checked up to opening (the budget) but not pushed.
    let Ok(mut opened) =
        args::check(width, height, &params, lens, format.as_deref()).and_then(args::Checked::open)
    else {
        return;
    };
    let (w, h, fmt) = (opened.width, opened.height, opened.format);
    let len = fmt.buffer_len(w, h);
    if len > 1 << 20 {
        return;
    }
    let mut planar = Vec::new();
    for _ in 0..usize::from(r.byte() % 8) {
        let wrong = r.byte();
        let n = match wrong % 4 {
            0 => len.saturating_sub(usize::from(wrong)),
            1 => len + usize::from(wrong),
            _ => len,
        };
        let frame = vec![r.byte(); n];
        let t = r.number();
        let result = args::push_frame(
            &mut opened.stabilizer,
            fmt,
            w,
            h,
            &frame,
            t,
            None,
            &mut planar,
        );
        if n != len {
            assert!(
                result.is_err(),
                "a buffer of {n} bytes was taken (frame is {len})"
            );
        }
    }
    while opened.stabilizer.finish().is_some() {}
}

/// A target's body.
pub type Body = fn(&[u8]);

/// Every target by name (`fuzz/run.sh`, the `all` binary, the regression replay).
pub const TARGETS: &[(&str, Body)] = &[
    ("y4m", y4m),
    ("lens", lens),
    ("params_json", params_json),
    ("params_query", params_query),
    ("multipart", multipart),
    ("ingest_frame", ingest_frame),
    ("wasm_args", wasm_args),
];
