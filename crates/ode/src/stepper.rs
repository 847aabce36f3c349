//! The one trait every integration scheme implements ([`Stepper`]). The loop in `driver`
//! steps, interpolates and controls the step size only through it.

use crate::control::Control;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::work::{Evaluator, Work};

/// One integration scheme: how it steps, how it interpolates a step, how it controls the
/// step size and whether it can tell a stiff problem.
///
/// The contract with the loop: on entry to [`step`](Self::step), `w.x` holds x(t) and
/// `w.k[0]` = f(t, x); the step leaves x(t + h) in `w.x_new` (and for the explicit schemes
/// f(t + h, x_new) in `w.k[6]`, the next step's first stage, first same as last). If the
/// step is accepted the loop calls [`dense`](Self::dense) (when the interpolant is wanted),
/// then swaps `x` with `x_new` and `k[0]` with `k[6]`.
pub(crate) trait Stepper<R: Rhs> {
    /// One step from (t, w.x) of signed size h; returns its error norm (accepted when ≤ 1).
    /// A scheme without an error estimate returns NaN: it runs only with a fixed step, where
    /// the norm is not looked at.
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError>;

    /// Fills `w.interpolant` for the step just taken from t to t_next (DOP853 evaluates f
    /// for it; the other schemes form it from their stages).
    fn dense(&self, ev: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64);

    /// The step-size controller; `None` for a scheme without an error estimate, which
    /// [`Integrator::validate`](crate::Integrator::validate) allows only with a fixed step.
    fn control(&self) -> Option<Control>;

    /// The order whose error the first step's size is estimated for
    /// ([`initial_step_of_order`](crate::control::initial_step_of_order)).
    fn first_step_order(&self) -> i32 {
        4
    }

    /// Hairer's estimate of h·λ, λ the dominant eigenvalue of ∂f/∂x, for the step just
    /// taken, on DOPRI5's scale; `None` for schemes that give none (DOPRI5 and DOP853 do).
    fn stiffness_estimate(&self, w: &Work, h: f64) -> Option<f64> {
        let _ = (w, h);
        None
    }
}
