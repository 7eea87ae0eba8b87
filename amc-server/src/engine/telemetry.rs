//! The telemetry CSV: one row per output frame.

use amc_core::Telemetry;

/// Header of the telemetry CSV. The first eight columns are a stable contract:
/// the rotation vectors (radians) of the estimated `R_{0,j}` and of the view.
pub const TELEMETRY_HEADER: &str = "frame,t,rx,ry,rz,vx,vy,vz,est_speed_dps,view_speed_dps,valid_fraction,frames_averaged,saccade,iterations,rms_residual,track_valid_fraction,lost,template_reset,zoom,uncovered";

/// One row of the CSV, with its newline.
pub(crate) fn row(t: &Telemetry) -> String {
    let speed = |v: [f64; 3]| {
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            .sqrt()
            .to_degrees()
    };
    format!(
        "{},{:.6},{:e},{:e},{:e},{:e},{:e},{:e},{:.4},{:.4},{:.5},{},{},{},{:.6},{:.4},{},{},{:.5},{}\n",
        t.frame,
        t.t,
        t.r_est[0],
        t.r_est[1],
        t.r_est[2],
        t.r_view[0],
        t.r_view[1],
        t.r_view[2],
        speed(t.rate_est),
        speed(t.rate_view),
        t.valid_fraction,
        t.frames_averaged,
        t.saccade as u8,
        t.track.iterations,
        t.track.rms_residual,
        t.track.valid_fraction,
        t.track.lost as u8,
        t.track.template_reset as u8,
        t.zoom,
        t.uncovered,
    )
}
