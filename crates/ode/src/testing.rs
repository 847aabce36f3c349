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
