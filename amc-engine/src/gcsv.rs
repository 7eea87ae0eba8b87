//! `--export-gcsv`: a run's motion as Gyroflow's `.gcsv`, so that a clip
//! with no log of its own can be finished in Gyroflow (or read back here
//! with `--gyro`). One sample per frame interval, at its middle, of the
//! camera's body rate over it (`log(R_{0,j-1}^T R_{0,j}) / dt`, rad/s, the
//! camera's axes: x right, y down, z forward), in video time (offset 0),
//! with the readout as `frame_readout_time`.

use super::FrameRecord;
use std::fmt::Write as _;

/// The `.gcsv` text of a run's `frames` (in order), read out over `readout_ms`.
pub fn gcsv(frames: &[FrameRecord], readout_ms: f64) -> String {
    let mut out = String::from(
        "GYROFLOW IMU LOG\nversion,1.3\nid,amc\nvendor,amc\norientation,XYZ\n\
         note,camera motion estimated from the video by amc (camera axes: x right y down z forward)\n",
    );
    if readout_ms > 0.0 {
        let _ = writeln!(out, "frame_readout_time,{readout_ms}");
    }
    out.push_str("tscale,1\ngscale,1\nt,gx,gy,gz\n");
    for pair in frames.windows(2) {
        let t = 0.5 * (pair[0].telemetry.t + pair[1].telemetry.t);
        let w = pair[1].telemetry.rate_est;
        let _ = writeln!(out, "{t:.6},{:.7},{:.7},{:.7}", w[0], w[1], w[2]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample per interval, at its middle, with the later frame's rate.
    #[test]
    fn one_sample_per_frame_interval() {
        let frames: Vec<FrameRecord> = (0..3)
            .map(|j| FrameRecord {
                telemetry: amc_core::Telemetry {
                    t: j as f64 * 0.5,
                    rate_est: [j as f64, -1.0, 0.25],
                    ..amc_core::Telemetry::default()
                },
                metrics: Default::default(),
            })
            .collect();
        let text = gcsv(&frames, 12.5);
        assert!(text.starts_with("GYROFLOW IMU LOG\n"));
        assert!(text.contains("frame_readout_time,12.5\n"));
        let rows: Vec<&str> = text
            .lines()
            .skip_while(|l| *l != "t,gx,gy,gz")
            .skip(1)
            .collect();
        assert_eq!(
            rows,
            [
                "0.250000,1.0000000,-1.0000000,0.2500000",
                "0.750000,2.0000000,-1.0000000,0.2500000"
            ]
        );
    }
}
