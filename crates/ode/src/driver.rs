//! The integration loop: segments between discontinuities, direction, the step budget,
//! accepting and rejecting steps by the scheme's controller, the automatic switch to Rodas4,
//! and one interpolant per accepted step. Schemes are reached only through [`Stepper`].

use crate::control::{MIN_FACTOR, initial_step};
use crate::counts::Counts;
use crate::dopri5::Dopri5;
use crate::error::{BLOW_UP_GROWTH, OdeError};
use crate::interpolant::Interpolant;
use crate::lu::FactorError;
use crate::options::{Integrator, Scheme};
use crate::rhs::Rhs;
use crate::rk4::Rk4;
use crate::rodas4::Rodas4;
use crate::stepper::Stepper;
use crate::stiffness::Stiffness;
use crate::work::{Evaluator, Work};

/// The error to report for a failed integration whose state at t is x: a blow-up when a
/// component overflowed or grew beyond [`BLOW_UP_GROWTH`] times `start`, `e` otherwise.
fn explain<R: Rhs>(rhs: &R, e: OdeError, start: f64, t: f64, x: &[f64]) -> OdeError {
    let largest = |from: usize, to: usize| {
        (from..to.min(x.len()))
            .filter(|&i| !x[i].is_nan())
            .max_by(|&a, &b| x[a].abs().total_cmp(&x[b].abs()))
            .filter(|&i| x[i].abs() > BLOW_UP_GROWTH * start)
    };
    // A state that grew is the news; sensitivities grow with it, and faster.
    let states = rhs.states();
    match largest(0, states).or_else(|| largest(states, x.len())) {
        Some(i) => OdeError::BlowUp { t, what: rhs.describe(i), value: x[i], start },
        None => e,
    }
}

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
    mut wants: impl FnMut(f64, f64) -> bool,
    mut on_step: impl FnMut(&Interpolant),
) -> Result<(Counts, Vec<f64>), OdeError> {
    let n = rhs.dim();
    if x0.len() != n {
        return Err(OdeError::Dimension { what: "initial state", actual: x0.len(), expected: n });
    }
    cfg.validate().map_err(OdeError::InvalidSetup)?;
    for (what, v) in [("t0", t0), ("t_end", t_end)] {
        if !v.is_finite() {
            return Err(OdeError::InvalidInput { what: what.into(), value: v });
        }
    }
    if let Some(i) = x0.iter().position(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite { t: t0, what: format!("initial {}", rhs.describe(i)) });
    }
    let mut work = Work::new(n);
    work.x.copy_from_slice(x0);
    // The largest magnitude at the start (at least 1): what a blow-up is measured against.
    let start = x0.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let mut st = Evaluator {
        rhs,
        cfg: *cfg,
        counts: Counts { integrations: 1, ..Counts::default() },
        seg: (t0, t_end),
    };
    if t_end - t0 == 0.0 {
        return Ok((st.counts, x0.to_vec()));
    }
    let dir = (t_end - t0).signum();
    // Segment ends in the direction of integration; stops too close to a segment end to
    // take a step in between are merged with it.
    let resolution = |t: f64| 64.0 * f64::EPSILON * t.abs().max(1.0);
    let mut ends: Vec<f64> = stops
        .iter()
        .copied()
        .filter(|&s| (s - t0) * dir > resolution(t0) && (t_end - s) * dir > resolution(t_end))
        .collect();
    if dir < 0.0 {
        ends.reverse();
    }
    ends.push(t_end);

    let mut t = t0;
    let mut h = cfg.initial_step.unwrap_or(0.0).abs();
    // ln of the previous accepted error (Hairer's facold, at least 1e-4).
    let mut ln_err_old: f64 = 1e-4f64.ln();
    // The scheme stepping now: `auto` starts explicit and may switch to Rodas4.
    let mut current = stepper::<R>(cfg.scheme);
    let mut stiffness = Stiffness::default();
    // Where DOPRI5's stiffness test fired, if it did and the scheme stays explicit.
    let mut stiff_since: Option<f64> = None;
    for &seg_end in &ends {
        st.seg = (t, seg_end);
        st.f(t, &work.x, &mut work.k[0]);

        if let Some(fixed) = cfg.fixed_step {
            let length = seg_end - t;
            let count = ((length.abs() / fixed) - 1e-9).ceil().max(1.0) as usize;
            let hs = length / count as f64;
            for i in 0..count {
                if (st.counts.steps + st.counts.rejected_steps) as usize >= cfg.max_steps {
                    let e = OdeError::TooManySteps { t, t_end, steps: cfg.max_steps };
                    return Err(explain(st.rhs, e, start, t, &work.x));
                }
                let t_next = if i + 1 == count { seg_end } else { t + hs };
                current
                    .step(&mut st, &mut work, t, t_next - t)
                    .map_err(|e| implicit_error(e, t))?;
                accept(&mut st, &mut work, current, (t, t_next), &mut wants, &mut on_step)
                    .map_err(|e| explain(st.rhs, e, start, t_next, &work.x_new))?;
                t = t_next;
            }
            continue;
        }

        if h == 0.0 {
            h = initial_step(&mut st, &mut work, t, dir);
        }
        let mut last_rejected = false;
        // The component that was NaN or infinite in the last rejected trial step, if any:
        // when the step size then underflows, that is the reason to report.
        let mut non_finite: Option<usize> = None;
        let mut reached = false;
        while !reached {
            if (st.counts.steps + st.counts.rejected_steps) as usize >= cfg.max_steps {
                let steps = cfg.max_steps;
                let e = match stiff_since {
                    Some(since) => OdeError::Stiff { t, since, steps },
                    None => OdeError::TooManySteps { t, t_end, steps },
                };
                return Err(explain(st.rhs, e, start, t, &work.x));
            }
            let remaining = seg_end - t;
            let mut hs = h.min(cfg.max_step);
            let lands = hs * 1.01 >= remaining.abs();
            if lands {
                hs = remaining.abs();
            }
            // Hairer's test: the step no longer changes t in floating point.
            if hs <= 16.0 * f64::EPSILON * t.abs() || hs < f64::MIN_POSITIVE {
                let e = match non_finite {
                    Some(i) => OdeError::NonFinite { t, what: st.rhs.describe(i) },
                    None => OdeError::StepSizeTooSmall { t, h: hs * dir },
                };
                return Err(explain(st.rhs, e, start, t, &work.x));
            }
            let t_next = if lands { seg_end } else { t + dir * hs };
            let err = match current.step(&mut st, &mut work, t, t_next - t) {
                Ok(err) => err,
                // A singular iteration matrix: a shorter step changes it.
                Err(FactorError::Singular) => f64::NAN,
                Err(e) => return Err(implicit_error(e, t)),
            };
            let h_lambda = if stiffness.due(cfg.scheme == Scheme::Auto, st.counts.steps) {
                current.stiffness_estimate(&work, hs)
            } else {
                None
            };
            if !err.is_finite() {
                // The trial step left the region where f is defined: retry much shorter.
                st.counts.rejected_steps += 1;
                h = hs * MIN_FACTOR;
                last_rejected = true;
                non_finite = work.x_new.iter().chain(&work.k[6]).position(|v| !v.is_finite());
                non_finite = non_finite.map(|i| i % n).or(Some(0));
                continue;
            }
            non_finite = None;
            let ln_err = err.max(f64::MIN_POSITIVE).ln();
            if err <= 1.0 {
                accept(&mut st, &mut work, current, (t, t_next), &mut wants, &mut on_step)
                    .map_err(|e| explain(st.rhs, e, start, t_next, &work.x_new))?;
                t = t_next;
                reached = lands;
                let fac = control(current).accepted(ln_err, ln_err_old);
                ln_err_old = ln_err.max(1e-4f64.ln());
                h = hs / fac;
                if last_rejected {
                    h = h.min(hs);
                }
                last_rejected = false;
                if let Some(h_lambda) = h_lambda
                    && stiffness.observe(h_lambda)
                {
                    match cfg.scheme {
                        Scheme::Auto if st.rhs.factor(t, st.side(t), &work.x, 1.0).is_ok() => {
                            current = stepper(Scheme::Rodas4);
                            st.counts.jacobians += 1;
                        }
                        _ => {
                            stiff_since.get_or_insert(t);
                        }
                    }
                }
            } else {
                st.counts.rejected_steps += 1;
                h = hs / control(current).rejected(ln_err);
                last_rejected = true;
            }
        }
    }
    Ok((st.counts, work.x))
}

/// The scheme that steps first for `scheme` (the automatic choice starts with DOPRI5): the
/// one place a [`Scheme`] is mapped to its [`Stepper`].
pub(crate) fn stepper<'s, R: Rhs + 's>(scheme: Scheme) -> &'s dyn Stepper<R> {
    match scheme {
        Scheme::Dopri5 | Scheme::Auto => &Dopri5,
        Scheme::Rk4 => &Rk4,
        Scheme::Rodas4 => &Rodas4,
    }
}

/// The step-size controller of an error-controlled scheme.
fn control<R: Rhs>(scheme: &dyn Stepper<R>) -> crate::control::Control {
    scheme
        .control()
        .expect("Integrator::validate allows schemes without error control only with a fixed step")
}

fn implicit_error(e: FactorError, t: f64) -> OdeError {
    match e {
        FactorError::Unsupported => OdeError::InvalidSetup(
            "this right-hand side provides no Jacobian for the implicit integrator".into(),
        ),
        FactorError::Singular => OdeError::SingularJacobian { t },
    }
}

/// Accepts the step from t to t_next held in `work`: interpolant and callback (if wanted),
/// advance.
fn accept<R: Rhs>(
    st: &mut Evaluator<'_, R>,
    work: &mut Work,
    scheme: &dyn Stepper<R>,
    (t, t_next): (f64, f64),
    wants: &mut impl FnMut(f64, f64) -> bool,
    on_step: &mut impl FnMut(&Interpolant),
) -> Result<(), OdeError> {
    if let Some(i) = work.x_new.iter().position(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite { t, what: st.rhs.describe(i) });
    }
    st.counts.steps += 1;
    if wants(t, t_next) {
        scheme.dense(work, t, t_next);
        on_step(&work.interpolant);
    }
    std::mem::swap(&mut work.x, &mut work.x_new);
    // The explicit schemes' last stage is f(t_next, x_next): the next step's first.
    work.k.swap(0, 6);
    Ok(())
}
