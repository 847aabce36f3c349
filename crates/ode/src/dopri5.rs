//! Dormand–Prince 5(4) (Hairer's DOPRI5): an explicit Runge–Kutta pair, error-controlled
//! by the difference of its orders 5 and 4, with a dense output of order 4 and Hairer's
//! estimate of h·λ that the stiffness test reads.

use crate::control::Control;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::stepper::Stepper;
use crate::work::{Evaluator, Work};

// Dormand & Prince (1980), coefficients as in Hairer, Nørsett & Wanner, Solving ODE I, Table 5.2.
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
// Error estimate: difference of the 5th- and 4th-order solutions.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
// Dense output of order 4 (Hairer's DOPRI5 code, CONTD5).
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// Hairer's DOPRI5 defaults: PI control with β = 0.04, err^(0.2 − 0.75 β) / err_old^β, the
/// step growing at most tenfold.
const BETA: f64 = 0.04;
const CONTROL: Control = Control { exponent: 0.2 - BETA * 0.75, beta: BETA, max_factor: 10.0 };

/// The DOPRI5 scheme.
pub(crate) struct Dopri5;

impl<R: Rhs> Stepper<R> for Dopri5 {
    /// One DOPRI5 step from (t, w.x) with `k[0]` = f(t, x). Leaves the solution in w.x_new,
    /// the sixth stage's argument x₆ in w.tmp, f(t + h, x_new) in `k[6]`, and returns the
    /// error norm.
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError> {
        let n = w.x.len();
        let [k1, k2, k3, k4, k5, k6, k7, e] = &mut w.k;
        // Slices of one length: the loops below run without bounds checks.
        let (x, tmp, xn) = (&w.x[..n], &mut w.tmp[..n], &mut w.x_new[..n]);
        for i in 0..n {
            tmp[i] = x[i] + h * A21 * k1[..n][i];
        }
        ev.f(t + C2 * h, tmp, k2);
        let (k1, k2) = (&k1[..n], &k2[..n]);
        for i in 0..n {
            tmp[i] = x[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        ev.f(t + C3 * h, tmp, k3);
        let k3 = &k3[..n];
        for i in 0..n {
            tmp[i] = x[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        ev.f(t + C4 * h, tmp, k4);
        let k4 = &k4[..n];
        for i in 0..n {
            tmp[i] = x[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        ev.f(t + C5 * h, tmp, k5);
        let k5 = &k5[..n];
        for i in 0..n {
            tmp[i] =
                x[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        ev.f(t + h, tmp, k6);
        let k6 = &k6[..n];
        for i in 0..n {
            xn[i] =
                x[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        ev.f(t + h, xn, k7);
        let k7 = &k7[..n];
        let e = &mut e[..n];
        for i in 0..n {
            e[i] =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
        }
        Ok(ev.error_norm(e, x, xn))
    }

    /// Hairer's form: the cubic Hermite interpolant through both ends and their slopes, plus
    /// the fourth-order term r₅ from the stages (his code's CONTD5).
    fn dense(&self, _: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64) {
        let h = t_next - t;
        let n = w.x.len();
        let (x, xn, k) = (&w.x[..n], &w.x_new[..n], &w.k);
        w.interpolant.set_hermite((t, t_next), (x, xn), (&k[0][..n], &k[6][..n]));
        let [_, _, _, _, r5] = w.interpolant.coefficients_mut();
        let r5 = &mut r5[..n];
        let (k1, k3, k4, k5, k6, k7) =
            (&k[0][..n], &k[2][..n], &k[3][..n], &k[4][..n], &k[5][..n], &k[6][..n]);
        for i in 0..n {
            r5[i] =
                h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
        }
    }

    fn control(&self) -> Option<Control> {
        Some(CONTROL)
    }

    /// h ‖f(x_new) − f(x₆)‖ / ‖x_new − x₆‖, both at t + h: the stages that
    /// [`step`](Self::step) leaves in `k[6]`, `k[5]`, x_new and tmp.
    fn stiffness_estimate(&self, w: &Work, h: f64) -> Option<f64> {
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..w.x.len() {
            num += (w.k[6][i] - w.k[5][i]) * (w.k[6][i] - w.k[5][i]);
            den += (w.x_new[i] - w.tmp[i]) * (w.x_new[i] - w.tmp[i]);
        }
        Some(if den > 0.0 { h.abs() * (num / den).sqrt() } else { 0.0 })
    }
}
