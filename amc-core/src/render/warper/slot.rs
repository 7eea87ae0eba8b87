//! One frame warped alone: the scalar reference ([`Warper::warp`]) and the
//! saccade slots, interleaved or one plane.

use super::buffers::RowMap;
use super::downsample::box_down_slot;
use super::supersample::Target;
use super::Warper;
use crate::image::FrameRef;
use crate::render::accumulator::WarpedFrame;
use crate::render::kernels::Geometry;
use crate::shutter::RollingProjector;
use nalgebra::Matrix3;

impl Warper {
    /// Warps `frame` by `m` (output ray -> source ray) and calls
    /// `f(pixel_index, [r, g, b])` with 8.8 fixed-point samples for every
    /// pixel of the render grid ([`Warper::render_size`]: the output's, or the
    /// supersampled one) whose ray lands inside the source frame. Scalar: the
    /// reference the vectorized paths are tested against.
    pub fn warp<F: FnMut(usize, [u32; 3])>(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        mut f: F,
    ) {
        if frame.width < 2 || frame.height < 2 {
            return;
        }
        let geom = Geometry::of(frame).with_cubic(self.cubic());
        let (ow, oh) = (self.out.width, self.out.height);
        let mut map = RowMap::default();
        let global = RollingProjector::default();
        self.prepare_map(&mut map, m, self.rows.first().unwrap_or(&global), None);
        let (mut xs, mut ys) = (vec![0f32; ow], vec![0f32; ow]);
        for v in 0..oh {
            self.fill_row(&map, v, &mut xs, &mut ys);
            for (u, (&sx, &sy)) in xs.iter().zip(&ys).enumerate() {
                if let Some(rgb) = geom.sample(frame.data, sx, sy) {
                    f(v * ow + u, rgb);
                }
            }
        }
    }

    /// Warps one interleaved frame into a saccade slot: 8.8 fixed-point samples
    /// (3 per pixel) and a coverage flag per pixel (0 where the frame does not
    /// cover it), the slot resized to this warper's output. Supersampled: each
    /// pixel is its block's [`box_down_slot`] (covered only where every sample is).
    pub fn warp_into_slot(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        slot: &mut WarpedFrame,
        index: u64,
    ) {
        self.supersample_render(
            slot,
            |w, target| {
                let slot = match target {
                    Target::Caller(slot) => slot,
                    Target::Fine(fine) => &mut fine.slot,
                };
                let (ow, oh) = (w.out.width, w.out.height);
                slot.reset(index, ow * oh);
                let maps = w.prepare_maps(std::slice::from_ref(m));
                let datas = [frame.data];
                let pass = w.pass(&maps, &datas, Geometry::of(frame), frame.height);
                let mut scratch = std::mem::take(&mut w.scratch);
                scratch.fit(1, ow, pass.tables, false);
                for v in 0..oh {
                    w.accumulate_row(&pass, None, v, &mut scratch, false);
                    let vals = &mut slot.value[3 * v * ow..3 * (v + 1) * ow];
                    let cov = &mut slot.covered[v * ow..(v + 1) * ow];
                    let [r, g, b] = &scratch.sums;
                    // Zipped slices, so that the loop needs no bounds checks
                    // and vectorizes whatever it is inlined into.
                    let n8 = pass.n8;
                    let sums = r[..n8].iter().zip(&g[..n8]).zip(&b[..n8]);
                    let sums = sums.zip(&scratch.count[..n8]);
                    for ((px, c), (((&r, &g), &b), &k)) in vals[..3 * n8]
                        .chunks_exact_mut(3)
                        .zip(&mut cov[..n8])
                        .zip(sums)
                    {
                        px[0] = r as u16;
                        px[1] = g as u16;
                        px[2] = b as u16;
                        *c = k as u8;
                    }
                    for u in pass.n8..ow {
                        if let Some(rgb) =
                            pass.geom
                                .sample(frame.data, scratch.xs[0][u], scratch.ys[0][u])
                        {
                            vals[3 * u] = rgb[0] as u16;
                            vals[3 * u + 1] = rgb[1] as u16;
                            vals[3 * u + 2] = rgb[2] as u16;
                            cov[u] = 1;
                        }
                    }
                }
                w.scratch = scratch;
                w.maps = maps;
            },
            |w, fine, slot| {
                let view = (w.view_w, w.view_h);
                slot.reset(index, view.0 * view.1);
                box_down_slot(
                    &fine.slot.value,
                    &fine.slot.covered,
                    w.supersample,
                    3,
                    view,
                    &mut slot.value,
                    &mut slot.covered,
                );
            },
        )
    }

    /// Warps one plane (`width x height`, followed by padding as for
    /// [`Warper::average_plane_into`]) into `values` (8.8 fixed-point samples)
    /// and `covered` (1 where the plane covers the output pixel), both this
    /// warper's output size; uncovered pixels get 0. Supersampled: as
    /// [`Warper::warp_into_slot`].
    pub fn warp_plane_into(
        &mut self,
        plane: &[u8],
        width: usize,
        height: usize,
        m: &Matrix3<f64>,
        values: &mut [u16],
        covered: &mut [u8],
    ) {
        let fine_len = self.out.width * self.out.height;
        self.supersample_render(
            (values, covered),
            |w, target| {
                let (values, covered) = match target {
                    Target::Caller(buffers) => buffers,
                    Target::Fine(fine) => fine.plane_slot(fine_len),
                };
                let ow = w.out.width;
                let maps = w.prepare_maps(std::slice::from_ref(m));
                let datas = [plane];
                let pass = w.pass(&maps, &datas, Geometry::plane(width, height, 1), height);
                let mut scratch = std::mem::take(&mut w.scratch);
                scratch.fit(1, ow, pass.tables, false);
                for (v, (vals, cov)) in values
                    .chunks_mut(ow)
                    .zip(covered.chunks_mut(ow))
                    .enumerate()
                {
                    w.accumulate_row(&pass, None, v, &mut scratch, true);
                    // Zipped slices, so that the loop needs no bounds checks
                    // and vectorizes whatever it is inlined into.
                    let n8 = pass.n8;
                    let sums = scratch.sums[0][..n8].iter().zip(&scratch.count[..n8]);
                    for ((val, c), (&s, &k)) in vals[..n8].iter_mut().zip(&mut cov[..n8]).zip(sums)
                    {
                        *val = s as u16;
                        *c = k as u8;
                    }
                    for u in pass.n8..ow {
                        let s = pass
                            .geom
                            .sample_gray(plane, scratch.xs[0][u], scratch.ys[0][u]);
                        vals[u] = s.unwrap_or(0) as u16;
                        cov[u] = s.is_some() as u8;
                    }
                }
                w.scratch = scratch;
                w.maps = maps;
            },
            |w, fine, (values, covered)| {
                box_down_slot(
                    &fine.slot.value[..fine_len],
                    &fine.slot.covered[..fine_len],
                    w.supersample,
                    1,
                    (w.view_w, w.view_h),
                    values,
                    covered,
                );
            },
        )
    }
}

// The scalar slot fill sits here rather than in `accumulator.rs` so that the
// accumulator stays a plain buffer below the warper (no warper <-> accumulator cycle).
impl WarpedFrame {
    /// Warps `frame` into this slot (reusing its buffers) with the scalar
    /// sampler: the reference [`Warper::warp_into_slot`] is tested against.
    pub fn fill(
        &mut self,
        warper: &mut Warper,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        index: u64,
    ) {
        let (w, h) = warper.render_size();
        self.reset(index, w * h);
        let (value, covered) = (&mut self.value, &mut self.covered);
        warper.warp(frame, m, |i, rgb| {
            value[3 * i] = rgb[0] as u16;
            value[3 * i + 1] = rgb[1] as u16;
            value[3 * i + 2] = rgb[2] as u16;
            covered[i] = 1;
        });
        let s = warper.supersample();
        if s > 1 {
            let view = warper.output_size();
            let (mut value, mut covered) =
                (vec![0u16; 3 * view.0 * view.1], vec![0u8; view.0 * view.1]);
            box_down_slot(
                &self.value,
                &self.covered,
                s,
                3,
                view,
                &mut value,
                &mut covered,
            );
            self.value = value;
            self.covered = covered;
        }
    }

    /// Makes this the slot of frame `index` with `pixels` pixels of three
    /// samples, every one 0 and uncovered (reusing the buffers).
    fn reset(&mut self, index: u64, pixels: usize) {
        self.index = index;
        self.value.clear();
        self.value.resize(3 * pixels, 0);
        self.covered.clear();
        self.covered.resize(pixels, 0);
    }
}
