//! Real footage with a gyroscope: the cc9 frames' estimated frame-to-frame rotations against
//! the integrated gyro (see ../shared/data/README.md for the axis mapping and time offset);
//! and a readout on real footage that cannot show it (karma.mp4) staying bounded.

use amc_e2e::*;

/// The data README: "once 0.022 s is added to the gyro timestamps" (an
/// earlier version said "subtracted", which was wrong; the scan below finds
/// the best shift either way).
const README_SHIFT_S: f64 = 0.022;
/// Shifts (s) added to the gyro timestamps that the test scans for the best alignment.
const SHIFT_RANGE_S: (f64, f64, f64) = (-0.060, 0.060, 0.002);
const SUBSTEPS: usize = 30;

struct Gyro {
    t: Vec<f64>,
    w: Vec<[f64; 3]>,
}

impl Gyro {
    /// Loads the gyro with `shift` seconds added to its timestamps.
    fn load(shift: f64) -> Gyro {
        let text = std::fs::read_to_string(data("cc9/gyro.txt")).unwrap();
        let mut t = Vec::new();
        let mut w = Vec::new();
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let v: Vec<f64> = line.split(',').map(|x| x.trim().parse().unwrap()).collect();
            assert_eq!(v.len(), 4, "gyro line {line:?}");
            // Columns wx,wy,wz,t; body rate in camera axes is (-wy, -wx, -wz).
            t.push(v[3] + shift);
            w.push([-v[1], -v[0], -v[2]]);
        }
        Gyro { t, w }
    }

    /// Body rate at time `t`, linearly interpolated.
    fn rate(&self, t: f64) -> [f64; 3] {
        let i = self.t.partition_point(|&x| x <= t);
        if i == 0 {
            return self.w[0];
        }
        if i >= self.t.len() {
            return *self.w.last().unwrap();
        }
        let (t0, t1) = (self.t[i - 1], self.t[i]);
        let a = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        let (w0, w1) = (self.w[i - 1], self.w[i]);
        [0, 1, 2].map(|k| w0[k] + a * (w1[k] - w0[k]))
    }

    /// Rotation R_{a}^T R_{b} from integrating the body rate between times `ta` and `tb`.
    fn integrate(&self, ta: f64, tb: f64) -> M3 {
        let dt = (tb - ta) / SUBSTEPS as f64;
        let mut r = I3;
        for k in 0..SUBSTEPS {
            let w = self.rate(ta + (k as f64 + 0.5) * dt);
            r = mul(&r, &exp(w.map(|x| x * dt)));
        }
        r
    }
}

/// The agreement with the gyro: stabilizes cc9 with `--readout-ms readout`
/// and returns the mean error and the gyro shift at the best alignment.
fn agreement(readout: &str) -> (f64, f64) {
    let frames_dir = data("cc9/frames");
    let lens = data("cc9/lens.json");
    let stamps: Vec<f64> = std::fs::read_to_string(data("cc9/framestamp.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.trim().parse().unwrap())
        .collect();
    let tmp = tempfile::tempdir().unwrap();
    let tel = tmp.path().join("telemetry.csv");
    amc_ok(&[
        "stabilize".to_string(),
        s(&frames_dir),
        "-o".into(),
        s(&tmp.path().join("out.y4m")),
        "--lens".into(),
        s(&lens),
        "--fps".into(),
        "30".into(),
        "--telemetry".into(),
        s(&tel),
        "-q".into(),
        "--readout-ms".into(),
        readout.into(),
    ]);
    let est = rotations(&Csv::read(&tel), "rx", "ry", "rz");
    let n = est.len();
    assert_eq!(
        n, 103,
        "expected 103 frames (RE_frame-99..201) in the telemetry, got {n}"
    );

    // Errors for one gyro time shift: per frame pair, and the gyro motion.
    let errors = |shift: f64| -> (Vec<f64>, Vec<f64>) {
        let gyro = Gyro::load(shift);
        let mut err = Vec::new();
        let mut motion = Vec::new();
        for j in 1..n {
            let (ta, tb) = (stamps[99 + j - 1], stamps[99 + j]);
            let g = gyro.integrate(ta, tb);
            let e = rel(&est[&(j - 1)], &est[&j]);
            err.push(angle_between_deg(&g, &e));
            motion.push(angle_deg(&g));
        }
        (err, motion)
    };
    let (readme_err, motion) = errors(README_SHIFT_S);
    let nonfinite = readme_err.iter().filter(|x| !x.is_finite()).count();
    assert_eq!(
        nonfinite, 0,
        "{nonfinite} frame pairs have non-finite estimates"
    );
    let (lo, hi, step) = SHIFT_RANGE_S;
    let mut best = (f64::INFINITY, 0.0, Vec::new());
    let mut shift = lo;
    while shift <= hi + 1e-9 {
        let (e, _) = errors(shift);
        let m = mean(&e);
        if m < best.0 {
            best = (m, shift, e);
        }
        shift += step;
    }
    let (best_mean, best_shift, best_err) = best;
    eprintln!("[cc9] --readout-ms {readout}");
    eprintln!(
        "[cc9] {} frame pairs, mean gyro motion {:.4} deg/frame",
        readme_err.len(),
        mean(&motion)
    );
    eprintln!(
        "[cc9] gyro shifted by the README's {README_SHIFT_S:+.3} s: mean error {:.4} deg, median {:.4}",
        mean(&readme_err),
        median(&readme_err)
    );
    eprintln!(
        "[cc9] best shift {best_shift:+.3} s: mean error {best_mean:.4} deg, median {:.4}, max {:.4}",
        median(&best_err),
        max(&best_err)
    );
    (best_mean, best_shift)
}

#[test]
fn cc9_gyro_agreement() {
    // Measured: the estimates line up with the gyro at a shift of about +0.022 s
    // (the README's; on exact synthetic timing the tracker has no lag), where
    // they agree to ~0.084 deg per frame.
    let (best_mean, best_shift) = agreement("0");
    assert!(
        (best_shift - 0.022).abs() <= 0.02,
        "best gyro alignment at {best_shift:+.3} s, expected about +0.022 s"
    );
    assert!(
        best_mean < 0.1,
        "mean gyro disagreement {best_mean:.4} deg >= 0.1 deg at the best alignment"
    );
}

/// The phone's sensor rolls its shutter (readout about 33 ms, see the data
/// README). With the readout, the mid-readout poses agree better with the
/// gyro. Measured (2026-12-04): mean 0.0581 deg per frame (0.0839 as a global
/// shutter), median 0.043, max 0.38 (0.79). Before the template handover 0.0578
/// (0.0793); 0.0569 with 30 ms and 0.0566 with 36 ms. The error is mostly roll (RMS
/// 0.063 deg per frame against the gyro's 0.064 of roll motion) and mostly in the
/// first 25 frame pairs (0.112 deg against 0.040 after), where the phone turns fastest.
#[test]
fn cc9_gyro_agreement_with_its_rolling_shutter() {
    let (global, _) = agreement("0");
    let (rolling, shift) = agreement("33");
    assert!(
        (shift - 0.022).abs() <= 0.02,
        "best gyro alignment at {shift:+.3} s, expected about +0.022 s"
    );
    assert!(
        rolling < 0.065 && rolling < 0.8 * global,
        "mean gyro disagreement {rolling:.4} deg with a 33 ms readout (global shutter: {global:.4})"
    );
}

/// A readout given for footage whose readout motion is too small to see: a
/// drone flying forward slowly (karma.mp4, ~5 deg/s) with a 10 ms readout
/// (0.15 px of motion across a readout). The readout path absorbed the
/// forward flight's looming, template after template: it grew to 148 deg
/// and the output lost up to 72% of its pixels. Now the path stays near what
/// the rotation rate predicts, and the output is whole. (Here rather than in
/// `regressions.rs`, whose signal test counts the ffmpeg processes reading
/// karma.mp4 and would count this test's.)
#[test]
fn a_readout_on_slow_forward_flight_stays_bounded() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("out.y4m");
    let tel = d.path().join("t.csv");
    amc_ok(&[
        "stabilize".to_string(),
        s(&data("karma/karma.mp4")),
        "-o".into(),
        s(&out),
        "--fov".into(),
        "90".into(),
        "--readout-ms".into(),
        "10".into(),
        "--mode".into(),
        "none".into(),
        "--telemetry".into(),
        s(&tel),
        "-q".into(),
    ]);
    let csv = Csv::read(&tel);
    let (rx, ry, rz) = (
        csv.col("readout_rx"),
        csv.col("readout_ry"),
        csv.col("readout_rz"),
    );
    let across: Vec<f64> = (0..rx.len())
        .map(|j| {
            (rx[j] * rx[j] + ry[j] * ry[j] + rz[j] * rz[j])
                .sqrt()
                .to_degrees()
        })
        .collect();
    let mut sorted = across.clone();
    sorted.sort_by(f64::total_cmp);
    let (median, max) = (sorted[sorted.len() / 2], sorted[sorted.len() - 1]);
    let valid = csv.col("valid_fraction");
    let least = valid.iter().copied().fold(1.0, f64::min);
    eprintln!("[karma, 10 ms] rotation across a readout: median {median:.3} deg, max {max:.3}; least valid share {least:.4}");
    // Measured: median 0.017 deg, max 0.81; every output whole.
    assert!(median < 0.1 && max < 2.0, "median {median} max {max} deg");
    assert!(least > 0.99, "valid share down to {least}");
}
