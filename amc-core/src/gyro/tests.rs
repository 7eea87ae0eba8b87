//! Recovery of a known offset, mounting, bias and drift from a simulated log.

use super::*;
use crate::readout::MeasuredReadout;
use crate::so3::{exp, Rot, Tangent};
use nalgebra::Vector3;

/// A smooth shake: body angular velocity (camera axes, rad/s) at `t`, about
/// `dps` deg/s RMS, several incommensurate frequencies on each axis.
fn omega(t: f64, dps: f64) -> Vector3<f64> {
    let a = dps.to_radians() / 1.2;
    let f = |k: f64, p: f64| (2.0 * std::f64::consts::PI * k * t + p).sin();
    Vector3::new(
        a * (0.8 * f(3.13, 0.0) + 0.5 * f(7.37, 1.0) + 0.3 * f(13.71, 2.0)),
        a * (0.7 * f(2.29, 0.5) + 0.6 * f(9.17, 1.5) + 0.3 * f(17.93, 0.2)),
        a * (0.5 * f(1.71, 0.9) + 0.4 * f(5.93, 2.5) + 0.2 * f(11.37, 1.1)),
    )
}

/// The camera's steps at `fps` for `seconds`.
fn video(fps: f64, seconds: f64, dps: f64) -> Vec<VisionStep> {
    let (ts, rs) = orientations(fps, seconds, dps);
    VisionStep::from_orientations(&ts, &rs)
}

/// The camera's orientations at `fps` for `seconds`, integrated finely.
fn orientations(fps: f64, seconds: f64, dps: f64) -> (Vec<f64>, Vec<Rot>) {
    let n = (fps * seconds) as usize;
    let sub = 40;
    let mut r = Rot::identity();
    let (mut ts, mut rs) = (vec![0.0], vec![r]);
    for j in 1..=n {
        for k in 0..sub {
            let dt = 1.0 / fps / sub as f64;
            let t = (j - 1) as f64 / fps + (k as f64 + 0.5) * dt;
            r *= exp(&(omega(t, dps) * dt));
        }
        ts.push(j as f64 / fps);
        rs.push(r);
    }
    (ts, rs)
}

struct LogSpec {
    offset: f64,
    mount: Rot,
    bias: Vector3<f64>,
    rate: f64,
    noise: f64,
    /// Log seconds before the video starts and after it ends.
    before: f64,
    after: f64,
    drift_ppm: f64,
    /// A spike of this many rad/s on x over `glitch.1..glitch.1 + glitch.2` (video time).
    glitch: Option<(f64, f64, f64)>,
}

/// The log of the motion of [`video`]: log time = (video time - offset) /
/// (1 + drift), IMU axes, bias, deterministic "noise".
fn log(spec: &LogSpec, seconds: f64, dps: f64) -> GyroSamples {
    let mut out = GyroSamples::default();
    let n = ((seconds + spec.before + spec.after) * spec.rate) as usize;
    let mut seed = 12345u64;
    let mut noise = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0 * 3f64.sqrt()
    };
    for i in 0..n {
        let video_t = -spec.before + i as f64 / spec.rate;
        let log_t = (video_t - spec.offset) / (1.0 + spec.drift_ppm * 1e-6);
        let mut w = spec.mount.transpose() * omega(video_t, dps) + spec.bias;
        w += Vector3::new(noise(), noise(), noise()) * spec.noise;
        if let Some((amp, from, len)) = spec.glitch {
            if (from..from + len).contains(&video_t) {
                w.x += amp;
            }
        }
        out.t.push(log_t);
        out.w.push(w);
    }
    out
}

fn spec() -> LogSpec {
    LogSpec {
        offset: 3.2731,
        // An FPV camera tilted up 30 deg about x, turned a little.
        mount: exp(&Vector3::new(30f64.to_radians(), 0.05, -0.08)),
        bias: Vector3::new(0.01, -0.02, 0.005),
        rate: 1000.0,
        noise: 0.01,
        before: 5.0,
        after: 2.0,
        drift_ppm: 0.0,
        glitch: None,
    }
}

fn angle_deg(a: &Rot, b: &Rot) -> f64 {
    crate::so3::log(&(a.transpose() * b)).norm().to_degrees()
}

#[test]
fn offset_mounting_and_bias_come_back() {
    for dps in [100.0, 300.0] {
        let s = spec();
        let steps = video(60.0, 8.0, dps);
        let got = sync(&log(&s, 8.0, dps), &steps).unwrap();
        let err_ms = (got.offset_s - s.offset) * 1e3;
        let mount_deg = angle_deg(&got.mount, &s.mount);
        assert!(
            err_ms.abs() < 0.5,
            "{dps} deg/s: offset off by {err_ms:.3} ms"
        );
        assert!(
            mount_deg < 0.3,
            "{dps} deg/s: mounting off by {mount_deg:.3} deg"
        );
        assert!((got.bias - s.bias).norm() < 0.003, "bias {:?}", got.bias);
        assert!(got.correlation > 0.9, "{}", got.correlation);
        assert_eq!(got.glitches, 0);
    }
}

#[test]
fn a_glitch_is_found_and_left_out() {
    let mut s = spec();
    s.glitch = Some((8.0, 4.0, 0.02));
    let steps = video(60.0, 8.0, 200.0);
    let got = sync(&log(&s, 8.0, 200.0), &steps).unwrap();
    assert!((got.offset_s - s.offset).abs() < 0.0005, "{}", got.offset_s);
    assert!(angle_deg(&got.mount, &s.mount) < 0.3);
    assert!((1..=4).contains(&got.glitches), "{} glitches", got.glitches);
}

#[test]
fn the_drift_of_the_clocks_comes_back() {
    let mut s = spec();
    s.drift_ppm = 400.0;
    let steps = video(60.0, 20.0, 150.0);
    let got = sync(&log(&s, 20.0, 150.0), &steps).unwrap();
    assert!(
        (got.drift_ppm - 400.0).abs() < 60.0,
        "{} ppm",
        got.drift_ppm
    );
    // At the clip's first frame (video time 0, log time -offset / (1 + drift)),
    // video time = log time + offset / (1 + drift).
    let at_start = s.offset / (1.0 + s.drift_ppm * 1e-6);
    assert!(
        (got.offset_s - at_start).abs() < 0.0005,
        "{} against {at_start}",
        got.offset_s
    );
}

#[test]
fn a_log_of_other_motion_is_refused() {
    let s = spec();
    let steps = video(60.0, 8.0, 200.0);
    let mut other = log(&s, 8.0, 200.0);
    // Another clip's log: motion of the same kind, at other frequencies.
    other.w = other
        .t
        .iter()
        .map(|&t| omega(2.3 * t + 40.0, 200.0))
        .collect();
    assert!(matches!(
        sync(&other, &steps),
        Err(GyroError::NoMatch { .. })
    ));
    let short = GyroSamples {
        t: other.t[..1000].to_vec(),
        w: other.w[..1000].to_vec(),
    };
    assert!(matches!(
        sync(&short, &steps),
        Err(GyroError::LogTooShort { .. })
    ));
}

/// A 300 deg/s clip's truth, vision's jittered poses (0.03 deg per axis,
/// frames 200-202 lost) and a 1 kHz log with a 20 ms spike at 3 s.
struct FusionCase {
    ts: Vec<f64>,
    truth: Vec<Rot>,
    vision: Vec<VisionPose>,
    gyro: GyroSamples,
}

fn fusion_case() -> FusionCase {
    let (fps, seconds, dps) = (60.0, 6.0, 300.0);
    let (ts, truth) = orientations(fps, seconds, dps);
    let mut seed = 99u64;
    let mut jitter = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 12f64.sqrt() * 0.03f64.to_radians()
    };
    let mut vision: Vec<VisionPose> = ts
        .iter()
        .zip(&truth)
        .map(|(&t, r)| VisionPose {
            t,
            pose: r * exp(&Vector3::new(jitter(), jitter(), jitter())),
            lost: false,
        })
        .collect();
    for j in [200, 201, 202] {
        vision[j].pose = exp(&Vector3::new(0.3, -0.2, 0.1));
        vision[j].lost = true;
    }
    let mut s = spec();
    s.glitch = Some((6.0, 3.0, 0.02));
    let gyro = log(&s, seconds, dps);
    FusionCase {
        ts,
        truth,
        vision,
        gyro,
    }
}

/// The per-step angle between the truth and `poses`, degrees.
fn step_errors(truth: &[Rot], poses: &[Rot], skip: std::ops::RangeInclusive<usize>) -> Vec<f64> {
    (1..truth.len())
        .filter(|j| !skip.contains(j))
        .map(|j| {
            angle_deg(
                &(truth[j - 1].transpose() * truth[j]),
                &(poses[j - 1].transpose() * poses[j]),
            )
        })
        .collect()
}

/// Online fusion, frame by frame: each pose depends only on the frames up to
/// it; the steps are finer than vision's, the glitch and the lost frames are
/// bridged, and the end does not drift.
#[test]
fn online_fusion_is_causal_beats_vision_and_bridges() {
    let FusionCase {
        ts,
        truth,
        vision,
        gyro,
    } = fusion_case();
    // Synchronized on the first 3 s alone, as a live feed would be.
    let warm = 180;
    let poses: Vec<Rot> = vision[..warm].iter().map(|v| v.pose).collect();
    let sync = sync(&gyro, &VisionStep::from_orientations(&ts[..warm], &poses)).unwrap();
    let track = GyroTrack::new(&gyro, &sync);
    let run = |frames: &[VisionPose], lag: usize| {
        let params = OnlineParams {
            lag,
            ..OnlineParams::default()
        };
        let mut online = OnlineFusion::new(track.clone(), 0.0, params).unwrap();
        let mut out: Vec<FusedPose> = frames.iter().filter_map(|f| online.push(*f)).collect();
        out.extend(std::iter::from_fn(|| online.finish()));
        assert_eq!(out.len(), frames.len());
        (out, online.glitch_intervals(), online.bridged_frames())
    };
    for lag in [0, 30] {
        let (fused, glitches, bridged) = run(&vision, lag);
        // Causal: the first 250 poses are the same when the frames after them change.
        let mut changed = vision.clone();
        for v in &mut changed[250..] {
            v.pose = exp(&Vector3::new(0.1, 0.2, 0.3)) * v.pose;
        }
        let (early, _, _) = run(&changed, lag);
        assert_eq!(&early[..250 - lag], &fused[..250 - lag]);
        assert!(glitches >= 1, "{glitches} glitch intervals");
        assert_eq!(bridged, 3);
        let fused_poses: Vec<Rot> = fused.iter().map(|f| f.pose).collect();
        let seen: Vec<Rot> = vision.iter().map(|v| v.pose).collect();
        let mut f = step_errors(&truth, &fused_poses, 1..=0);
        let mut v = step_errors(&truth, &seen, 200..=203);
        let worst_glitch = f[174..189].iter().copied().fold(0.0, f64::max);
        let worst_lost = f[198..204].iter().copied().fold(0.0, f64::max);
        f.sort_by(f64::total_cmp);
        v.sort_by(f64::total_cmp);
        let (fm, vm) = (f[f.len() / 2], v[v.len() / 2]);
        let end = angle_deg(&truth[ts.len() - 1], &fused_poses[ts.len() - 1]);
        eprintln!("lag {lag}: online {fm:.4} deg per step, vision {vm:.4}, glitch {worst_glitch:.4}, lost {worst_lost:.4}, end {end:.4}");
        assert!(
            fm < 0.5 * vm,
            "lag {lag}: online {fm:.4} deg per step against vision's {vm:.4}"
        );
        assert!(
            worst_glitch < 2.0 * v[v.len() - 1],
            "lag {lag}: {worst_glitch:.4} deg in the glitch"
        );
        assert!(
            worst_lost < 0.05,
            "lag {lag}: {worst_lost:.4} deg where tracking was lost"
        );
        assert!(end < 0.1, "lag {lag}: {end:.4} deg at the end");
    }
}

/// Fusion against the truth: vision jitters (0.03 deg per axis), three
/// frames are lost (their poses garbage), the log has a 20 ms spike of
/// 6 rad/s. The fused steps are several times finer than vision's, the spike
/// is bridged by vision, the lost frames by the gyro, and nothing drifts.
#[test]
fn fusion_beats_vision_bridges_a_glitch_and_lost_frames() {
    let FusionCase {
        ts,
        truth,
        vision,
        gyro,
    } = fusion_case();
    let poses: Vec<Rot> = vision.iter().map(|v| v.pose).collect();
    let got = sync(&gyro, &VisionStep::from_orientations(&ts, &poses)).unwrap();
    let fusion = fuse(
        &GyroTrack::new(&gyro, &got),
        &vision,
        0.0,
        &FuseParams::default(),
    )
    .unwrap();
    assert!(fusion.glitch_intervals >= 1, "{fusion:?}");
    assert_eq!(fusion.bridged_frames, 3);
    let step_err = |p: &dyn Fn(usize) -> Rot, j: usize| {
        angle_deg(
            &(truth[j - 1].transpose() * truth[j]),
            &(p(j - 1).transpose() * p(j)),
        )
    };
    let fused = |j: usize| fusion.frames[j].pose;
    let seen = |j: usize| vision[j].pose;
    let mut f: Vec<f64> = (1..ts.len()).map(|j| step_err(&fused, j)).collect();
    let mut v: Vec<f64> = (1..ts.len())
        .filter(|j| !(200..=203).contains(j))
        .map(|j| step_err(&seen, j))
        .collect();
    let worst_glitch = (175..190).map(|j| step_err(&fused, j)).fold(0.0, f64::max);
    let worst_lost = (199..205).map(|j| step_err(&fused, j)).fold(0.0, f64::max);
    f.sort_by(f64::total_cmp);
    v.sort_by(f64::total_cmp);
    let (fm, vm) = (f[f.len() / 2], v[v.len() / 2]);
    let end = angle_deg(&truth[ts.len() - 1], &fusion.frames[ts.len() - 1].pose);
    assert!(
        fm < 0.35 * vm,
        "fused {fm:.4} deg per step against vision's {vm:.4}"
    );
    assert!(
        worst_glitch < 2.0 * v[v.len() - 1],
        "{worst_glitch:.4} deg in the glitch"
    );
    assert!(
        worst_lost < 0.05,
        "{worst_lost:.4} deg where tracking was lost"
    );
    assert!(end < 0.05, "{end:.4} deg at the end");
}

/// A log on the video's own clock (a camera's per-frame record): at the
/// offset given, the mounting and bias come back; another clip's motion is
/// refused there as the search refuses it.
#[test]
fn a_log_on_the_videos_clock_is_fitted_at_its_offset() {
    let s = spec();
    let steps = video(60.0, 8.0, 200.0);
    let gyro = log(&s, 8.0, 200.0);
    let got = sync_at(&gyro, &steps, s.offset).unwrap();
    assert_eq!(got.offset_s, s.offset);
    assert!(angle_deg(&got.mount, &s.mount) < 0.3);
    assert!((got.bias - s.bias).norm() < 0.003, "bias {:?}", got.bias);
    let other = GyroSamples {
        t: gyro.t.clone(),
        w: gyro
            .t
            .iter()
            .map(|&t| omega(2.3 * t + 40.0, 200.0))
            .collect(),
    };
    assert!(matches!(
        sync_at(&other, &steps, s.offset),
        Err(GyroError::NoMatch { .. })
    ));
}

/// A log that starts after the video (a flight controller armed late)
/// covers part of the clip: synchronized on that part.
#[test]
fn a_log_covering_part_of_the_clip_is_synchronized() {
    let mut s = spec();
    // From 3 s into the 8 s clip to its end.
    s.before = -3.0;
    s.after = 0.0;
    let steps = video(60.0, 8.0, 200.0);
    let got = sync(&log(&s, 8.0, 200.0), &steps).unwrap();
    assert!((got.offset_s - s.offset).abs() < 0.0005, "{}", got.offset_s);
    assert!(angle_deg(&got.mount, &s.mount) < 0.3);
}

/// The rotation of the camera of [`omega`] from `a` to `b` (camera axes of `a`).
fn turn(a: f64, b: f64, dps: f64) -> Tangent {
    let sub = 64;
    let dt = (b - a) / sub as f64;
    let mut r = Rot::identity();
    for k in 0..sub {
        r *= exp(&(omega(a + (k as f64 + 0.5) * dt, dps) * dt));
    }
    crate::so3::log(&r)
}

/// A synchronized track of [`spec`]'s log and the frame times of a 60
/// frames/s clip, `seconds` long.
fn synced(seconds: f64, dps: f64) -> (GyroTrack, Vec<f64>) {
    let s = spec();
    let gyro = log(&s, seconds, dps);
    let got = sync(&gyro, &video(60.0, seconds, dps)).unwrap();
    let times = (0..(60.0 * seconds) as usize)
        .map(|j| j as f64 / 60.0)
        .collect();
    (GyroTrack::new(&gyro, &got), times)
}

/// Deterministic noise in `[-1, 1]`.
fn jitter(i: usize, k: usize) -> f64 {
    (((i * 7919 + k * 104_729) % 1000) as f64 / 500.0) - 1.0
}

#[test]
fn the_readout_is_measured_against_the_log() {
    let dps = 250.0;
    let (track, times) = synced(6.0, dps);
    for readout_ms in [8.0, 20.0] {
        let h = 0.5e-3 * readout_ms;
        let frames: Vec<MeasuredReadout> = times
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                let mut phi = turn(t - h, t + h, dps);
                // The tracker's own error: 10% of the rotation, and a few
                // frames that are nothing like it (a moving object).
                phi += Vector3::new(jitter(i, 0), jitter(i, 1), jitter(i, 2)) * 0.1 * phi.norm();
                if i % 40 == 7 {
                    phi = Vector3::new(0.02, -0.03, 0.01);
                }
                MeasuredReadout { t, phi }
            })
            .collect();
        let got = readout_from_gyro(&track, &frames, 1.0 / 60.0).unwrap();
        assert!(got.confident, "{got:?}");
        assert!(
            (got.readout_ms - readout_ms).abs() < 0.03 * readout_ms,
            "{} ms for {readout_ms} ms",
            got.readout_ms
        );
        assert!(got.explained > 0.9, "{got:?}");
    }
}

#[test]
fn a_global_shutter_reads_as_one_and_a_still_camera_tells_nothing() {
    let dps = 250.0;
    let (track, times) = synced(6.0, dps);
    // Only the tracker's noise within frames, while the camera turns.
    let frames: Vec<MeasuredReadout> = times
        .iter()
        .enumerate()
        .map(|(i, &t)| MeasuredReadout {
            t,
            phi: Vector3::new(jitter(i, 0), jitter(i, 1), jitter(i, 2)) * 1e-4,
        })
        .collect();
    let got = readout_from_gyro(&track, &frames, 1.0 / 60.0).unwrap();
    assert_eq!(got.readout_ms, 0.0, "{got:?}");
    assert!(got.confident, "{got:?}");
    // A camera that barely moves pins nothing down (its log, synced by
    // hand: the picture could not sync it).
    let still = 0.05;
    let s = spec();
    let exact = GyroSync {
        offset_s: s.offset,
        t_first: 0.0,
        drift_ppm: 0.0,
        mount: s.mount,
        bias: s.bias,
        glitches: 0,
        residual_rad_s: 0.0,
        correlation: 1.0,
    };
    let track = GyroTrack::new(&log(&s, 6.0, still), &exact);
    let frames: Vec<MeasuredReadout> = times
        .iter()
        .map(|&t| MeasuredReadout {
            t,
            phi: turn(t - 0.005, t + 0.005, still),
        })
        .collect();
    match readout_from_gyro(&track, &frames, 1.0 / 60.0) {
        Some(got) => assert!(!got.confident, "{got:?}"),
        None => {}
    }
    // Too few frames: none.
    assert_eq!(readout_from_gyro(&track, &frames[..5], 1.0 / 60.0), None);
}
