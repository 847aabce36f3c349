//! The assembly of a fit's result once the loop has ended: which point is returned, the
//! certificate there, the termination it earns, and the [`Estimate`] with its covariance,
//! standard errors and intervals.

use std::time::Instant;

use nalgebra::DMatrix;
use sysid_ode::System;

use crate::certificate::{Certificate, certify, exact_fit_tolerance, optimality, other_side};
use crate::confidence::interval;
use crate::estimate::{Estimate, ExperimentFit, Iteration, ScaleEstimate};
use crate::evaluate::Linearization;
use crate::evaluations::Evaluations;
use crate::linalg::NormalFactor;
use crate::options::DriverOptions;
use crate::problem::Problem;
use crate::step::Iterate;
use crate::termination::{Failure, PROGRESS, PROGRESS_WINDOW, Rule, Termination};

/// How the loop ended, before the certificate judges it.
pub(crate) enum Ending {
    Rule(Rule),
    MaxIterations,
    /// The wall-clock limit of this many seconds ran out.
    TimeLimit(f64),
    /// The caller asked the fit to stop ([`stop_when`](crate::observer::stop_when)).
    Interrupted,
    Failed {
        iteration: usize,
        failure: Failure,
    },
}
/// The names of the unknowns the certificate finds undetermined.
pub(crate) fn undetermined_names<S: System>(problem: &Problem<S>, c: &Certificate) -> Vec<String> {
    let names = problem.names();
    c.undetermined().into_iter().map(|i| names[i].clone()).collect()
}

/// How far beyond τ an adaptive integration's exact fit may be at the integration that
/// checks it before the claim is withdrawn (a fixed step's is held to τ itself, as before).
const EXACT_FIT_MARGIN: f64 = 100.0;

/// Whether ε's integration error `cost_error` at the point of `lin` says that the integration
/// does not resolve the model there ([`Certificate::unresolved`]): more than a tenth of ε,
/// and more than ten times the resolution the tolerances promise. Near the data ε itself is
/// at that resolution (an error as large as ε is then the tolerances' own, not a failure);
/// an oscillator's ε, wrong by up to 6e6 times rtol·ε (Borghans at rtol 1e-8), is still
/// within a few per cent of itself.
fn integration_unresolved<S: System>(
    problem: &Problem<S>,
    lin: &Linearization,
    cost_error: f64,
) -> bool {
    cost_error > 0.1 * lin.cost.abs()
        && cost_error > 10.0 * problem.cost_resolution(lin.cost, lin.norm)
}

/// Whether `a` has a finite cost below `b`'s (or `b` is missing or has none).
pub(crate) fn is_better(a: &Iterate, b: Option<&Iterate>) -> bool {
    a.cost.is_finite() && b.is_none_or(|b| b.cost.is_nan() || a.cost < b.cost)
}

/// Whether a run that ended by `ending` returns its best iterate rather than the last one:
/// the iterate a rule stopped at is returned where its certificate (`verdict`) holds, else
/// whichever of the two is better. The driver sets the scales of the returned point by it,
/// and [`Record::finish`] assembles that point: the two must agree.
pub(crate) fn returns_best(
    ending: &Ending,
    verdict: Option<&Judged>,
    current: &Iterate,
    best: Option<&Iterate>,
) -> bool {
    let certified = matches!(ending, Ending::Rule(_)) && verdict.is_some_and(|(_, c)| c.holds());
    !certified && best.is_some_and(|b| is_better(b, Some(current)))
}
/// The model's linearization at a point (if it could be evaluated) and the certificate there.
type Judged = (Option<Linearization>, Certificate);

/// What the assembly of the estimate needs.
pub(crate) struct Record<'a> {
    pub(crate) method: &'a str,
    pub(crate) options: &'a DriverOptions,
    /// The certificate's tolerance.
    pub(crate) gtol: f64,
    pub(crate) started: Instant,
}

impl Record<'_> {
    /// The estimate of a run whose start could not be evaluated: the start, no history.
    pub(crate) fn start_failed<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        z: Vec<f64>,
        failure: Failure,
    ) -> Estimate {
        let k = z.len();
        let point = Iterate::new(z, f64::NAN);
        let certificate = Certificate::failed(k, self.gtol);
        let termination = match failure {
            Failure::Budget { integrations } => Termination::IntegrationBudget { integrations },
            failure => Termination::StartFailed(failure),
        };
        self.estimate(ev, point, None, certificate, termination, (0, 0), Vec::new())
    }

    /// The estimate after `ending`, with `current` the last iterate (its number is the count
    /// of updates; its certificate if the loop judged it) and `best` the best earlier one. A
    /// rule that the certificate confirms returns the iterate it stopped at; anything else
    /// returns the best iterate.
    pub(crate) fn finish<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        (iterations, current, verdict): (usize, Iterate, Option<Judged>),
        best: Option<(usize, Iterate)>,
        ending: Ending,
        history: Vec<Iteration>,
    ) -> Estimate {
        let mut stalled = None;
        if let Ending::Rule(rule) = ending {
            let (lin, certificate) = verdict.unwrap_or_else(|| self.judge(ev, &current));
            if certificate.holds() {
                let termination = Termination::Converged(rule);
                let at = (iterations, iterations);
                return self.estimate(
                    ev,
                    current,
                    lin.as_ref(),
                    certificate,
                    termination,
                    at,
                    history,
                );
            }
            stalled = Some((rule, certificate.optimality, lin, certificate));
        }
        // A rule's certified iterate was returned above.
        let to_best =
            best.as_ref().is_some_and(|(_, b)| returns_best(&ending, None, &current, Some(b)));
        let termination = match ending {
            Ending::Rule(rule) => Termination::Stalled {
                rule,
                iteration: iterations,
                optimality: stalled.as_ref().map_or(f64::INFINITY, |s| s.1),
                error: stalled.as_ref().map_or(0.0, |s| s.3.error),
                plateau: stalled.as_ref().is_some_and(|s| s.3.plateau()),
                undetermined: stalled
                    .as_ref()
                    .map(|s| undetermined_names(ev.problem(), &s.3))
                    .unwrap_or_default(),
                moving: match rule {
                    Rule::Progress => moving(ev.problem(), &history),
                    _ => Vec::new(),
                },
                unchecked: stalled
                    .as_ref()
                    .and_then(|(.., c)| c.unchecked.clone().filter(|_| c.unconfirmed())),
                // Set below, from the point returned.
                unresolved: None,
                blocked: ev.last_failed().map(|e| e.to_string()),
            },
            Ending::MaxIterations => Termination::MaxIterations {
                fell: fell(&history, current.epsilon()),
                moving: moving(ev.problem(), &history),
                // Set below, from the point returned.
                unresolved_gradient: None,
            },
            Ending::TimeLimit(seconds) => Termination::TimeLimit { seconds },
            Ending::Interrupted => Termination::Interrupted,
            Ending::Failed { failure: Failure::Budget { integrations }, .. } => {
                Termination::IntegrationBudget { integrations }
            }
            Ending::Failed { iteration, failure } => Termination::Failed { iteration, failure },
        };
        let mut termination = termination;
        let (at, point, lin, certificate) = match best {
            Some((i, b)) if to_best => {
                let (lin, certificate) = self.judge(ev, &b);
                (i, b, lin, certificate)
            }
            _ => {
                let (lin, certificate) = match stalled {
                    Some((.., lin, certificate)) => (lin, certificate),
                    None => self.judge(ev, &current),
                };
                (iterations, current, lin, certificate)
            }
        };
        // A stall is told by the point returned: where the integration does not resolve the
        // model there, that is what is said of it (its cost may be an artefact of the
        // integration, lower than any point's the run met whose integration holds).
        if let Termination::Stalled {
            unresolved, optimality, error, plateau, undetermined, ..
        } = &mut termination
        {
            // Its measure and flags as the JSON gives them for that point.
            (*optimality, *error) = (certificate.optimality, certificate.error);
            *plateau = certificate.plateau();
            *undetermined = undetermined_names(ev.problem(), &certificate);
            if certificate.unresolved {
                *unresolved =
                    Some((certificate.cost_error, lin.as_ref().map_or(f64::NAN, |l| l.cost)));
            }
        }
        if let Termination::MaxIterations { unresolved_gradient, .. } = &mut termination
            && !certificate.holds()
            && certificate.optimality.is_finite()
            && certificate.error > certificate.optimality
        {
            *unresolved_gradient = Some((certificate.optimality, certificate.error));
        }
        self.estimate(ev, point, lin.as_ref(), certificate, termination, (at, iterations), history)
    }

    /// The model's linearization at `point` and the certificate there: the method's own
    /// linearization when it made one, else one more integration (outside the budget: the
    /// verdict needs it); and the measure's integration error, from one more integration at
    /// a tenth of the tolerances, or with error control for a fixed step
    /// ([`Evaluations::reference`]; not measured where that integration fails).
    pub(crate) fn judge<S: System>(&self, ev: &Evaluations<'_, S>, point: &Iterate) -> Judged {
        let problem = ev.problem();
        let lin = match &point.linearization {
            Some(lin) => Some(lin.clone()),
            None => match problem.linearize(&point.z) {
                Ok(lin) => {
                    ev.add(lin.counts);
                    Some(lin)
                }
                Err(_) => None,
            },
        };
        let certificate = match &lin {
            Some(lin) => {
                let max_condition = self.options.max_condition;
                let mut certificate = certify(problem, lin, self.gtol, max_condition);
                let linearize = |z: &[f64]| problem.linearize(z).ok();
                // The verdict on the unknowns held at kinks of switch times passing sample
                // times ([`other_side`]), once the exact fit is settled: made here with the
                // error measurement, or below.
                let mut kinks_judged = false;
                // The cost is the model's only as far as the integration resolves it: its
                // error is always measured, an exact fit included (a fixed step's always
                // was; an adaptive one's since a logistic growth from 1e-14, below atol
                // 1e-10, passed through its data at a start 2.7 times the true one and was
                // certified an exact fit, its ε 1 622 at a tenth of the tolerances). A
                // reference that cannot be integrated leaves the claim unproven (∞): the
                // working integration may have stepped over a singularity that the finer one
                // meets (Crauste's pathogen, P′ = ρ P² − …, blows up just before the last
                // sample at points Rodas5P and DOP853 integrate at rtol 1e-8 and fail at
                // 1e-10).
                if certificate.optimality.is_finite()
                    && let Some(finer) = ev.reference()
                {
                    certificate.error_measured = true;
                    match finer.linearize(&point.z) {
                        Ok(fine) => {
                            ev.add(fine.counts);
                            certificate.cost_error = (lin.cost - fine.cost).abs();
                            // Withdrawn where the finer ‖r‖ is far beyond τ: within 100·τ
                            // it is the working integration's own global error (synthetic
                            // data made by the same integration give ‖r‖ = 0 there and that
                            // error at the finer one); the logistic case was 1e6 times τ.
                            if certificate.exact_fit {
                                let tau = exact_fit_tolerance(problem) * problem.data_norm();
                                let fixed = problem.integrator().fixed_step.is_some();
                                let margin = if fixed { 1.0 } else { EXACT_FIT_MARGIN };
                                if fine.norm > margin * tau {
                                    certificate.exact_fit = false;
                                    certificate.optimality =
                                        optimality(problem, lin, self.gtol).value;
                                }
                            }
                            if !certificate.exact_fit {
                                ev.add(other_side(problem, lin, &mut certificate, &linearize));
                                kinks_judged = true;
                                // The same measure at the finer integration, with the same
                                // verdict on kinks: their difference is the integration's.
                                let mut finely = certify(&finer, &fine, self.gtol, max_condition);
                                finely.optimality = optimality(&finer, &fine, self.gtol).value;
                                let linearize_finely = |z: &[f64]| finer.linearize(z).ok();
                                ev.add(other_side(&finer, &fine, &mut finely, &linearize_finely));
                                certificate.error =
                                    (certificate.optimality - finely.optimality).abs();
                                if integration_unresolved(problem, lin, certificate.cost_error) {
                                    certificate.unresolved = true;
                                    certificate.flat.fill(false);
                                    certificate.null_space = None;
                                }
                            }
                        }
                        // Another scheme at the same tolerances that fails (out of steps,
                        // a Rosenbrock scheme slow on a large model) says nothing of the
                        // working integration's error, as a finer one meeting a
                        // singularity would: the error is unmeasured.
                        Err(_) if ev.reference_is_another_scheme() => {
                            certificate.error_measured = false;
                        }
                        Err(e) => {
                            (certificate.error, certificate.cost_error) =
                                (f64::INFINITY, f64::INFINITY);
                            certificate.unchecked = Some(e.to_string());
                        }
                    }
                }
                if !kinks_judged && !certificate.exact_fit {
                    ev.add(other_side(problem, lin, &mut certificate, &linearize));
                }
                certificate
            }
            None => Certificate::failed(point.z.len(), self.gtol),
        };
        (lin, certificate)
    }

    #[allow(clippy::too_many_arguments)]
    fn estimate<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        point: Iterate,
        lin: Option<&Linearization>,
        certificate: Certificate,
        termination: Termination,
        (best_iteration, iterations): (usize, usize),
        history: Vec<Iteration>,
    ) -> Estimate {
        let problem = ev.problem();
        let unknowns = problem.unknowns();
        let values = unknowns.values(&point.z);
        // Unknowns held on a bound are not estimated there: no standard error, no interval,
        // and they do not count in the degrees of freedom.
        let held: Vec<bool> = certificate.active.iter().map(Option::is_some).collect();
        let free = held.iter().filter(|h| !**h).count();
        // s² A⁻¹ is the estimate's covariance at a minimum only.
        let covariance = lin
            .filter(|_| certificate.holds())
            .and_then(|l| problem.covariance(l, &held, self.options.max_condition));
        let std_errors: Option<Vec<f64>> = covariance.as_ref().map(|c| {
            (0..c.nrows()).map(|i| if held[i] { f64::NAN } else { c[(i, i)].sqrt() }).collect()
        });
        let dof = problem.n_observations().map(|n| n.saturating_sub(free + problem.scales().len()));
        let intervals = match (&std_errors, dof) {
            (Some(se), Some(dof)) if dof > 0 => Some(
                unknowns
                    .list()
                    .iter()
                    .zip(values.iter().zip(se))
                    .map(|(u, (&v, &s))| interval(v, s, dof, u.log).unwrap_or([f64::NAN; 2]))
                    .collect(),
            ),
            _ => None,
        };
        Estimate {
            method: self.method.to_string(),
            names: problem.names(),
            values,
            std_errors,
            intervals,
            covariance,
            // One measure for every method: ε from the integration the certificate judged
            // (the problem's integrator, with sensitivities); none (NaN) where the point could
            // not be evaluated so. The method's own figure there (quasilinearization's, from an
            // integration 10 times tighter) stays in the history: as the fit's cost it ranked
            // a start that cannot be integrated first in a multistart (Perelson).
            cost: lin.map_or(f64::NAN, |l| l.cost),
            dof,
            iterations,
            best_iteration,
            termination,
            certificate,
            history,
            elapsed: self.started.elapsed(),
            counts: ev.counts(),
            nll: lin.and_then(|l| problem.nll(l)),
            prior: lin.and_then(|l| problem.prior_nll(l)),
            experiments: ExperimentFit::all(
                problem,
                lin.and_then(|l| problem.experiment_nlls(l)).as_deref(),
            ),
            scales: Vec::new(),
            noise_model: problem.has_noise_model(),
            retry: None,
        }
    }
}

/// The estimate of a fit in rounds between closed-form updates of the noise scales (see
/// [`drive`](crate::method::drive)): the last round's, on the whole history, with the scales at the
/// values that round held (`held`) and their part of the certificate, `moved`, the largest
/// relative change the closed form would still make.
pub(crate) fn with_scales<S: System>(
    problem: &Problem<S>,
    held: &Problem<S>,
    rounds: Vec<Estimate>,
    moved: f64,
    out_of_iterations: bool,
) -> Estimate {
    // A round starts where the last one stopped, at the scales' new values: its first row
    // replaces the last one's, so that each row is the point as last evaluated (and the
    // reported point's row is the certificate's).
    let mut rounds = rounds.into_iter();
    let mut e = rounds.next().expect("at least one round");
    rounds.for_each(|next| e.continue_with(next));
    let iterations = e.iterations;
    e.certificate.scales = Some(moved);
    if !e.certificate.holds()
        && let Termination::Converged(rule) = e.termination
    {
        // The fit of the last round was certified, but the scales would still move: the
        // iteration budget ran out before they could, or the rounds stalled.
        e.termination = if out_of_iterations {
            Termination::MaxIterations { fell: None, moving: Vec::new(), unresolved_gradient: None }
        } else {
            Termination::Stalled {
                rule,
                iteration: iterations,
                optimality: e.certificate.optimality.max(moved),
                error: e.certificate.error,
                plateau: false,
                undetermined: Vec::new(),
                moving: Vec::new(),
                unchecked: None,
                unresolved: None,
                blocked: None,
            }
        };
    }
    let converged = e.certificate.holds();
    if !converged {
        // The last round's uncertainty was of a certified point; with the scales still
        // moving the whole is not one.
        (e.std_errors, e.intervals, e.covariance) = (None, None, None);
    }
    let counts_per_scale = held.scale_samples();
    e.scales = held
        .scales()
        .iter()
        .zip(counts_per_scale)
        .map(|(&j, n)| {
            let u = &problem.declared()[j];
            let value =
                held.scale_values()[held.scales().iter().position(|&s| s == j).expect("a scale")];
            let (lo, hi) = (u.min.unwrap_or(f64::NEG_INFINITY), u.max.unwrap_or(f64::INFINITY));
            let bound = if value <= lo {
                Some(crate::certificate::Bound::Lower)
            } else if value >= hi {
                Some(crate::certificate::Bound::Upper)
            } else {
                None
            };
            // Fisher information of s: 2n/s² (n samples of normal noise).
            let std_error =
                (converged && bound.is_none() && n > 0).then(|| value / (2.0 * n as f64).sqrt());
            let interval = match (std_error, e.dof) {
                (Some(se), Some(dof)) if dof > 0 => interval(value, se, dof, u.log),
                _ => None,
            };
            ScaleEstimate { name: u.name.clone(), value, std_error, interval, bound }
        })
        .collect();
    e
}

impl<S: System> Problem<S> {
    /// Covariance of the estimates (as values) from the normal matrix at the estimate,
    /// transformed to values by the delta method. With a noise model it is the inverse
    /// Fisher information, A⁻¹ (σ given or estimated); with relative weights the noise's
    /// scale is estimated from the residuals: s² A⁻¹, s² = ε / (N − k). Unknowns `held` on a
    /// bound are not estimated there: the covariance is that of the free ones, with
    /// N − k_free, and the held ones' rows and columns are 0. `None` when there are no more
    /// data than free unknowns, for a record given as a function (no count N), or when A_FF
    /// is singular: its Jacobi-scaled condition number above `max_condition` (standard
    /// errors from a matrix the data cannot invert are numbers without meaning).
    pub fn covariance(
        &self,
        lin: &Linearization,
        held: &[bool],
        max_condition: f64,
    ) -> Option<DMatrix<f64>> {
        let k = self.unknowns.len();
        let free: Vec<usize> = (0..k).filter(|&i| !held.get(i).copied().unwrap_or(false)).collect();
        let n = self.n_observations()?;
        let estimated = free.len() + self.scales().len();
        if n <= estimated || free.is_empty() {
            return None;
        }
        let s2 = match self.has_noise_model() {
            true => 1.0,
            false => lin.cost / (n - free.len()) as f64,
        };
        // Weights are relative: s² A⁻¹ does not depend on their overall scale c, and is
        // formed as (s²/c)(A/c)⁻¹ with c the largest diagonal entry, so that tiny weights
        // (1e-308) do not overflow A⁻¹ and huge ones do not overflow A.
        let block = lin.normal.select_rows(&free).select_columns(&free);
        let c = block.diagonal().iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if !(c > 0.0 && c.is_finite()) {
            return None;
        }
        let inverse = NormalFactor::new(&(block / c), max_condition).ok()?.inverse();
        let s2 = s2 / c;
        let scale: Vec<f64> =
            self.unknowns.list().iter().zip(&lin.z).map(|(u, &z)| u.scale(z)).collect();
        let mut cov = DMatrix::zeros(k, k);
        for (a, &i) in free.iter().enumerate() {
            for (b, &j) in free.iter().enumerate() {
                cov[(i, j)] = s2 * inverse[(a, b)] * scale[i] * scale[j];
            }
        }
        Some(cov)
    }
}

/// How much the cost fell over the last [`PROGRESS_WINDOW`] iterations of `history`; None
/// for a shorter history, a cost that is not finite at either end, or a fall the progress
/// rule counts as none (at most [`PROGRESS`] of `epsilon`, the last iterate's ε, as the
/// driver's rule measures it: under hierarchical optimisation the rows' costs are the
/// profile's, twice the NLL up to a constant, whose size says nothing).
fn fell(history: &[Iteration], epsilon: f64) -> Option<f64> {
    let last = history.last()?.cost;
    let then = history[history.len().checked_sub(PROGRESS_WINDOW + 1)?].cost;
    let fell = then - last;
    (fell.is_finite() && fell > PROGRESS * epsilon.abs()).then_some(fell)
}

/// The unknowns whose coordinates moved most over the last [`PROGRESS_WINDOW`] iterations
/// of `history`: those that moved at least a tenth of the most any did, most first, at
/// most 5.
fn moving<S: System>(problem: &Problem<S>, history: &[Iteration]) -> Vec<String> {
    let (Some(last), Some(then)) =
        (history.last(), history.len().checked_sub(PROGRESS_WINDOW + 1).map(|i| &history[i]))
    else {
        return Vec::new();
    };
    let list = problem.unknowns().list();
    let mut moved: Vec<(f64, &str)> = list
        .iter()
        .enumerate()
        .map(|(i, u)| {
            let d = u.coordinate(last.values[i]) - u.coordinate(then.values[i]);
            (if d.is_nan() { 0.0 } else { d.abs() }, u.name.as_str())
        })
        .collect();
    moved.sort_by(|a, b| b.0.total_cmp(&a.0));
    let most = moved.first().map_or(0.0, |m| m.0);
    moved
        .into_iter()
        .filter(|m| most > 0.0 && m.0 >= 0.1 * most)
        .take(5)
        .map(|m| m.1.to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A history whose costs fall evenly by `fall` over the progress window, from `first`.
    fn history(first: f64, fall: f64) -> Vec<Iteration> {
        (0..=PROGRESS_WINDOW)
            .map(|i| Iteration {
                iteration: i,
                cost: first - fall * i as f64 / PROGRESS_WINDOW as f64,
                gradient_norm: 0.0,
                step_norm: None,
                condition: None,
                optimality: None,
                values: Vec::new(),
                diagnostics: Default::default(),
            })
            .collect()
    }

    /// The fall the iteration limit reports is judged against ε, whatever constant the
    /// profile's costs carry (near 0 here, where a fall of any size was counted).
    #[test]
    fn the_fall_at_the_limit_is_judged_against_epsilon() {
        let epsilon = 313.0;
        for first in [0.1, -40.0, 1e4] {
            assert_eq!(fell(&history(first, 0.5 * PROGRESS * epsilon), epsilon), None, "{first}");
            let fast = 2.0 * PROGRESS * epsilon;
            let got = fell(&history(first, fast), epsilon).expect("a fall");
            assert!((got - fast).abs() <= 1e-9 * first.abs().max(1.0), "{first}: {got}");
        }
        assert_eq!(
            fell(&history(0.1, 1.0)[1..], epsilon),
            None,
            "a history shorter than the window"
        );
    }
}
