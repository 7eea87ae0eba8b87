//! One-dimensional minimization: the golden-section search both
//! self-calibrations (`--fov auto`, `--readout-ms auto`) refine with.

/// Golden-section search for a minimum of `f` on `[a, b]` (a unimodal
/// bracket, e.g. around the best point of a coarse grid): `iters` steps,
/// one evaluation each (plus two to start), each shrinking the bracket by
/// `(sqrt(5) - 1) / 2`. Returns the final bracket's middle, or `f`'s first error.
pub fn golden_section<E>(
    mut f: impl FnMut(f64) -> Result<f64, E>,
    mut a: f64,
    mut b: f64,
    iters: usize,
) -> Result<f64, E> {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let mut fc = f(c)?;
    let mut fd = f(d)?;
    for _ in 0..iters {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c)?;
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d)?;
        }
    }
    Ok((a + b) / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_parabolas_minimum() {
        let x = golden_section(|x| Ok::<_, ()>((x - 0.3).powi(2)), -1.0, 2.0, 40).unwrap();
        assert!((x - 0.3).abs() < 1e-6, "{x}");
        // Errors pass through.
        assert_eq!(
            golden_section(|_| Err::<f64, _>("no"), 0.0, 1.0, 3),
            Err("no")
        );
    }
}
