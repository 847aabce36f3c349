//! What sysid's tests share: the tolerance checks (one helper, so failures read the same)
//! and the smallest test system with a closed form.

use crate::{Scalar, Signature, System};

/// x' = −k x: one state `x`, one parameter `k`.
#[derive(Clone, Debug)]
pub struct Decay(pub Signature);

impl Decay {
    /// The system with state `x` and parameter `k`.
    pub fn new() -> Self {
        Self(Signature::new(&["x"], &["k"]))
    }

    /// (x, ∂x/∂x0, ∂x/∂k) at time τ after t0.
    pub fn exact(x0: f64, k: f64, tau: f64) -> (f64, f64, f64) {
        let e = (-k * tau).exp();
        (x0 * e, e, -tau * x0 * e)
    }
}

impl Default for Decay {
    fn default() -> Self {
        Self::new()
    }
}

impl System for Decay {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * y[0];
    }
}

/// Asserts |actual − expected| ≤ tol · max(|expected|, floor) with floor = 1e-300, i.e. a
/// relative tolerance; compare with 0 through [`assert_close_abs`].
#[track_caller]
pub fn assert_close(actual: f64, expected: f64, tol: f64) {
    let err = (actual - expected).abs();
    let bound = tol * expected.abs().max(1e-300);
    assert!(
        err <= bound,
        "{actual:e} differs from {expected:e} by {err:.3e} (relative {:.3e}), allowed {tol:.1e} relative",
        err / expected.abs().max(1e-300)
    );
}

/// Asserts |actual − expected| ≤ tol (an absolute tolerance).
#[track_caller]
pub fn assert_close_abs(actual: f64, expected: f64, tol: f64) {
    let err = (actual - expected).abs();
    assert!(err <= tol, "{actual:e} differs from {expected:e} by {err:.3e}, allowed {tol:.1e}");
}

/// max over m, c of |a_m(c) − b_m(c)| / max_m |b_m(c)|, m over `count` output times: the
/// largest difference of two solutions, each component scaled by its largest magnitude in b
/// (so a sensitivity of 1e5 and one of 1e-3 are judged alike).
pub fn scaled_difference(
    count: usize,
    a: impl Fn(usize) -> Vec<f64>,
    b: impl Fn(usize) -> Vec<f64>,
) -> f64 {
    let (a, b): (Vec<Vec<f64>>, Vec<Vec<f64>>) = (0..count).map(|m| (a(m), b(m))).unzip();
    let width = b[0].len();
    (0..width)
        .map(|c| {
            let scale = b.iter().map(|b| b[c].abs()).fold(1e-300, f64::max);
            a.iter().zip(&b).map(|(a, b)| (a[c] - b[c]).abs() / scale).fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}
