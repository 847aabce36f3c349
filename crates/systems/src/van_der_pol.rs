//! The van der Pol oscillator x' = v, v' = −x + μ (1 − x²) v.

use sysid_ode::{Scalar, Signature, System};

/// x' = v, v' = −x + μ (1 − x²) v: states x, v; parameter mu.
#[derive(Clone, Debug)]
pub struct VanDerPol(Signature);

impl Default for VanDerPol {
    fn default() -> Self {
        Self(Signature::new(&["x", "v"], &["mu"]))
    }
}

impl System for VanDerPol {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let (x, v, mu) = (y[0], y[1], p[0]);
        dy[0] = v;
        dy[1] = -x + mu * (-(x * x) + 1.0) * v;
    }
}
