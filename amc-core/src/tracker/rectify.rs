//! Rolling shutter: template rays rectified into the template frame's
//! mid-readout camera.

use super::irls::CHUNK;
use super::landing::{path_at, rotate_small, row_times_into};
use super::state::LevelTemplate;
use super::Tracker;
use crate::image::GrayImage;
use crate::shutter::{IntraFrame, RowTime};

impl Tracker {
    /// Rectifies the current template again (every level), with `path` as
    /// its own readout path from now on. No effect with a global shutter.
    pub(super) fn rectify_template_again(&mut self, path: IntraFrame) {
        let Some(rows) = &self.rolling else { return };
        self.tpl_path = path;
        for (level, tpl) in self.template.iter_mut().enumerate() {
            rectify_template(tpl, rows, self.row_tables.get(level), level, &path);
        }
    }
}

/// Rolling shutter: turns each template ray into the template frame's
/// mid-readout camera, `y = exp(a(s)) x` for the readout fraction `s` of its
/// row (`a(s)` of the template frame's readout path), in `xs, ys, zs`.
/// The rays come from the points' pixels, so a template can be rectified
/// again with another path.
pub(super) fn rectify_template(
    tpl: &mut LevelTemplate,
    rows: &RowTime,
    table: Option<&GrayImage>,
    level: usize,
    intra: &IntraFrame,
) {
    let Some(k) = tpl.k else {
        tpl.zs.clear();
        return;
    };
    let n = tpl.xs.len();
    tpl.zs.resize(n, 0.0);
    let w = tpl.width.max(1) as f64;
    let path = intra.terms().map(|t| [t.x as f32, t.y as f32, t.z as f32]);
    let (mut pu, mut pv, mut ps) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
    // In chunks, each pass a loop that vectorizes (a point at a time, with
    // an integer division for its pixel and the path in f64, this was as
    // costly as a tenth of the frames' tracking).
    for lo in (0..n).step_by(CHUNK) {
        let len = (n - lo).min(CHUNK);
        let loc = &tpl.loc[lo..][..len];
        for q in 0..len {
            // Exact: `loc < 2^32` and `w` are exact in f64, and the half
            // keeps the quotient off the integers.
            let v = ((loc[q] as f64 + 0.5) / w).floor();
            pv[q] = v as f32;
            pu[q] = (loc[q] as f64 - v * w) as f32;
        }
        row_times_into(rows, table, level, &pu[..len], &pv[..len], &mut ps[..len]);
        let (xs, ys, zs) = (
            &mut tpl.xs[lo..][..len],
            &mut tpl.ys[lo..][..len],
            &mut tpl.zs[lo..][..len],
        );
        for q in 0..len {
            let (x, y) = k.ray(pu[q], pv[q]);
            let s = ps[q];
            let ray = rotate_small(&path_at(&path, s), &[x, y, 1.0]);
            // A pixel whose ray leaves the sensor's lens (NaN `s`) keeps its ray.
            let ok = s.is_finite();
            xs[q] = if ok { ray[0] } else { x };
            ys[q] = if ok { ray[1] } else { y };
            zs[q] = if ok { ray[2] } else { 1.0 };
        }
    }
}
