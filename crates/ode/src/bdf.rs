//! A variable-order, variable-step multistep scheme for stiff systems: the numerical
//! differentiation formulas of orders 1 to 4 and BDF5 (Shampine & Reichelt, "The MATLAB ODE
//! suite", SIAM J. Sci. Comput. 18, 1997, the formulas of ode15s), in backward differences
//! at a constant step that are re-interpolated when the step changes.
//!
//! Why beside Rodas5P: a Rosenbrock step costs a Jacobian, a factorisation and eight stages
//! (each an evaluation of f and a solve) for every step. A multistep step costs one to three
//! evaluations and solves (a simplified Newton iteration on one implicit equation), and the
//! factorised matrix serves many steps: it is formed again only when the step has changed by
//! more than 30 %, after 20 steps, or when the iteration fails to converge (the rules of
//! CVODE, Hindmarsh et al., ACM TOMS 31, 2005). On large stiff problems integrated over long
//! spans that is several times less work per step.
//!
//! The formulas, for order q at step h with ∇ʲ the backward differences and γ_q = Σ_{j≤q} 1/j:
//!
//! Σ_{j=1}^{q} (1/j) ∇ʲ y_{n+1} − h f(t_{n+1}, y_{n+1}) − κ_q γ_q (y_{n+1} − y⁽⁰⁾) = 0,
//!
//! with the predictor y⁽⁰⁾ = Σ_{j=0}^{q} ∇ʲ y_n. Written for the correction d = y_{n+1} − y⁽⁰⁾
//! (which is ∇^{q+1} y_{n+1}):
//!
//! d = (h/α_q) f(t_{n+1}, y⁽⁰⁾ + d) − ψ,  α_q = (1 − κ_q) γ_q,  ψ = (1/α_q) Σ_{j=1}^{q} γ_j ∇ʲ y_n,
//!
//! solved by Newton's method with the matrix I − c J, c = h/α_q (E = I/c − J factorised by the
//! right-hand side, the sensitivities' block with it: for an augmented state [y; S] the
//! iteration corrects the states and their sensitivities together, CVODES' simultaneous
//! corrector). The local error is (κ_q γ_q + 1/(q+1)) d; the error norm is the one every
//! scheme shares, sensitivities included.

use crate::control::{MIN_FACTOR, SAFETY};
use crate::interpolant::Interpolant;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::work::Evaluator;

/// The highest order.
pub(crate) const MAX_ORDER: usize = 5;
/// κ_q of the numerical differentiation formulas (Shampine & Reichelt, Table 1); 0 is BDF.
/// Order 5 is BDF5: an NDF of order 5 loses too much stability.
const KAPPA: [f64; MAX_ORDER + 1] = [0.0, -0.1850, -1.0 / 9.0, -0.0823, -0.0415, 0.0];
/// The largest growth of the step in one change. (The smallest ratio after a failed error
/// test, and the safety factor, are the one-step schemes' [`MIN_FACTOR`] and [`SAFETY`].)
const MAX_FACTOR: f64 = 10.0;
/// The step after a Newton iteration that failed with a fresh matrix, as a share of the
/// failed one (CVODE's ETACF).
pub(crate) const DIVERGED_FACTOR: f64 = 0.25;
/// A step grows after a success only when it can grow by at least this factor (CVODE's
/// THRESH): every change of the step re-interpolates the differences, and one of more than
/// 30 % costs a factorisation.
const GROWTH_THRESHOLD: f64 = 1.5;
/// Newton iterations per attempt (CVODE's maxcor).
const NEWTON_ITERATIONS: usize = 3;
/// The iteration stops once its remaining error, as the error estimate would weigh it, is
/// below this share of the tolerance (CVODE's nlscoef).
const NEWTON_SHARE: f64 = 0.1;
/// The matrix is formed again when c = h/α has moved by more than this share since it was
/// formed (CVODE's DGMAX) ...
const MATRIX_DRIFT: f64 = 0.3;
/// ... or after this many steps with it (CVODE's MSBP).
const MATRIX_STEPS: usize = 20;
/// The contraction estimate decays by this factor per iteration (CVODE's CRDOWN).
const RATE_DECAY: f64 = 0.3;
/// An iteration whose correction more than doubles diverges (CVODE's RDIV).
const DIVERGING: f64 = 2.0;

/// γ_q = Σ_{j=1}^{q} 1/j.
fn gamma(q: usize) -> f64 {
    (1..=q).map(|j| 1.0 / j as f64).sum()
}

/// α_q = (1 − κ_q) γ_q.
fn alpha(q: usize) -> f64 {
    (1.0 - KAPPA[q]) * gamma(q)
}

/// The local error of order q per unit of the correction d: κ_q γ_q + 1/(q + 1).
fn error_constant(q: usize) -> f64 {
    KAPPA[q] * gamma(q) + 1.0 / (q + 1) as f64
}

/// What a trial step came to.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Attempt {
    /// The corrector converged; the step's error norm (accepted when ≤ 1).
    Converged(f64),
    /// The Newton iteration failed with a matrix formed for this very step, or f was not
    /// finite: the step must be shorter.
    Diverged,
}

/// The multistep scheme's memory: the backward differences, the order, the step they are
/// for, the factorised matrix's age, and the work vectors of a step.
pub(crate) struct History {
    /// d[j] = ∇ʲ y at the last accepted point for steps of `h`, j ≤ order + 2 (∇^{q+1} and
    /// ∇^{q+2} for the estimates of the next order up).
    d: [Vec<f64>; MAX_ORDER + 3],
    order: usize,
    /// The signed step the differences are for.
    h: f64,
    /// Steps accepted since the step or the order last changed.
    equal_steps: usize,
    /// c = h/α of the factorised matrix, if there is one, and the steps accepted with it.
    factored: Option<f64>,
    steps_with_matrix: usize,
    /// The Newton iteration's contraction estimate, kept from step to step.
    rate: f64,
    /// Consecutive failed error tests of the step under way.
    failures: usize,
    /// The order of the step accepted last, which its interpolant is of.
    accepted_order: usize,
    /// The Newton iterations of the last converged attempt.
    iterations: usize,
    predicted: Vec<f64>,
    psi: Vec<f64>,
    /// The iterate, and after a converged attempt the new solution.
    y: Vec<f64>,
    /// The correction d = y − y⁽⁰⁾.
    correction: Vec<f64>,
    f: Vec<f64>,
    delta: Vec<f64>,
    /// Spare rows for re-expressing the differences.
    rows: Vec<Vec<f64>>,
}

impl History {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            d: std::array::from_fn(|_| vec![0.0; n]),
            order: 1,
            h: 0.0,
            equal_steps: 0,
            factored: None,
            steps_with_matrix: 0,
            rate: 1.0,
            failures: 0,
            accepted_order: 1,
            iterations: 0,
            predicted: vec![0.0; n],
            psi: vec![0.0; n],
            y: vec![0.0; n],
            correction: vec![0.0; n],
            f: vec![0.0; n],
            delta: vec![0.0; n],
            rows: Vec::new(),
        }
    }

    /// Starts at order 1 from x with f = f(t, x) and the signed step h: at the start of an
    /// integration and after every discontinuity, where the past says nothing of the future.
    /// The matrix is formed again at the first step.
    pub(crate) fn start(&mut self, x: &[f64], f: &[f64], h: f64) {
        self.d[0].copy_from_slice(x);
        for (d1, f) in self.d[1].iter_mut().zip(f) {
            *d1 = h * f;
        }
        for d in &mut self.d[2..] {
            d.fill(0.0);
        }
        self.order = 1;
        self.h = h;
        self.equal_steps = 0;
        self.factored = None;
        self.rate = 1.0;
        self.failures = 0;
    }

    /// The signed step the next attempt takes.
    pub(crate) fn h(&self) -> f64 {
        self.h
    }

    /// The solution of the last converged attempt.
    pub(crate) fn solution(&self) -> &[f64] {
        &self.y
    }

    /// Re-expresses the differences for steps of `h` (Shampine & Reichelt's R U: the
    /// differences of the interpolating polynomial at the new spacing).
    pub(crate) fn rescale(&mut self, h: f64) {
        if h.to_bits() == self.h.to_bits() {
            return;
        }
        let q = self.order;
        let weights = rescaling(q, h / self.h);
        // Row by row into spare rows, every pass over contiguous vectors: d'_i = Σ_k w_ik d_k,
        // k = 1..=q (the first row, y itself, maps to itself).
        let n = self.d[0].len();
        let mut new = std::mem::take(&mut self.rows);
        while new.len() < q {
            new.push(vec![0.0; n]);
        }
        for (row, w) in new[..q].iter_mut().zip(&weights[1..=q]) {
            row.fill(0.0);
            for (d, &w) in self.d[1..=q].iter().zip(&w[1..=q]) {
                for (r, d) in row.iter_mut().zip(d) {
                    *r += w * d;
                }
            }
        }
        for (d, row) in self.d[1..=q].iter_mut().zip(&mut new[..q]) {
            std::mem::swap(d, row);
        }
        self.rows = new;
        self.h = h;
        self.equal_steps = 0;
    }

    /// One trial step from t to t + h (h the history's step): the predictor, then Newton's
    /// iteration on the corrector, forming the matrix where there is none, it is old or it was
    /// formed for a step too different, and once more when the iteration fails with an old one.
    pub(crate) fn attempt<R: Rhs>(
        &mut self,
        ev: &mut Evaluator<'_, R>,
        t_new: f64,
    ) -> Result<Attempt, FactorError> {
        let q = self.order;
        let (a, c) = (alpha(q), self.h / alpha(q));
        let n = self.y.len();
        self.predicted.fill(0.0);
        self.psi.fill(0.0);
        for j in 0..=q {
            let g = gamma(j) / a;
            for ((p, s), d) in self.predicted.iter_mut().zip(&mut self.psi).zip(&self.d[j][..n]) {
                *p += d;
                *s += g * d;
            }
        }
        let tolerance = NEWTON_SHARE / error_constant(q);
        loop {
            let fresh = match self.factored {
                None => true,
                Some(formed) => {
                    (c / formed - 1.0).abs() > MATRIX_DRIFT
                        || self.steps_with_matrix >= MATRIX_STEPS
                }
            };
            if fresh {
                let side = ev.side(t_new);
                self.factored = None;
                ev.factor(t_new, side, &self.predicted, 1.0 / c)?;
                self.factored = Some(c);
                self.steps_with_matrix = 0;
                self.rate = 1.0;
            }
            if self.newton(ev, t_new, c, tolerance) {
                break;
            }
            if fresh {
                return Ok(Attempt::Diverged);
            }
            self.factored = None;
        }
        let err = error_constant(q) * ev.error_norm(&self.correction, &self.d[0], &self.y);
        Ok(Attempt::Converged(err))
    }

    /// Newton's iteration on the corrector with the factorised matrix I/c_f − J (c_f the c it
    /// was formed for), from the predictor: whether it converged.
    fn newton<R: Rhs>(
        &mut self,
        ev: &mut Evaluator<'_, R>,
        t_new: f64,
        c: f64,
        tolerance: f64,
    ) -> bool {
        let formed = self.factored.unwrap_or(c);
        // (I − c_f J)⁻¹ = E⁻¹/c_f; with c ≠ c_f the correction is scaled by 2/(1 + c/c_f),
        // which makes up most of the difference (CVODE).
        let scale = (formed.to_bits() != c.to_bits()).then(|| 2.0 / (1.0 + c / formed));
        self.y.copy_from_slice(&self.predicted);
        self.correction.fill(0.0);
        let mut previous = f64::NAN;
        for m in 0..NEWTON_ITERATIONS {
            ev.f(t_new, &self.y, &mut self.f);
            for (((r, f), p), d) in
                self.delta.iter_mut().zip(&self.f).zip(&self.psi).zip(&self.correction)
            {
                *r = (c * f - p - d) / formed;
            }
            ev.solve(&mut self.delta);
            if let Some(scale) = scale {
                self.delta.iter_mut().for_each(|r| *r *= scale);
            }
            let size = ev.error_norm(&self.delta, &self.y, &self.y);
            if !size.is_finite() {
                return false;
            }
            for ((y, d), r) in self.y.iter_mut().zip(&mut self.correction).zip(&self.delta) {
                *y += r;
                *d += r;
            }
            if m > 0 {
                self.rate = (RATE_DECAY * self.rate).max(size / previous);
            }
            if size * self.rate.min(1.0) <= tolerance {
                self.iterations = m + 1;
                return true;
            }
            if m > 0 && size > DIVERGING * previous {
                return false;
            }
            previous = size;
        }
        false
    }

    /// The factor of the step after a failed error test with norm `err` (> 1); from the
    /// second failure in a row the order drops by one as well (CVODE drops it from the
    /// fourth). Whether the history is then to be started afresh at the point
    /// ([`History::start`], with f there): from the second failure in a row at order 1.
    ///
    /// At order 1 the first difference is the last step's secant, whose slope is off by about
    /// h_old·y″/2 however short the new step: the predictor's error, which is the error
    /// estimate, then shrinks only as h, not h², and repeated failures take the step down to
    /// t's resolution (Chen_MSB2009 by `bdf` at rtol 1e-9, atol 1e-13, where an input ramps
    /// from 0 to 1e7 within 0.01 after t = 1799.99, failed so at a step of 5.6e-12). CVODE
    /// reloads its first column from f where failures persist at the first order.
    pub(crate) fn rejected(&mut self, err: f64) -> (f64, bool) {
        self.failures += 1;
        let q = self.order;
        let factor = (safety(self.iterations) * err.powf(-1.0 / (q + 1) as f64)).max(MIN_FACTOR);
        if self.failures >= 2 && q > 1 {
            self.order = q - 1;
        }
        (factor, self.failures >= 2 && self.order == 1)
    }

    /// Takes the converged attempt with error norm `err` as the new point: the differences
    /// move on to it; after q + 1 steps at one step and order, the order among q − 1, q and
    /// q + 1 whose error allows the longest step is taken, and the factor of the step is
    /// returned where it changes.
    pub(crate) fn accept<R: Rhs>(&mut self, ev: &mut Evaluator<'_, R>, err: f64) -> Option<f64> {
        let q = self.order;
        {
            let (low, high) = self.d.split_at_mut(q + 1);
            let (above, beyond) = high.split_at_mut(1);
            for ((e2, e1), d) in beyond[0].iter_mut().zip(&mut above[0]).zip(&self.correction) {
                *e2 = d - *e1;
                *e1 = *d;
            }
            for (v, u) in low[q].iter_mut().zip(&above[0]) {
                *v += u;
            }
            for i in (0..q).rev() {
                let (lower, upper) = low.split_at_mut(i + 1);
                for (v, u) in lower[i].iter_mut().zip(&upper[0]) {
                    *v += u;
                }
            }
        }
        self.accepted_order = q;
        self.failures = 0;
        self.equal_steps += 1;
        self.steps_with_matrix += 1;
        if self.equal_steps <= q {
            return None;
        }
        let norm = |ev: &mut Evaluator<'_, R>, v: &[f64], y: &[f64]| ev.error_norm(v, y, y);
        let y = &self.d[0];
        let below =
            if q > 1 { error_constant(q - 1) * norm(ev, &self.d[q], y) } else { f64::INFINITY };
        let above = if q < MAX_ORDER {
            error_constant(q + 1) * norm(ev, &self.d[q + 2], y)
        } else {
            f64::INFINITY
        };
        let growth = |e: f64, p: usize| e.powf(-1.0 / p as f64);
        let candidates =
            [(q - 1, growth(below, q)), (q, growth(err, q + 1)), (q + 1, growth(above, q + 2))];
        let (order, best) = candidates
            .into_iter()
            .filter(|&(o, _)| (1..=MAX_ORDER).contains(&o))
            .fold((q, 0.0), |b, c| if c.1 > b.1 { c } else { b });
        let factor = (safety(self.iterations) * best).min(MAX_FACTOR);
        if order == q && factor < GROWTH_THRESHOLD {
            return None;
        }
        self.order = order;
        Some(factor)
    }

    /// Fills `out` with the interpolating polynomial of the step just accepted, from t to
    /// t_next: the one through the last q + 1 points at the accepted step's spacing, of
    /// degree q ≤ 5, in the form of [`Interpolant`].
    pub(crate) fn dense(&self, out: &mut Interpolant, t: f64, t_next: f64) {
        let q = self.accepted_order;
        let to_r = dense_map(q);
        let coefficients = out.coefficients6_mut();
        let n = self.d[0].len();
        for (i, r) in coefficients.into_iter().enumerate() {
            let r = &mut r[..n];
            r.fill(0.0);
            for (j, d) in self.d[..=q].iter().enumerate() {
                let w = to_r[i][j];
                if w != 0.0 {
                    for (r, d) in r.iter_mut().zip(&d[..n]) {
                        *r += w * d;
                    }
                }
            }
        }
        out.set_span(t, t_next);
    }
}

/// The safety factor of a new step after an attempt that took `iterations` Newton iterations:
/// [`SAFETY`], less where the iteration was slow (Shampine & Reichelt's rule).
fn safety(iterations: usize) -> f64 {
    let most = NEWTON_ITERATIONS as f64;
    SAFETY * (2.0 * most + 1.0) / (2.0 * most + iterations as f64)
}

/// The weights w of the differences at the step ρh for order q: d'_i = Σ_k w_ik d_k, w the
/// transpose of R(ρ)·U, with R(ρ)_ij = Π_{l=1}^{i} (l − 1 − ρj)/l and U = R(1) (Shampine &
/// Reichelt, section 2.2).
fn rescaling(q: usize, rho: f64) -> [[f64; MAX_ORDER + 1]; MAX_ORDER + 1] {
    let r = |rho: f64| -> [[f64; MAX_ORDER + 1]; MAX_ORDER + 1] {
        let mut m = [[0.0; MAX_ORDER + 1]; MAX_ORDER + 1];
        m[0] = [1.0; MAX_ORDER + 1];
        for i in 1..=q {
            let above = m[i - 1];
            for (j, (v, a)) in m[i].iter_mut().zip(above).enumerate() {
                *v = a * (i as f64 - 1.0 - rho * j as f64) / i as f64;
            }
        }
        m
    };
    let (r, u) = (r(rho), r(1.0));
    std::array::from_fn(|i| std::array::from_fn(|k| (0..=q).map(|m| r[k][m] * u[m][i]).sum()))
}

/// The weights of the differences d_0..d_q in r₁..r₆ of [`Interpolant`]'s form, for the
/// polynomial through the last q + 1 points of a step accepted at order q:
/// p(θ) = Σ_j d_j b_j(θ), b_j(θ) = Π_{m<j} (θ − 1 + m)/(m + 1), θ = 0 at the step's start
/// and 1 at its end (b_j(1) = 0 for j ≥ 1: p(1) = y_{n+1}; p(0) = d_0 − d_1 = y_n).
fn dense_map(q: usize) -> [[f64; MAX_ORDER + 1]; MAX_ORDER + 1] {
    let mut map = [[0.0; MAX_ORDER + 1]; MAX_ORDER + 1];
    for j in 0..=q {
        // b_j's coefficients of θ⁰..θ⁵.
        let mut a = [0.0; MAX_ORDER + 1];
        a[0] = 1.0;
        for m in 0..j {
            let (shift, divisor) = (m as f64 - 1.0, (m + 1) as f64);
            for i in (0..=MAX_ORDER).rev() {
                let lower = if i > 0 { a[i - 1] } else { 0.0 };
                a[i] = (lower + shift * a[i]) / divisor;
            }
        }
        for (row, r) in map.iter_mut().zip(hairer_form(a)) {
            row[j] = r;
        }
    }
    map
}

/// r₁..r₆ with r₁ + θ(r₂ + (1−θ)(r₃ + θ(r₄ + (1−θ)(r₅ + θ r₆)))) = Σ_i a_i θⁱ.
fn hairer_form(a: [f64; MAX_ORDER + 1]) -> [f64; MAX_ORDER + 1] {
    let r6 = a[5];
    let r5 = a[4] + 2.0 * r6;
    let r4 = -a[3] - 2.0 * r5 + r6;
    let r3 = r4 + r5 - a[2];
    let r2 = a[1] - r3;
    [a[0], r2, r3, r4, r5, r6]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A polynomial of degree q with unremarkable coefficients.
    fn polynomial(q: usize) -> impl Fn(f64) -> f64 {
        move |t: f64| (0..=q).map(|i| (0.3 + 0.7 * i as f64) * (t - 0.4).powi(i as i32)).sum()
    }

    /// ∇ʲ p at t for steps of h, j = 0..=q.
    fn differences(p: &impl Fn(f64) -> f64, q: usize, t: f64, h: f64) -> Vec<f64> {
        let mut values: Vec<f64> = (0..=q).map(|m| p(t - m as f64 * h)).collect();
        let mut out = vec![values[0]];
        for _ in 1..=q {
            values = values.windows(2).map(|w| w[0] - w[1]).collect();
            out.push(values[0]);
        }
        out
    }

    fn history(p: &impl Fn(f64) -> f64, q: usize, t: f64, h: f64) -> History {
        let mut history = History::new(1);
        for (j, d) in differences(p, q, t, h).into_iter().enumerate() {
            history.d[j][0] = d;
        }
        (history.order, history.accepted_order, history.h) = (q, q, h);
        history
    }

    /// The differences of a polynomial of degree q, re-expressed for another step, are its
    /// differences at that step: re-interpolation is exact on the polynomials it interpolates.
    #[test]
    fn rescaled_differences_are_those_at_the_new_step() {
        for q in 1..=MAX_ORDER {
            let p = polynomial(q);
            for (h, rho) in [(0.1, 0.25), (0.1, 3.0), (-0.05, 1.7), (0.2, 0.5)] {
                let mut history = history(&p, q, 1.3, h);
                history.rescale(rho * h);
                let expected = differences(&p, q, 1.3, rho * h);
                // Both sides difference values of up to 20: rounding of 1e-14 each, amplified
                // by the cancellation (measured up to 8e-12 at q = 5, ρ = 3).
                for (j, e) in expected.iter().enumerate() {
                    let got = history.d[j][0];
                    assert!((got - e).abs() <= 5e-11, "q {q} ρ {rho} ∇{j}: {got} vs {e}");
                }
            }
        }
    }

    /// The dense output of a step accepted at order q is the polynomial through the last
    /// q + 1 points: it reproduces a polynomial of degree q anywhere on the step, in the form
    /// of [`Interpolant`] (r₆ included from order 5).
    #[test]
    fn the_dense_output_is_the_interpolating_polynomial() {
        for q in 1..=MAX_ORDER {
            let p = polynomial(q);
            let (t_next, h) = (1.3, 0.1);
            let history = history(&p, q, t_next, h);
            let mut interpolant = Interpolant::new(1);
            history.dense(&mut interpolant, t_next - h, t_next);
            for s in [0.0, 0.1, 0.37, 0.5, 0.9, 1.0].map(|theta| t_next - h + theta * h) {
                let mut out = [0.0];
                interpolant.eval(s, &mut out);
                assert!((out[0] - p(s)).abs() <= 1e-12 * (1.0 + p(s).abs()), "q {q} at {s}");
            }
        }
    }

    /// With κ = 0 the formulas are the BDFs: BDF2's y_{n+1} − (4/3) y_n + (1/3) y_{n−1} =
    /// (2/3) h f has c = h/α₂ = 2h/3 and error constant 1/3; the NDFs' constants are
    /// Shampine & Reichelt's (Table 1: 1/2 − 0.1850, ..., and BDF5's 1/6).
    #[test]
    fn the_formulas_constants() {
        assert!((gamma(2) - 1.5).abs() < 1e-15);
        assert!((1.5 * (1.0 - KAPPA[2]) - alpha(2)).abs() < 1e-15);
        assert!((error_constant(1) - (0.5 - 0.1850)).abs() < 1e-15);
        assert!((error_constant(5) - 1.0 / 6.0).abs() < 1e-15);
        for q in 1..=MAX_ORDER {
            assert!(error_constant(q) > 0.0 && alpha(q) > 0.0);
        }
    }
}
