//! The telemetry CSV: one row per output frame.

use amc_core::Telemetry;

/// Header of the telemetry CSV. The first eight columns are a stable contract:
/// the rotation vectors (radians) of the estimated `R_{0,j}` (the mid-readout
/// pose with a rolling shutter) and of the view. New columns go at the end:
/// the last three are the camera's rotation across the frame's readout
/// (`readout_rotation`, radians; zero with a global shutter).
pub const TELEMETRY_HEADER: &str = "frame,t,rx,ry,rz,vx,vy,vz,est_speed_dps,view_speed_dps,valid_fraction,frames_averaged,saccade,iterations,rms_residual,track_valid_fraction,lost,template_reset,zoom,uncovered,readout_rx,readout_ry,readout_rz";

/// One row of the CSV, with its newline.
pub(crate) fn row(t: &Telemetry) -> String {
    let speed = |v: [f64; 3]| {
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            .sqrt()
            .to_degrees()
    };
    format!(
        "{},{:.6},{:e},{:e},{:e},{:e},{:e},{:e},{:.4},{:.4},{:.5},{},{},{},{:.6},{:.4},{},{},{:.5},{},{:e},{:e},{:e}\n",
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
        t.readout_rotation[0],
        t.readout_rotation[1],
        t.readout_rotation[2],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stable columns first; the readout rotation last, one value per column.
    #[test]
    fn readout_columns_come_last() {
        assert!(TELEMETRY_HEADER.starts_with("frame,t,rx,ry,rz,vx,vy,vz,"));
        assert!(TELEMETRY_HEADER.ends_with(",zoom,uncovered,readout_rx,readout_ry,readout_rz"));
        let t = Telemetry {
            readout_rotation: [0.25, -0.5, 0.125],
            ..Telemetry::default()
        };
        let line = row(&t);
        let cells: Vec<&str> = line.trim_end().split(',').collect();
        assert_eq!(cells.len(), TELEMETRY_HEADER.split(',').count(), "{line}");
        let last: Vec<f64> = cells[cells.len() - 3..]
            .iter()
            .map(|c| c.parse().unwrap())
            .collect();
        assert_eq!(last, [0.25, -0.5, 0.125]);
    }
}
