//! The classical fourth-order Runge–Kutta method with a fixed step (for order studies and
//! comparisons), with the cubic Hermite interpolant through both ends of a step as its dense
//! output.

use crate::control::Control;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::stepper::Stepper;
use crate::work::{Evaluator, Work};

/// The RK4 scheme.
pub(crate) struct Rk4;

impl<R: Rhs> Stepper<R> for Rk4 {
    /// One classical RK4 step; f(t + h, x_new) in `k[6]` for the Hermite dense output. No error
    /// estimate: NaN.
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError> {
        let n = w.x.len();
        let [k1, k2, k3, k4, _, _, k7, _] = &mut w.k;
        let (x, tmp, xn) = (&w.x, &mut w.tmp, &mut w.x_new);
        for i in 0..n {
            tmp[i] = x[i] + 0.5 * h * k1[i];
        }
        ev.f(t + 0.5 * h, tmp, k2);
        for i in 0..n {
            tmp[i] = x[i] + 0.5 * h * k2[i];
        }
        ev.f(t + 0.5 * h, tmp, k3);
        for i in 0..n {
            tmp[i] = x[i] + h * k3[i];
        }
        ev.f(t + h, tmp, k4);
        for i in 0..n {
            xn[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        ev.f(t + h, xn, k7);
        Ok(f64::NAN)
    }

    fn dense(&self, _: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64) {
        let n = w.x.len();
        let (x, xn, k) = (&w.x[..n], &w.x_new[..n], &w.k);
        w.interpolant.set_hermite((t, t_next), (x, xn), (&k[0][..n], &k[6][..n]));
    }

    fn control(&self) -> Option<Control> {
        None
    }
}
