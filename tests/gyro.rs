//! Real footage with a gyroscope: the cc9 frames' estimated frame-to-frame rotations against
//! the integrated gyro (see ../shared/data/README.md for the axis mapping and time offset).

use amc_e2e::*;

/// Gyro time offset: subtract from the gyro timestamps to align them with framestamp.txt.
const GYRO_OFFSET_S: f64 = 0.022;
const SUBSTEPS: usize = 50;

struct Gyro {
    t: Vec<f64>,
    w: Vec<[f64; 3]>,
}

impl Gyro {
    fn load() -> Gyro {
        let text = std::fs::read_to_string(data("cc9/gyro.txt")).unwrap();
        let mut t = Vec::new();
        let mut w = Vec::new();
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let v: Vec<f64> = line.split(',').map(|x| x.trim().parse().unwrap()).collect();
            assert_eq!(v.len(), 4, "gyro line {line:?}");
            // Columns wx,wy,wz,t; body rate in camera axes is (-wy, -wx, -wz).
            t.push(v[3] - GYRO_OFFSET_S);
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

#[test]
fn cc9_gyro_agreement() {
    let frames_dir = data("cc9/frames");
    let lens = data("cc9/lens.json");
    let stamps: Vec<f64> = std::fs::read_to_string(data("cc9/framestamp.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.trim().parse().unwrap())
        .collect();
    let gyro = Gyro::load();

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
    ]);
    let est = rotations(&Csv::read(&tel), "rx", "ry", "rz");
    let n = est.len();
    assert_eq!(
        n, 103,
        "expected 103 frames (RE_frame-99..201) in the telemetry, got {n}"
    );

    let mut err = Vec::new();
    let mut motion = Vec::new();
    for j in 1..n {
        let (ta, tb) = (stamps[99 + j - 1], stamps[99 + j]);
        let g = gyro.integrate(ta, tb);
        let e = rel(&est[&(j - 1)], &est[&j]);
        err.push(angle_between_deg(&g, &e));
        motion.push(angle_deg(&g));
    }
    let nonfinite = err.iter().filter(|x| !x.is_finite()).count();
    let fe = finite(&err);
    let mean_err = mean(&fe);
    eprintln!(
        "[cc9] {} frame pairs: gyro vs estimate error mean {:.4} deg, median {:.4} deg, max {:.4} deg \
         (non-finite: {nonfinite}); mean gyro motion {:.4} deg/frame",
        err.len(),
        mean_err,
        median(&fe),
        max(&fe),
        mean(&motion)
    );
    eprintln!("[cc9] ==> MEAN ERROR {mean_err:.4} deg per frame (bar < 0.15, goal < 0.1) <==");
    assert_eq!(
        nonfinite, 0,
        "{nonfinite} frame pairs have non-finite estimates"
    );
    assert!(
        mean_err < 0.15,
        "mean gyro disagreement {mean_err:.4} deg >= 0.15 deg"
    );
}
