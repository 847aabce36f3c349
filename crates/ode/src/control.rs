//! Step-size control for the error-controlled schemes: the safety factor and the smallest
//! step ratio they share, the controller each parameterises, and the first step.
//! Here, not in a scheme's file, so that neither the loop nor another scheme imports a scheme
//! for its constants.

use crate::rhs::Rhs;
use crate::work::{Evaluator, Work};

/// The next step aims at 0.9 of the size the error estimate allows (DOPRI5 and RODAS alike).
pub(crate) const SAFETY: f64 = 0.9;
/// The smallest ratio h_new/h after one step (DOPRI5 and RODAS alike); also the ratio after
/// a trial step that left the region where f is defined.
pub(crate) const MIN_FACTOR: f64 = 0.2;

/// The controller h_new = h / fac with fac = err^`exponent` / err_old^`beta` / [`SAFETY`],
/// kept within [1/`max_factor`, 1/[`MIN_FACTOR`]]; err_old is the previous accepted error.
/// `beta` > 0 is PI control (Gustafsson), `beta` = 0 plain (I) control.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Control {
    pub(crate) exponent: f64,
    pub(crate) beta: f64,
    /// The largest growth of the step size in one accepted step.
    pub(crate) max_factor: f64,
}

impl Control {
    /// The divisor of h after an accepted step with ln(err) = `ln_err`, the previous accepted
    /// one having `ln_err_old`.
    #[inline]
    pub(crate) fn accepted(&self, ln_err: f64, ln_err_old: f64) -> f64 {
        // err^exponent / err_old^beta as one exp. With beta = 0 (RODAS) the subtracted term
        // is ±0, err_old being finite, which changes no bit of the result.
        ((self.exponent * ln_err - self.beta * ln_err_old).exp() / SAFETY)
            .clamp(1.0 / self.max_factor, 1.0 / MIN_FACTOR)
    }

    /// The divisor of h after a rejected step (err > 1): never more than 1/[`MIN_FACTOR`],
    /// and without the previous error, which belongs to an accepted step.
    #[inline]
    pub(crate) fn rejected(&self, ln_err: f64) -> f64 {
        ((self.exponent * ln_err).exp() / SAFETY).min(1.0 / MIN_FACTOR)
    }
}

/// Hairer's starting step size for a given direction (Solving ODE I, Section II.4), from
/// (t, w.x) with `w.k[0]` = f(t, x), for a first step of order `order` (its error grows as
/// h^(order + 1): 4 for DOPRI5 and the Rosenbrock schemes, 8 for DOP853, 1 for the
/// multistep scheme's first step); one evaluation of f, into `w.k[1]`.
pub(crate) fn initial_step_of_order<R: Rhs>(
    ev: &mut Evaluator<'_, R>,
    w: &mut Work,
    t: f64,
    dir: f64,
    order: i32,
) -> f64 {
    let n = w.x.len() as f64;
    let (rtol, atol) = (ev.cfg.rtol, ev.cfg.atol);
    let (mut dnf, mut dny) = (0.0, 0.0);
    // A component without a scale yet (0 under a purely relative tolerance, atol = 0)
    // says nothing about the first step's size.
    // Each state's own floor where it has one (see `state_floors`), else atol.
    let floor = |own: &[f64], i: usize| own.get(i).copied().unwrap_or(atol);
    for (i, (x, f)) in w.x.iter().zip(&w.k[0]).enumerate() {
        let sk = floor(&ev.state_floors, i) + rtol * x.abs();
        if sk > 0.0 {
            dnf += (f / sk) * (f / sk);
            dny += (x / sk) * (x / sk);
        }
    }
    let (dnf, dny) = ((dnf / n).sqrt(), (dny / n).sqrt());
    // A scale so small that the ratio overflows (atol 1e-320 for a state at 0) says no more
    // than none: Hairer's default then.
    let ratio = 0.01 * dny / dnf;
    let mut h = if dnf <= 1e-5 || dny <= 1e-5 || !(ratio > 0.0 && ratio.is_finite()) {
        1e-6
    } else {
        ratio
    };
    h = h.min(ev.cfg.max_step);
    for i in 0..w.x.len() {
        w.tmp[i] = w.x[i] + dir * h * w.k[0][i];
    }
    ev.f(t + dir * h, &w.tmp, &mut w.k[1]);
    let mut der2 = 0.0;
    for i in 0..w.x.len() {
        let sk = floor(&ev.state_floors, i) + rtol * w.x[i].abs();
        if sk > 0.0 {
            der2 += ((w.k[1][i] - w.k[0][i]) / sk).powi(2);
        }
    }
    let der2 = (der2 / n).sqrt() / h;
    let der12 = der2.abs().max(dnf);
    let h1 = if der12 <= 1e-15 {
        (h * 1e-3).max(1e-6)
    } else {
        (0.01 / der12).powf(1.0 / f64::from(order + 1))
    };
    // Likewise where the second derivative's estimate overflows: the first guess stands.
    let h1 = if h1 > 0.0 { h1 } else { h };
    (100.0 * h).min(h1).max(LEAST_FIRST_STEP * t.abs()).min(ev.cfg.max_step)
}

/// The least first step, relative to |t|: 64 units in the last place of t, four times what
/// the driver's underflow test refuses; the driver's `resolution(t)` without its floor at
/// |t| < 1, so that near t = 0 the estimate stands as it was. Hairer's estimate samples f at t + h for a first
/// guess h and can fall below t's resolution where f changes fast just after t (an input
/// switched on at t = 1799.99 that ramps to 1e7 within 0.01, as Chen_MSB2009's does, gave
/// 9.5e-13 for `bdf`'s first step at rtol 1e-9, atol 1e-13, where t resolves 6.4e-12): the
/// integration then failed before its first trial. The error test, not the estimate, decides
/// how short the steps must be.
const LEAST_FIRST_STEP: f64 = 64.0 * f64::EPSILON;
