//! Every kernel against the scalar reference, bit for bit.

use super::*;

/// Every kernel this CPU runs and the scalar reference agree bit for bit, for
/// tables (with NaN and out-of-frame points) and homography rows, RGB and RGBA,
/// bilinear and bicubic.
#[test]
fn every_kernel_matches_scalar() {
    // 72 pixels: four 16-lane steps and a last one of eight.
    let (w, h, n) = (37usize, 23usize, 72usize);
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut rand = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 40) as u32
    };
    // Bilinear and bicubic sampling.
    for (channels, cubic) in [(3usize, false), (4, false), (3, true), (4, true)] {
        let frames: Vec<Vec<u8>> = (0..4)
            .map(|_| {
                (0..w * h * channels + FRAME_PADDING)
                    .map(|_| rand() as u8)
                    .collect()
            })
            .collect();
        let datas: Vec<&[u8]> = frames.iter().map(|f| f.as_slice()).collect();
        let geom = Geometry {
            cubic,
            ..Geometry::plane(w, h, channels)
        };
        let table = |r: &mut dyn FnMut() -> u32, size: usize| -> Vec<f32> {
            (0..n)
                .map(|_| match r() % 16 {
                    0 => f32::NAN,
                    1 => -EDGE_TOLERANCE * 0.5,
                    2 => (size - 1) as f32 + EDGE_TOLERANCE * 0.5,
                    _ => (r() % 100_000) as f32 / 100_000.0 * (size + 2) as f32 - 1.0,
                })
                .collect()
        };
        let (xs, ys) = (table(&mut rand, w), table(&mut rand, h));
        let coords = [
            RowCoords::Table(&xs, &ys),
            RowCoords::Homography(HomographyRow {
                x0: -3.0,
                y0: 5.5,
                z0: 0.9,
                dx: 0.7,
                dy: 0.11,
                dz: 0.003,
            }),
            RowCoords::Homography(HomographyRow {
                x0: 40.0,
                y0: -2.0,
                z0: 1.2,
                dx: -0.5,
                dy: 0.4,
                // Crosses z = 0 inside the row: rays behind the camera.
                dz: -0.02,
            }),
            // A slight roll: sixteen pixels' taps on two or three rows,
            // where the AVX-512 kernel picks them from row windows.
            RowCoords::Homography(HomographyRow {
                x0: 2.3,
                y0: 7.4,
                z0: 1.0,
                dx: 0.97,
                dy: 0.045,
                dz: 0.0005,
            }),
        ];
        let run = |kernel: Kernel| {
            let mut sums = vec![vec![0u32; n]; 4];
            let [r, g, b, c] = &mut sums[..] else {
                unreachable!()
            };
            // SAFETY: the kernel comes from `detect` (or is scalar), `n` is a
            // multiple of 8, frames are padded and every buffer holds `n` values.
            unsafe { kernel.accumulate_row(&datas, &geom, &coords, n, r, g, b, c) };
            sums
        };
        let reference = run(Kernel::Scalar);
        // Some pixels are covered by every frame, some by at most one.
        assert!(reference[3].iter().any(|&c| c <= 1) && reference[3].contains(&4));
        for kernel in Kernel::available() {
            assert_eq!(run(kernel), reference, "{kernel:?}");
        }
        // The same frames read as single-channel planes of `channels` times
        // the width: the gray kernel against its scalar reference.
        let gray = Geometry::plane(w * channels, h, 1).with_cubic(cubic);
        let run_gray = |kernel: Kernel| {
            let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
            // SAFETY: as above; each plane has FRAME_PADDING >= 2 bytes past it.
            unsafe { kernel.accumulate_row_gray(&datas, &gray, &coords, n, &mut acc, &mut count) };
            (acc, count)
        };
        let reference = run_gray(Kernel::Scalar);
        // Some by every frame, some by at most one of the first three (the
        // fourth, the slight roll, covers the whole row of the wider plane).
        assert!(reference.1.iter().any(|&c| c <= 2) && reference.1.contains(&4));
        for kernel in Kernel::available() {
            assert_eq!(run_gray(kernel), reference, "gray {kernel:?}");
        }
        // Two planes of that geometry at once (the frames in another
        // order for the second): each the gray kernel's sums.
        let mut others = datas.clone();
        others.rotate_left(1);
        let run_other = |kernel: Kernel| {
            let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
            // SAFETY: as above.
            unsafe { kernel.accumulate_row_gray(&others, &gray, &coords, n, &mut acc, &mut count) };
            (acc, count)
        };
        let other = run_other(Kernel::Scalar);
        assert_ne!(other.0, reference.0);
        for kernel in Kernel::available() {
            let (mut a, mut b, mut count) = (vec![0u32; n], vec![0u32; n], vec![0u32; n]);
            // SAFETY: as above, for both sets of planes.
            unsafe {
                kernel.accumulate_row_gray_pair(
                    &datas, &others, &gray, &coords, n, &mut a, &mut b, &mut count,
                )
            };
            assert_eq!(
                (&a, &count),
                (&reference.0, &reference.1),
                "pair, first {kernel:?}"
            );
            assert_eq!(b, other.0, "pair, second {kernel:?}");
        }
        // And points on the plane's own edges and corners (its right edge
        // is past the tables above): within the tolerance outside, on the
        // last column and row, and just inside them.
        let edge = |r: &mut dyn FnMut() -> u32, size: usize| -> Vec<f32> {
            let last = (size - 1) as f32;
            let near = [
                -EDGE_TOLERANCE,
                0.0,
                last - 1.0 / 1024.0,
                last - 1.0 / 256.0,
                last,
                last + EDGE_TOLERANCE,
                last + 2.0 * EDGE_TOLERANCE,
            ];
            (0..n).map(|_| near[r() as usize % near.len()]).collect()
        };
        let (ex, ey) = (edge(&mut rand, w * channels), edge(&mut rand, h));
        let edges = [RowCoords::Table(&ex, &ey)];
        let run_edges = |kernel: Kernel| {
            let (mut acc, mut count) = (vec![0u32; n], vec![0u32; n]);
            // SAFETY: as above.
            unsafe {
                kernel.accumulate_row_gray(&datas[..1], &gray, &edges, n, &mut acc, &mut count)
            };
            (acc, count)
        };
        let reference = run_edges(Kernel::Scalar);
        assert!(reference.1.contains(&0) && reference.1.contains(&1));
        for kernel in Kernel::available() {
            assert_eq!(run_edges(kernel), reference, "gray edges {kernel:?}");
        }
        // Finishing those sums into pixels, where a kernel has a pass for it:
        // as `average` rounds, `fill` where no frame covers the pixel.
        // Every fifth pixel made one that no frame covers (sum 0, as the
        // kernels leave it).
        let uncovered = |i: usize, v: u32| if i % 5 == 0 { 0 } else { v };
        let sums: &Vec<u32> = &reference
            .0
            .iter()
            .enumerate()
            .map(|(i, &s)| uncovered(i, s))
            .collect();
        let counts: &Vec<u32> = &reference
            .1
            .iter()
            .enumerate()
            .map(|(i, &k)| uncovered(i, k))
            .collect();
        let fill = 77u8;
        let expected: Vec<u8> = sums
            .iter()
            .zip(counts)
            .map(|(&s, &k)| if k == 0 { fill } else { average(s, k) })
            .collect();
        for kernel in Kernel::available() {
            let (mut out, mut coverage) = (vec![0u8; n], vec![0u8; n]);
            // SAFETY: as above; `n` is a multiple of 8 and every slice holds `n` values.
            let complete = unsafe {
                kernel.finish_row_gray(sums, counts, &mut out, &mut coverage, n, 3, fill)
            };
            if let Some(complete) = complete {
                assert_eq!(out, expected, "finish {kernel:?}");
                assert!(coverage.iter().zip(counts).all(|(&c, &k)| c as u32 == k));
                assert_eq!(complete, counts.iter().filter(|&&k| k == 3).count());
            }
        }
        // The ghost-free forms: random frames differ by up to 255 levels, so
        // a threshold of 60 levels gives weights from 0 to 16 (3: mostly 0).
        for levels in [3.0, 60.0] {
            let deghost = Deghost::new(levels).unwrap();
            let run_merge = |kernel: Kernel| {
                let mut sums = vec![vec![0u32; n]; 5];
                let [r, g, b, w, c] = &mut sums[..] else {
                    unreachable!()
                };
                // SAFETY: as above.
                unsafe { kernel.merge_row(&datas, &geom, &coords, deghost, n, [r, g, b], w, c) };
                sums
            };
            let reference = run_merge(Kernel::Scalar);
            if levels > 10.0 {
                let partial = reference[3].iter().any(|&w| w % 16 != 0);
                assert!(partial, "{levels}: some partial weights");
            }
            for kernel in Kernel::available() {
                assert_eq!(run_merge(kernel), reference, "merge {levels} {kernel:?}");
            }
            let run_merge_gray = |kernel: Kernel| {
                let mut sums = vec![vec![0u32; n]; 3];
                let [s, w, c] = &mut sums[..] else {
                    unreachable!()
                };
                // SAFETY: as above.
                unsafe { kernel.merge_row_gray(&datas, &gray, &coords, deghost, n, s, w, c) };
                sums
            };
            let reference = run_merge_gray(Kernel::Scalar);
            for kernel in Kernel::available() {
                let sums = run_merge_gray(kernel);
                assert_eq!(sums, reference, "merge gray {levels} {kernel:?}");
            }
            // Two planes at once (the second's frames in another order, as
            // above): each as the plane kernel merges it, with its own weights.
            let (mut other_s, mut other_w, mut other_c) = (vec![0; n], vec![0; n], vec![0; n]);
            // SAFETY: as above.
            unsafe {
                Kernel::Scalar.merge_row_gray(
                    &others,
                    &gray,
                    &coords,
                    deghost,
                    n,
                    &mut other_s,
                    &mut other_w,
                    &mut other_c,
                )
            };
            assert_ne!(
                other_w, reference[1],
                "{levels}: the planes' weights differ"
            );
            for kernel in Kernel::available() {
                let mut sums = vec![vec![0u32; n]; 5];
                let [sa, sb, wa, wb, c] = &mut sums[..] else {
                    unreachable!()
                };
                // SAFETY: as above, for both sets of planes.
                unsafe {
                    kernel.merge_row_gray_pair(
                        (&datas, &others),
                        &gray,
                        &coords,
                        deghost,
                        n,
                        (sa, sb),
                        (wa, wb),
                        c,
                    )
                };
                let first = [sums[0].clone(), sums[2].clone(), sums[4].clone()];
                assert_eq!(
                    first.to_vec(),
                    reference,
                    "merge pair, first {levels} {kernel:?}"
                );
                assert_eq!(
                    (&sums[1], &sums[3]),
                    (&other_s, &other_w),
                    "merge pair, second {levels} {kernel:?}"
                );
            }
        }
    }
}
