//! The integration loop: segments between discontinuities, direction, the step budget,
//! accepting and rejecting steps by the scheme's controller, the automatic switches between
//! DOPRI5 and Rodas5P, and one interpolant per accepted step. Schemes are reached only
//! through [`Stepper`].

use crate::bdf::{Attempt, DIVERGED_FACTOR, History};
use crate::control::{Control, MIN_FACTOR, initial_step_of_order};
use crate::counts::Counts;
use crate::dop853::{self, Dop853};
use crate::dopri5::Dopri5;
use crate::error::{BLOW_UP_GROWTH, OdeError};
use crate::interpolant::Interpolant;
use crate::lu::FactorError;
use crate::options::{AUTO_DOP853_RTOL, Integrator, Scheme};
use crate::rhs::Rhs;
use crate::rk4::Rk4;
use crate::rodas4::Rodas4;
use crate::rodas5p::Rodas5p;
use crate::stepper::Stepper;
use crate::stiffness::{
    EXPLICIT_H_LAMBDA, EXPLICIT_REFRESHES, SPECTRAL_EVERY, SPECTRAL_STIFF_H_LAMBDA, STIFF_H_LAMBDA,
    SpectralRadius, Stiffness,
};
use crate::work::{Evaluator, Work, state_floors};

/// Integrates dx/dt = f(t, x) from (t0, x0) to t_end (either direction), stopping exactly on
/// every time in `stops` strictly between them, and calls `on_step` with the interpolant of
/// each accepted step, in the order they are taken. Returns the work done and x(t_end).
pub fn integrate<R: Rhs>(
    cfg: &Integrator,
    rhs: &mut R,
    (t0, x0): (f64, &[f64]),
    t_end: f64,
    stops: &[f64],
    on_step: impl FnMut(&Interpolant),
) -> Result<(Counts, Vec<f64>), OdeError> {
    integrate_selected(cfg, rhs, (t0, x0), t_end, stops, |_, _| true, on_step)
}

/// [`integrate`], handing `on_step` only the steps from t to t_next for which
/// `wants(t, t_next)` holds: the others' interpolants are never formed (sampling at a
/// hundred output times needs one step in five on van der Pol).
pub(crate) fn integrate_selected<R: Rhs>(
    cfg: &Integrator,
    rhs: &mut R,
    (t0, x0): (f64, &[f64]),
    t_end: f64,
    stops: &[f64],
    wants: impl FnMut(f64, f64) -> bool,
    on_step: impl FnMut(&Interpolant),
) -> Result<(Counts, Vec<f64>), OdeError> {
    run_from(cfg, rhs, (t0, x0), t_end, stops, (wants, on_step), false).map(|(c, x, _)| (c, x))
}

/// [`integrate`] for one of the consecutive parts of an integration that restarts between
/// them (the adjoint's, at every sample): under the automatic choice the part starts with
/// Rodas5P where `stiff` says the part before it ended with Rodas5P, rather than spend
/// fifteen or more DOPRI5 steps finding the stiffness again (the restart changes the state,
/// not the Jacobian); `stiff` is then whether this part ended with Rodas5P.
pub(crate) fn integrate_part<R: Rhs>(
    cfg: &Integrator,
    rhs: &mut R,
    (t0, x0): (f64, &[f64]),
    t_end: f64,
    stops: &[f64],
    stiff: &mut bool,
) -> Result<(Counts, Vec<f64>), OdeError> {
    // No one reads the parts' interpolants: none is formed.
    let no_step = (|_: f64, _: f64| false, |_: &Interpolant| {});
    let (counts, x, ended_stiff) = run_from(cfg, rhs, (t0, x0), t_end, stops, no_step, *stiff)?;
    *stiff = ended_stiff;
    Ok((counts, x))
}

/// [`integrate_selected`], starting with Rodas5P under the automatic choice where `stiff`
/// (and the right-hand side has a Jacobian to factorise); also whether it ended with
/// Rodas5P.
fn run_from<R: Rhs>(
    cfg: &Integrator,
    rhs: &mut R,
    (t0, x0): (f64, &[f64]),
    t_end: f64,
    stops: &[f64],
    (wants, on_step): (impl FnMut(f64, f64) -> bool, impl FnMut(&Interpolant)),
    stiff: bool,
) -> Result<(Counts, Vec<f64>, bool), OdeError> {
    check_inputs(cfg, rhs, (t0, x0), t_end)?;
    if rhs.n_events() > 0 && cfg.scheme == Scheme::Bdf {
        return Err(OdeError::InvalidSetup(
            "the model's state events are located by the one-step schemes only, not by bdf (use rodas5p or auto)".into(),
        ));
    }
    if rhs.n_events() > 0 && t_end < t0 {
        return Err(OdeError::InvalidSetup(format!(
            "the model's state events fire integrating forward in time only, not from {t0} back to {t_end}"
        )));
    }
    let mut run = Run::new(cfg, rhs, (t0, x0), t_end, wants, on_step);
    if t_end - t0 == 0.0 {
        return Ok((run.ev.counts, x0.to_vec(), stiff));
    }
    if stiff && cfg.scheme == Scheme::Auto {
        run.start_implicit();
    }
    let ends = segment_ends(t0, t_end, stops);
    // t0 and t_end may be stops themselves (a switch at the last measurement): stages there
    // take the right-hand side from inside, as at the stops between.
    let at_stop = |t: f64| stops.iter().any(|&s| (s - t).abs() <= resolution(t));
    let (from_stop, to_stop) = (at_stop(t0), at_stop(t_end));
    for (i, &seg_end) in ends.iter().enumerate() {
        if i > 0 {
            let dir = run.dir;
            run.ev.rhs.cross(ends[i - 1], &mut run.work.x, dir);
        }
        let last = i + 1 == ends.len();
        run.segment(seg_end, (i > 0 || from_stop, !last || to_stop))?;
    }
    let ended_stiff = matches!(run.stepper, Active::Rodas5p);
    Ok((run.ev.counts, run.work.x, ended_stiff))
}

/// Rejects what no integration can start from: an initial state of the wrong length, invalid
/// settings, non-finite ends or initial values.
fn check_inputs<R: Rhs>(
    cfg: &Integrator,
    rhs: &R,
    (t0, x0): (f64, &[f64]),
    t_end: f64,
) -> Result<(), OdeError> {
    let n = rhs.dim();
    if x0.len() != n {
        return Err(OdeError::Dimension { what: "initial state", actual: x0.len(), expected: n });
    }
    cfg.validate().map_err(|e| OdeError::InvalidSetup(e.to_string()))?;
    for (what, v) in [("t0", t0), ("t_end", t_end)] {
        if !v.is_finite() {
            return Err(OdeError::InvalidInput { what: what.into(), value: v });
        }
    }
    if let Some(i) = x0.iter().position(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite { t: t0, what: format!("initial {}", rhs.describe(i)) });
    }
    Ok(())
}

/// How close to t a stop is merged with it: no step fits in between.
pub(crate) fn resolution(t: f64) -> f64 {
    64.0 * f64::EPSILON * t.abs().max(1.0)
}

/// Segment ends in the direction of integration, t_end last: the stops strictly between t0
/// and t_end, except those too close to either to take a step in between (merged with it).
fn segment_ends(t0: f64, t_end: f64, stops: &[f64]) -> Vec<f64> {
    let dir = (t_end - t0).signum();
    let mut ends: Vec<f64> = stops
        .iter()
        .copied()
        .filter(|&s| (s - t0) * dir > resolution(t0) && (t_end - s) * dir > resolution(t_end))
        .collect();
    if dir < 0.0 {
        ends.reverse();
    }
    ends.push(t_end);
    ends
}

/// The scheme stepping now. An enum rather than `dyn Stepper`: the loop calls it at every
/// step, and static dispatch lets the scheme's stages inline into the loop (a trait object
/// cost 5–15 % of an integration's time in the `ode` bench).
#[derive(Clone, Copy, Debug)]
enum Active {
    Dopri5,
    Dop853,
    Rk4,
    Rodas4,
    Rodas5p,
}

impl Active {
    /// The scheme that steps first for `scheme` (the automatic choice starts with DOPRI5):
    /// the one place a [`Scheme`] is mapped to its [`Stepper`]. The multistep scheme keeps
    /// a history no one-step [`Stepper`] has and steps in its own loop
    /// ([`Run::multistep_segment`]); its integration never steps with the one named here.
    fn first(cfg: &Integrator) -> Self {
        match cfg.scheme {
            Scheme::Auto => Self::explicit(cfg),
            Scheme::Dopri5 => Self::Dopri5,
            Scheme::Dop853 => Self::Dop853,
            Scheme::Rk4 => Self::Rk4,
            Scheme::Rodas4 => Self::Rodas4,
            Scheme::Rodas5p | Scheme::Bdf => Self::Rodas5p,
        }
    }

    /// The automatic choice's explicit scheme: DOP853 at rtol ≤ [`AUTO_DOP853_RTOL`], DOPRI5
    /// above.
    fn explicit(cfg: &Integrator) -> Self {
        if cfg.rtol <= AUTO_DOP853_RTOL { Self::Dop853 } else { Self::Dopri5 }
    }
}

impl<R: Rhs> Stepper<R> for Active {
    #[inline]
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError> {
        match self {
            Self::Dopri5 => Dopri5.step(ev, w, t, h),
            Self::Dop853 => Dop853.step(ev, w, t, h),
            Self::Rk4 => Rk4.step(ev, w, t, h),
            Self::Rodas4 => Rodas4.step(ev, w, t, h),
            Self::Rodas5p => Rodas5p.step(ev, w, t, h),
        }
    }

    #[inline]
    fn dense(&self, ev: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64) {
        match self {
            Self::Dopri5 => Dopri5.dense(ev, w, t, t_next),
            Self::Dop853 => Dop853.dense(ev, w, t, t_next),
            Self::Rk4 => Rk4.dense(ev, w, t, t_next),
            Self::Rodas4 => Rodas4.dense(ev, w, t, t_next),
            Self::Rodas5p => Rodas5p.dense(ev, w, t, t_next),
        }
    }

    fn control(&self) -> Option<Control> {
        match self {
            Self::Dopri5 => <Dopri5 as Stepper<R>>::control(&Dopri5),
            Self::Dop853 => <Dop853 as Stepper<R>>::control(&Dop853),
            Self::Rk4 => <Rk4 as Stepper<R>>::control(&Rk4),
            Self::Rodas4 => <Rodas4 as Stepper<R>>::control(&Rodas4),
            Self::Rodas5p => <Rodas5p as Stepper<R>>::control(&Rodas5p),
        }
    }

    fn stiffness_estimate(&self, w: &Work, h: f64) -> Option<f64> {
        match self {
            Self::Dopri5 => <Dopri5 as Stepper<R>>::stiffness_estimate(&Dopri5, w, h),
            Self::Dop853 => <Dop853 as Stepper<R>>::stiffness_estimate(&Dop853, w, h),
            Self::Rk4 => <Rk4 as Stepper<R>>::stiffness_estimate(&Rk4, w, h),
            Self::Rodas4 => <Rodas4 as Stepper<R>>::stiffness_estimate(&Rodas4, w, h),
            Self::Rodas5p => <Rodas5p as Stepper<R>>::stiffness_estimate(&Rodas5p, w, h),
        }
    }
}

/// One integration under way: where it is, the scheme stepping, the step-size controller's
/// memory, the stiffness test, and where accepted steps go.
struct Run<'r, R: Rhs, W, O> {
    ev: Evaluator<'r, R>,
    work: Work,
    /// The scheme stepping now: `auto` starts explicit, may switch to Rodas5P and back.
    stepper: Active,
    t: f64,
    t_end: f64,
    /// The direction of integration, ±1.
    dir: f64,
    /// The next trial step size (a magnitude); 0 until the first adaptive segment chooses it.
    h: f64,
    /// ln of the previous accepted error (Hairer's facold, at least 1e-4).
    ln_err_old: f64,
    /// The largest magnitude at the start (at least 1): what a blow-up is measured against.
    start: f64,
    stiffness: Stiffness,
    /// The automatic choice's estimate of the Jacobian's dominant eigenvalue.
    spectral: SpectralRadius,
    /// Where DOPRI5's stiffness test fired, if it did and the scheme stays explicit.
    stiff_since: Option<f64>,
    /// Refreshes of [`SpectralRadius`] in a row, while `auto` steps with Rodas5P, at which
    /// DOPRI5 would be stable with a margin ([`Run::observe_non_stiffness`]).
    explicit_again: u32,
    wants: W,
    on_step: O,
    /// The state events' conditions at t ([`Rhs::event_conditions`]; empty without events),
    /// and at the end of the trial step.
    conditions: Vec<f64>,
    conditions_next: Vec<f64>,
    /// The state at a time inside a step, where an event is being located.
    inside: Vec<f64>,
    /// The multistep scheme's differences and matrix age, once it has stepped.
    multistep: Option<Box<History>>,
}

impl<'r, R: Rhs, W: FnMut(f64, f64) -> bool, O: FnMut(&Interpolant)> Run<'r, R, W, O> {
    fn new(
        cfg: &Integrator,
        rhs: &'r mut R,
        (t0, x0): (f64, &[f64]),
        t_end: f64,
        wants: W,
        on_step: O,
    ) -> Self {
        let stepper = Active::first(cfg);
        let more = if matches!(stepper, Active::Dop853) { dop853::MORE } else { 0 };
        let mut work = Work::new(x0.len(), more);
        work.x.copy_from_slice(x0);
        let counts = Counts { integrations: 1, ..Counts::default() };
        let events = rhs.n_events();
        let states = if events > 0 { rhs.states() } else { 0 };
        let own = state_floors(cfg, rhs, x0);
        Self {
            conditions: vec![0.0; events],
            conditions_next: vec![0.0; events],
            inside: vec![0.0; states],
            ev: Evaluator {
                costs: rhs.costs(),
                rhs,
                cfg: *cfg,
                counts,
                seg: (t0, t_end),
                stops: (false, false),
                floors: Vec::new(),
                relative: Vec::new(),
                state_floors: own,
            },
            work,
            stepper,
            t: t0,
            t_end,
            dir: (t_end - t0).signum(),
            h: cfg.initial_step.unwrap_or(0.0).abs(),
            ln_err_old: 1e-4f64.ln(),
            start: x0.iter().fold(1.0f64, |m, v| m.max(v.abs())),
            stiffness: Stiffness::default(),
            spectral: SpectralRadius::default(),
            stiff_since: None,
            explicit_again: 0,
            wants,
            on_step,
            multistep: None,
        }
    }

    /// Starts with Rodas5P, as the automatic choice switches to it (if the right-hand side
    /// has a Jacobian to factorise at the start).
    fn start_implicit(&mut self) {
        let t = self.t;
        if self.ev.factor(t, self.ev.side(t), &self.work.x, 1.0).is_ok() {
            self.stepper = Active::Rodas5p;
        }
    }

    /// Integrates from t to `seg_end`, inside which the right-hand side is smooth; `stops`
    /// says whether t and `seg_end` are stops (discontinuities or switches).
    fn segment(&mut self, seg_end: f64, stops: (bool, bool)) -> Result<(), OdeError> {
        self.ev.seg = (self.t, seg_end);
        self.ev.stops = stops;
        // A fresh first stage: there is none yet at t0, and at a discontinuity the last step's
        // f(t, x) is the limit from the other side.
        self.ev.f(self.t, &self.work.x, &mut self.work.k[0]);
        self.update_conditions();
        match self.ev.cfg.fixed_step {
            Some(fixed) => self.fixed_segment(fixed, seg_end),
            None if self.ev.cfg.scheme == Scheme::Bdf => self.multistep_segment(seg_end),
            None => self.adaptive_segment(seg_end),
        }
    }

    /// Equal steps of at most `fixed` across the segment, without error control.
    fn fixed_segment(&mut self, fixed: f64, seg_end: f64) -> Result<(), OdeError> {
        let length = seg_end - self.t;
        let count = ((length.abs() / fixed) - 1e-9).ceil().max(1.0) as usize;
        let hs = length / count as f64;
        for i in 0..count {
            self.check_budget()?;
            let t = self.t;
            let t_next = if i + 1 == count { seg_end } else { t + hs };
            // Events inside the step split it: the step is retaken to each one's time.
            while self.t.to_bits() != t_next.to_bits() {
                let t = self.t;
                self.stepper
                    .step(&mut self.ev, &mut self.work, t, t_next - t)
                    .map_err(|e| implicit_error(e, t))?;
                let crossed = self.events_in_step(t_next);
                if crossed.is_empty() {
                    self.accept(t_next)?;
                    continue;
                }
                let Some(tau) = self.step_to_event(&crossed, t_next)? else {
                    return Err(OdeError::InvalidSetup(format!(
                        "the step to an event at {} failed",
                        crossed[0].1
                    )));
                };
                // No step fits between the event and the step's end: it ends there.
                if (t_next - tau).abs() <= resolution(t_next) {
                    self.t = t_next;
                }
            }
        }
        Ok(())
    }

    /// Error-controlled steps to the end of the segment, the last landing on it exactly.
    fn adaptive_segment(&mut self, seg_end: f64) -> Result<(), OdeError> {
        if self.h == 0.0 {
            let order = <Active as Stepper<R>>::first_step_order(&self.stepper);
            self.h = initial_step_of_order(&mut self.ev, &mut self.work, self.t, self.dir, order);
        }
        let mut last_rejected = false;
        // The component that was NaN or infinite in the last rejected trial step, if any:
        // when the step size then underflows, that is the reason to report.
        let mut non_finite: Option<usize> = None;
        loop {
            self.check_budget()?;
            let remaining = seg_end - self.t;
            let mut hs = self.h.min(self.ev.cfg.max_step);
            let lands = hs * 1.01 >= remaining.abs();
            if lands {
                hs = remaining.abs();
            }
            self.check_step_size(hs, non_finite)?;
            let t_next = if lands { seg_end } else { self.t + self.dir * hs };
            let err = self.trial_step(t_next)?;
            if !err.is_finite() {
                // The trial step left the region where f is defined: retry much shorter.
                self.ev.counts.rejected_steps += 1;
                self.h = hs * MIN_FACTOR;
                last_rejected = true;
                non_finite = Some(self.first_non_finite());
                continue;
            }
            non_finite = None;
            let ln_err = err.max(f64::MIN_POSITIVE).ln();
            if err > 1.0 {
                self.ev.counts.rejected_steps += 1;
                self.h = hs / self.control().rejected(ln_err);
                last_rejected = true;
                continue;
            }
            let crossed = self.events_in_step(t_next);
            if !crossed.is_empty() {
                // An event inside the step: retaken to land on it, then started afresh.
                match self.step_to_event(&crossed, t_next)? {
                    None => {
                        self.ev.counts.rejected_steps += 1;
                        self.h = 0.5 * (crossed[0].1 - self.t).abs();
                        last_rejected = true;
                    }
                    // An event too close to the segment's end for a step in between: the
                    // segment ends there, its state the one after the event.
                    Some(tau) if (seg_end - tau).abs() <= resolution(seg_end) => {
                        self.t = seg_end;
                        return Ok(());
                    }
                    Some(_) => last_rejected = false,
                }
                continue;
            }
            let h_lambda = self.stiffness_estimate(hs);
            self.accept(t_next)?;
            self.next_step_size(hs, ln_err, last_rejected);
            last_rejected = false;
            if let Some(h_lambda) = h_lambda {
                self.observe_stiffness(h_lambda, hs);
            } else if matches!(self.stepper, Active::Rodas5p) && self.ev.cfg.scheme == Scheme::Auto
            {
                self.observe_non_stiffness(hs);
            }
            if lands {
                return Ok(());
            }
        }
    }

    /// The multistep scheme's steps to the end of the segment, started afresh at order 1
    /// (at a discontinuity the past says nothing of what follows), the last landing on it.
    fn multistep_segment(&mut self, seg_end: f64) -> Result<(), OdeError> {
        let n = self.work.x.len();
        let mut history = self.multistep.take().unwrap_or_else(|| Box::new(History::new(n)));
        let done = self.multistep_steps(&mut history, seg_end);
        self.multistep = Some(history);
        done
    }

    fn multistep_steps(&mut self, history: &mut History, seg_end: f64) -> Result<(), OdeError> {
        if self.h == 0.0 {
            self.h = initial_step_of_order(&mut self.ev, &mut self.work, self.t, self.dir, 1);
        }
        let max_step = self.ev.cfg.max_step;
        history.start(&self.work.x, &self.work.k[0], self.dir * self.h.min(max_step));
        loop {
            self.check_budget()?;
            let remaining = seg_end - self.t;
            let mut hs = history.h().abs().min(max_step);
            let lands = hs * 1.01 >= remaining.abs();
            if lands {
                hs = remaining.abs();
            }
            self.check_step_size(hs, None)?;
            history.rescale(self.dir * hs);
            let t_next = if lands { seg_end } else { self.t + self.dir * hs };
            let attempt = match history.attempt(&mut self.ev, t_next) {
                Ok(attempt) => attempt,
                Err(FactorError::Singular) => Attempt::Diverged,
                Err(e) => return Err(implicit_error(e, self.t)),
            };
            let err = match attempt {
                Attempt::Converged(err) if err <= 1.0 => err,
                Attempt::Converged(err) => {
                    self.ev.counts.rejected_steps += 1;
                    let (factor, afresh) = history.rejected(err);
                    if afresh {
                        self.ev.f(self.t, &self.work.x, &mut self.work.k[0]);
                        history.start(&self.work.x, &self.work.k[0], self.dir * hs * factor);
                    } else {
                        history.rescale(self.dir * hs * factor);
                    }
                    continue;
                }
                Attempt::Diverged => {
                    self.ev.counts.rejected_steps += 1;
                    history.rescale(self.dir * hs * DIVERGED_FACTOR);
                    continue;
                }
            };
            let factor = history.accept(&mut self.ev, err);
            self.work.x_new.copy_from_slice(history.solution());
            self.accept_with(t_next, |_, w, t, t_next| {
                history.dense(&mut w.interpolant, t, t_next)
            })?;
            if let Some(factor) = factor {
                history.rescale(self.dir * hs * factor);
            }
            self.h = history.h().abs();
            if lands {
                return Ok(());
            }
        }
    }

    /// Fails once accepted and rejected steps together reach the budget: as `Stiff` where
    /// DOPRI5's stiffness test has fired, the likely reason.
    fn check_budget(&self) -> Result<(), OdeError> {
        let (steps, t) = (self.ev.cfg.max_steps, self.t);
        if ((self.ev.counts.steps + self.ev.counts.rejected_steps) as usize) < steps {
            return Ok(());
        }
        let e = match self.stiff_since {
            Some(since) => OdeError::Stiff { t, since, steps },
            None => OdeError::TooManySteps { t, t_end: self.t_end, steps },
        };
        Err(self.explain(e, t, &self.work.x))
    }

    /// Hairer's test: fails when a step of `hs` no longer changes t in floating point, giving
    /// as the reason the component that was non-finite in the last rejected trial, if any.
    fn check_step_size(&self, hs: f64, non_finite: Option<usize>) -> Result<(), OdeError> {
        let t = self.t;
        if hs <= 16.0 * f64::EPSILON * t.abs() || hs < f64::MIN_POSITIVE {
            let e = match non_finite {
                Some(i) => OdeError::NonFinite { t, what: self.ev.rhs.describe(i) },
                None => OdeError::StepSizeTooSmall { t, h: hs * self.dir },
            };
            return Err(self.explain(e, t, &self.work.x));
        }
        Ok(())
    }

    /// A trial step from t to t_next and its error norm: NaN (reject, retry shorter) for a
    /// singular iteration matrix, which a shorter step changes.
    fn trial_step(&mut self, t_next: f64) -> Result<f64, OdeError> {
        let t = self.t;
        match self.stepper.step(&mut self.ev, &mut self.work, t, t_next - t) {
            Ok(err) => Ok(err),
            Err(FactorError::Singular) => Ok(f64::NAN),
            Err(e) => Err(implicit_error(e, t)),
        }
    }

    /// The component whose new value or last-stage derivative is not finite after a failed
    /// trial step; 0 when both are finite (an inner stage or a singular matrix failed).
    fn first_non_finite(&self) -> usize {
        let n = self.work.x.len();
        let w = &self.work;
        w.x_new.iter().chain(&w.k[6]).position(|v| !v.is_finite()).map_or(0, |i| i % n)
    }

    /// The step-size controller of the scheme stepping now.
    fn control(&self) -> Control {
        <Active as Stepper<R>>::control(&self.stepper).expect(
            "Integrator::validate allows schemes without error control only with a fixed step",
        )
    }

    /// The next trial step after accepting one of size `hs`: as the controller says, but no
    /// larger right after a rejection (Hairer).
    fn next_step_size(&mut self, hs: f64, ln_err: f64, last_rejected: bool) {
        let fac = self.control().accepted(ln_err, self.ln_err_old);
        self.ln_err_old = ln_err.max(1e-4f64.ln());
        self.h = hs / fac;
        if last_rejected {
            self.h = self.h.min(hs);
        }
    }

    /// The scheme's h·λ for the trial step just taken, when the stiffness test is due and
    /// the scheme gives one.
    fn stiffness_estimate(&self, hs: f64) -> Option<f64> {
        let every_step = self.ev.cfg.scheme == Scheme::Auto;
        if !self.stiffness.due(every_step, self.ev.counts.steps) {
            return None;
        }
        <Active as Stepper<R>>::stiffness_estimate(&self.stepper, &self.work, hs)
    }

    /// Records an accepted step's h·λ. Once the test fires, the automatic choice switches to
    /// Rodas5P (if the right-hand side has a Jacobian to factorise); any other choice notes
    /// where, to explain a step budget that runs out later.
    ///
    /// The automatic choice also counts a step as stiff where h times the Jacobian's spectral
    /// radius ([`SpectralRadius`], refreshed every [`SPECTRAL_EVERY`] accepted steps) exceeds
    /// [`SPECTRAL_STIFF_H_LAMBDA`].
    fn observe_stiffness(&mut self, h_lambda: f64, h: f64) {
        let auto = self.ev.cfg.scheme == Scheme::Auto;
        let mut h_lambda = h_lambda;
        if auto && matches!(self.stepper, Active::Dopri5 | Active::Dop853) {
            self.refresh_spectral(h);
            // On the scale of Hairer's threshold, which the test applies to both.
            let spectral =
                h.abs() * self.spectral.radius * STIFF_H_LAMBDA / SPECTRAL_STIFF_H_LAMBDA;
            h_lambda = h_lambda.max(spectral);
        }
        if !self.stiffness.observe(h_lambda) {
            return;
        }
        let t = self.t;
        if auto && self.ev.factor(t, self.ev.side(t), &self.work.x, 1.0).is_ok() {
            self.stepper = Active::Rodas5p;
        } else {
            self.stiff_since.get_or_insert(t);
        }
    }

    /// While the automatic choice steps with Rodas5P: every [`SPECTRAL_EVERY`] accepted steps
    /// h·|λ|max by [`SpectralRadius`], and after [`EXPLICIT_REFRESHES`] refreshes in a row
    /// below [`EXPLICIT_H_LAMBDA`] back to DOPRI5, whose step costs a few right-hand sides
    /// where Rodas5P's costs eight, a Jacobian and a factorisation: a model stiff only for a
    /// while (a fast transient at the start, a switch) is not integrated implicitly to its
    /// end. The margin below DOPRI5's stability boundary (3.3) keeps the two tests from
    /// switching back and forth at every refresh.
    fn observe_non_stiffness(&mut self, h: f64) {
        if !self.refresh_spectral(h) {
            return;
        }
        if h.abs() * self.spectral.radius < EXPLICIT_H_LAMBDA {
            self.explicit_again += 1;
        } else {
            self.explicit_again = 0;
        }
        if self.explicit_again >= EXPLICIT_REFRESHES {
            self.explicit_again = 0;
            self.stiffness = Stiffness::default();
            self.stepper = Active::explicit(&self.ev.cfg);
            // The explicit schemes' first stage is f(t, x) in k[0], which a Rodas5P step does not
            // leave behind.
            self.ev.f(self.t, &self.work.x, &mut self.work.k[0]);
        }
    }

    /// One power iteration of [`SpectralRadius`] at (t, x) after a step of `h`, every
    /// [`SPECTRAL_EVERY`] accepted steps; whether it was due.
    fn refresh_spectral(&mut self, h: f64) -> bool {
        if !self.ev.counts.steps.is_multiple_of(SPECTRAL_EVERY) {
            return false;
        }
        let (t, states) = (self.t, self.ev.rhs.states());
        let ev = &mut self.ev;
        self.spectral.refresh(&self.work.x, states, h, |x, dx| ev.f(t, x, dx));
        true
    }

    /// Accepts the step from t to t_next held in `work`: interpolant and callback (if
    /// wanted), advance.
    fn accept(&mut self, t_next: f64) -> Result<(), OdeError> {
        let stepper = self.stepper;
        self.accept_with(t_next, |ev, w, t, t_next| {
            <Active as Stepper<R>>::dense(&stepper, ev, w, t, t_next)
        })
    }

    /// [`accept`](Self::accept), the interpolant formed by `dense`.
    fn accept_with(
        &mut self,
        t_next: f64,
        dense: impl FnOnce(&mut Evaluator<'r, R>, &mut Work, f64, f64),
    ) -> Result<(), OdeError> {
        let t = self.t;
        if let Some(i) = self.work.x_new.iter().position(|v| !v.is_finite()) {
            let e = OdeError::NonFinite { t, what: self.ev.rhs.describe(i) };
            return Err(self.explain(e, t_next, &self.work.x_new));
        }
        self.ev.counts.steps += 1;
        if (self.wants)(t, t_next) {
            dense(&mut self.ev, &mut self.work, t, t_next);
            (self.on_step)(&self.work.interpolant);
        }
        std::mem::swap(&mut self.work.x, &mut self.work.x_new);
        // The explicit schemes' last stage is f(t_next, x_next): the next step's first.
        self.work.k.swap(0, 6);
        self.t = t_next;
        std::mem::swap(&mut self.conditions, &mut self.conditions_next);
        Ok(())
    }

    /// The events' conditions at the current (t, x), where there are events.
    fn update_conditions(&mut self) {
        if !self.conditions.is_empty() {
            let states = self.ev.rhs.states();
            self.ev.rhs.event_conditions(self.t, &self.work.x[..states], &mut self.conditions);
        }
    }

    /// The events whose condition falls from positive to zero or below in the trial step
    /// from t to t_next (in `work`), each with the time it does so, located on the step's
    /// interpolant: those at the earliest such time τ (within the time's resolution), in
    /// order, τ first. Empty without such an event; then the conditions at t_next are kept
    /// for the step's acceptance.
    fn events_in_step(&mut self, t_next: f64) -> Vec<(usize, f64)> {
        if self.conditions.is_empty() {
            return Vec::new();
        }
        let (t, states) = (self.t, self.ev.rhs.states());
        let next = &mut self.conditions_next;
        self.ev.rhs.event_conditions(t_next, &self.work.x_new[..states], next);
        let falls = |i: usize| self.conditions[i] > 0.0 && next[i] <= 0.0;
        if !(0..next.len()).any(falls) {
            return Vec::new();
        }
        let falling: Vec<usize> = (0..next.len()).filter(|&i| falls(i)).collect();
        <Active as Stepper<R>>::dense(&self.stepper, &mut self.ev, &mut self.work, t, t_next);
        let mut all = vec![0.0; self.conditions.len()];
        let mut located: Vec<(usize, f64)> = falling
            .into_iter()
            .map(|i| {
                let (rhs, inside, interpolant) =
                    (&mut *self.ev.rhs, &mut self.inside, &self.work.interpolant);
                let mut condition = |s: f64| {
                    interpolant.eval_range(s, 0, inside);
                    rhs.event_conditions(s, inside, &mut all);
                    all[i]
                };
                let ends = (self.conditions[i], self.conditions_next[i]);
                (i, crate::events::locate(&mut condition, (t, t_next), ends))
            })
            .collect();
        let first = located.iter().map(|e| e.1).fold(t_next, f64::min);
        located.retain(|e| e.1 - first <= resolution(first));
        for e in &mut located {
            e.1 = first;
        }
        located
    }

    /// Fires the events `crossed` (found by [`events_in_step`](Self::events_in_step)) at
    /// their time τ: the trial step to t_next is retaken to land on τ and accepted, x jumps
    /// there, and the integration starts afresh. None, with nothing accepted, when the
    /// retaken step fails its error test.
    fn step_to_event(
        &mut self,
        crossed: &[(usize, f64)],
        t_next: f64,
    ) -> Result<Option<f64>, OdeError> {
        let tau = crossed[0].1;
        if tau.to_bits() == t_next.to_bits() {
            self.accept(t_next)?;
        } else if (tau - self.t).abs() > resolution(self.t) {
            let err = self.trial_step(tau)?;
            let passed = err <= 1.0;
            if !passed && self.ev.cfg.fixed_step.is_none() {
                return Ok(None);
            }
            self.accept(tau)?;
        }
        // The step lands on τ as located on the trial step's interpolant, to rounding and to
        // the step's error: the condition there may still be a hair above 0.
        let states = self.ev.rhs.states();
        let mut landed = vec![0.0; self.conditions.len()];
        self.ev.rhs.event_conditions(tau, &self.work.x[..states], &mut landed);
        for &(i, _) in crossed {
            self.ev.rhs.fire(i, tau, &mut self.work.x);
        }
        if let Some(i) = self.work.x.iter().position(|v| !v.is_finite()) {
            let e = OdeError::NonFinite { t: tau, what: self.ev.rhs.describe(i) };
            return Err(self.explain(e, tau, &self.work.x));
        }
        self.t = tau;
        self.ev.f(tau, &self.work.x, &mut self.work.k[0]);
        self.update_conditions();
        // A fired event's condition counts from 0 after it, less what the reset moved it by:
        // a reset that leaves it alone must not leave it a hair above 0, or the event would
        // fire again as soon as the condition falls on (a second halving where one was due).
        for &(i, _) in crossed {
            self.conditions[i] -= landed[i].max(0.0);
        }
        Ok(Some(tau))
    }

    /// The error to report for a failed integration whose state at t is x: a blow-up when a
    /// component overflowed or grew beyond [`BLOW_UP_GROWTH`] times `start`, `e` otherwise.
    fn explain(&self, e: OdeError, t: f64, x: &[f64]) -> OdeError {
        let start = self.start;
        let largest = |from: usize, to: usize| {
            (from..to.min(x.len()))
                .filter(|&i| !x[i].is_nan())
                .max_by(|&a, &b| x[a].abs().total_cmp(&x[b].abs()))
                .filter(|&i| x[i].abs() > BLOW_UP_GROWTH * start)
        };
        // A state that grew is the news; sensitivities grow with it, and faster.
        let states = self.ev.rhs.states();
        match largest(0, states).or_else(|| largest(states, x.len())) {
            Some(i) => OdeError::BlowUp {
                t,
                what: self.ev.rhs.describe(i),
                value: x[i],
                start,
                steps: (self.ev.counts.steps + self.ev.counts.rejected_steps) as usize,
            },
            None => e,
        }
    }
}

/// The error for an implicit step whose matrix could not be factorised at t and that no
/// shorter step will cure: a right-hand side without a Jacobian, or a singular matrix in a
/// fixed-step integration.
fn implicit_error(e: FactorError, t: f64) -> OdeError {
    match e {
        FactorError::Unsupported => OdeError::InvalidSetup(
            "this right-hand side provides no Jacobian for the implicit integrator".into(),
        ),
        FactorError::Singular => OdeError::SingularJacobian { t },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ivp::ModelRhs;
    use crate::testing::Decay;

    /// x′ = −10⁴ x from x = 1, in two parts, [0, 1] and [1, 2]: the first starts with
    /// DOPRI5, finds the stiffness and ends with Rodas5P; the second, told so, takes a
    /// Jacobian at every step from its first (Rodas5P throughout), where started afresh it
    /// spends its first fifteen or more steps with DOPRI5 (no Jacobian) finding the
    /// stiffness again; both end at the same x to the tolerance.
    #[test]
    fn a_continued_part_starts_where_the_last_one_ended() {
        let (sys, p) = (Decay::new(), [1e4]);
        let cfg = Integrator::auto(1e-8, 1e-12);
        let mut rhs = ModelRhs::new(&sys, &p);
        let mut stiff = false;
        let (first, x1) =
            integrate_part(&cfg, &mut rhs, (0.0, &[1.0]), 1.0, &[], &mut stiff).unwrap();
        assert!(stiff && first.jacobians > 0, "{first:?}");
        let mut part = |stiff: bool| {
            let mut carried = stiff;
            let (counts, x) =
                integrate_part(&cfg, &mut rhs, (1.0, &x1), 2.0, &[], &mut carried).unwrap();
            assert!(carried, "the part ends stiff: {counts:?}");
            (counts, x[0])
        };
        let ((continued, x_continued), (fresh, x_fresh)) = (part(true), part(false));
        let attempted = |c: &Counts| c.steps + c.rejected_steps;
        assert!(continued.jacobians >= attempted(&continued), "{continued:?}");
        assert!(fresh.jacobians + 15 <= attempted(&fresh), "{fresh:?}");
        assert!((x_continued - x_fresh).abs() <= 1e-10, "{x_continued:e} against {x_fresh:e}");
    }
}
