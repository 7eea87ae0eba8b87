//! One-dimensional minimization: the golden-section search both
//! self-calibrations (`--fov auto`, `--readout-ms auto`) refine with, one
//! evaluation after another or two at once ([`golden_section_paired`]).

/// Golden-section search for a minimum of `f` on `[a, b]` (a unimodal
/// bracket, e.g. around the best point of a coarse grid): `iters` steps,
/// one evaluation each (plus two to start), each shrinking the bracket by
/// `(sqrt(5) - 1) / 2`. Returns the final bracket's middle, or `f`'s first error.
pub fn golden_section<E>(
    mut f: impl FnMut(f64) -> Result<f64, E>,
    a: f64,
    b: f64,
    iters: usize,
) -> Result<f64, E> {
    let (c, d) = Golden::inner(a, b);
    let (fc, fd) = (f(c)?, f(d)?);
    let mut s = Golden::new(a, b, fc, fd);
    for _ in 0..iters {
        let v = f(s.next())?;
        s.step(v);
    }
    Ok(s.middle())
}

/// [`golden_section`] with two evaluations at once (on rayon's threads with
/// the `parallel` feature): the two starting points together, then each
/// step's point beside a guess at the next step's (the branch a parabola
/// through the last three values predicts), kept where the guess was right.
/// The same points, decisions and result as [`golden_section`], in fewer
/// rounds (a round costs one evaluation's time on two cores). `record` sees
/// every evaluation, the guesses that were not needed included.
///
/// `f(x, bound)` is the value at `x`, except that where it is above `bound`
/// it may return any value above `bound` instead (an evaluation stopped
/// early, once it could only end above it): `bound` is the best value of the
/// bracket's inner points, a point worse than that only loses the next
/// comparison and leaves the bracket, so the steps and result are the same.
/// The two starting points get no bound.
pub fn golden_section_paired<E: Send>(
    f: impl Fn(f64, f64) -> Result<f64, E> + Sync,
    a: f64,
    b: f64,
    iters: usize,
    mut record: impl FnMut(f64, f64),
) -> Result<f64, E> {
    // `f` at `x`, and at `y` beside it where there is one.
    let mut both = |x: f64, y: Option<f64>, bound: f64| -> Result<(f64, Option<f64>), E> {
        let (fx, fy) = pair(&|x| f(x, bound), x, y);
        let (fx, fy) = (fx?, fy.transpose()?);
        record(x, fx);
        if let (Some(y), Some(fy)) = (y, fy) {
            record(y, fy);
        }
        Ok((fx, fy))
    };
    let (c, d) = Golden::inner(a, b);
    let (fc, fd) = both(c, Some(d), f64::INFINITY)?;
    let fd = fd.unwrap_or(f64::NAN);
    let mut s = Golden::new(a, b, fc, fd);
    let mut seen = vec![(c, fc), (d, fd)];
    let mut guessed: Option<(f64, f64)> = None;
    for left in (1..=iters).rev() {
        let p = s.next();
        // `p` is compared with the better inner point, and a guess at the
        // point after it with that or `p`'s value, whichever is lower.
        let bound = s.fc.min(s.fd);
        let v = match guessed.take() {
            Some((x, v)) if x.to_bits() == p.to_bits() => v,
            _ if left >= 2 && cfg!(feature = "parallel") => {
                let guess = s.guess_after(p, &seen);
                let (v, w) = both(p, Some(guess), bound)?;
                guessed = w.map(|w| (guess, w));
                v
            }
            _ => both(p, None, bound)?.0,
        };
        seen.push((p, v));
        s.step(v);
    }
    Ok(s.middle())
}

/// `f` at `x`, and at `y` where there is one (at once with the `parallel`
/// feature).
fn pair<E: Send>(
    f: &(impl Fn(f64) -> Result<f64, E> + Sync),
    x: f64,
    y: Option<f64>,
) -> (Result<f64, E>, Option<Result<f64, E>>) {
    let Some(y) = y else {
        return (f(x), None);
    };
    #[cfg(feature = "parallel")]
    let (fx, fy) = rayon::join(|| f(x), || f(y));
    #[cfg(not(feature = "parallel"))]
    let (fx, fy) = (f(x), f(y));
    (fx, Some(fy))
}

/// A golden-section bracket `[a, b]` with its two inner points' values.
#[derive(Clone, Copy, Debug)]
struct Golden {
    a: f64,
    b: f64,
    c: f64,
    d: f64,
    fc: f64,
    fd: f64,
}

impl Golden {
    /// The golden ratio's conjugate, `(sqrt(5) - 1) / 2`.
    fn ratio() -> f64 {
        (5f64.sqrt() - 1.0) / 2.0
    }

    /// The inner points of `[a, b]`.
    fn inner(a: f64, b: f64) -> (f64, f64) {
        let g = Self::ratio();
        (b - g * (b - a), a + g * (b - a))
    }

    fn new(a: f64, b: f64, fc: f64, fd: f64) -> Self {
        let (c, d) = Self::inner(a, b);
        Self { a, b, c, d, fc, fd }
    }

    /// The point the next step evaluates.
    fn next(&self) -> f64 {
        let g = Self::ratio();
        if self.fc < self.fd {
            self.d - g * (self.d - self.a)
        } else {
            self.c + g * (self.b - self.c)
        }
    }

    /// The step with `v`, the value at [`Golden::next`].
    fn step(&mut self, v: f64) {
        let g = Self::ratio();
        if self.fc < self.fd {
            self.b = self.d;
            self.d = self.c;
            self.fd = self.fc;
            self.c = self.b - g * (self.b - self.a);
            self.fc = v;
        } else {
            self.a = self.c;
            self.c = self.d;
            self.fc = self.fd;
            self.d = self.a + g * (self.b - self.a);
            self.fd = v;
        }
    }

    fn middle(&self) -> f64 {
        (self.a + self.b) / 2.0
    }

    /// A guess at the point after `p`'s step: the branch its value, as the
    /// parabola through the last three values `seen` predicts it, takes.
    fn guess_after(&self, p: f64, seen: &[(f64, f64)]) -> f64 {
        let predicted = match seen {
            [.., (x0, y0), (x1, y1), (x2, y2)] => {
                // Lagrange's form of the parabola through the three.
                let l0 = (p - x1) * (p - x2) / ((x0 - x1) * (x0 - x2));
                let l1 = (p - x0) * (p - x2) / ((x1 - x0) * (x1 - x2));
                let l2 = (p - x0) * (p - x1) / ((x2 - x0) * (x2 - x1));
                y0 * l0 + y1 * l1 + y2 * l2
            }
            _ => f64::NAN,
        };
        // Without a prediction: the new point as the better one.
        let v = if predicted.is_finite() {
            predicted
        } else {
            f64::MIN
        };
        let mut after = *self;
        after.step(v);
        after.next()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

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

    #[test]
    fn paired_steps_are_the_sequential_search_s_own() {
        let fs: [&(dyn Fn(f64) -> f64 + Sync); 3] = [
            &|x| (x - 0.3).powi(2),
            &|x| (x - 1.7).abs().sqrt() + 0.1 * (5.0 * x).sin(),
            &|x| (2.0 * x).cos() + 0.5 * x,
        ];
        for f in fs {
            for iters in [0, 1, 2, 7, 12, 30] {
                let mut order = Vec::new();
                let one = golden_section(
                    |x| {
                        order.push(x);
                        Ok::<_, ()>(f(x))
                    },
                    -1.0,
                    2.5,
                    iters,
                )
                .unwrap();
                let mut seen = Vec::new();
                let two = golden_section_paired(
                    |x, _| Ok::<_, ()>(f(x)),
                    -1.0,
                    2.5,
                    iters,
                    |x, _| seen.push(x),
                )
                .unwrap();
                assert_eq!(one.to_bits(), two.to_bits(), "{iters} steps");
                // Every point the sequential search took was evaluated.
                assert!(order.iter().all(|x| seen.contains(x)));
                // Stopped early above the bound, at any value above it: the
                // same steps and result.
                let stopped = AtomicUsize::new(0);
                let three = golden_section_paired(
                    |x, bound| {
                        let v = f(x);
                        Ok::<_, ()>(if v > bound {
                            stopped.fetch_add(1, Ordering::Relaxed);
                            bound.next_up()
                        } else {
                            v
                        })
                    },
                    -1.0,
                    2.5,
                    iters,
                    |_, _| {},
                )
                .unwrap();
                assert_eq!(
                    one.to_bits(),
                    three.to_bits(),
                    "{iters} steps, stopped early"
                );
                if iters >= 7 {
                    assert!(stopped.load(Ordering::Relaxed) > 0, "nothing stopped early");
                }
            }
        }
        assert_eq!(
            golden_section_paired(|_, _| Err::<f64, _>("no"), 0.0, 1.0, 3, |_, _| {}),
            Err("no")
        );
    }
}
