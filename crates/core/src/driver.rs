//! The iteration driver every method uses, in the spirit of argmin's executor: the problem,
//! the method's step, the state of the run and the record of it are kept apart. A method
//! supplies only its [`Step`] (Goodman's Newton step, the quasilinearization step, the
//! argmin adapter); the driver owns the loop, the history, the iteration and integration
//! budgets, the step test, the best iterate, the certificate at the returned point and the
//! assembly of the [`Estimate`].
//!
//! At each iterate, in order: record it; stop if ε = 0 exactly ([`Rule::ExactFit`]) or if
//! the first-order optimality there is below the gradient tolerance ([`Rule::Gradient`],
//! where the method computed the model's sensitivities at the iterate); ask the method for a
//! proposal (a failure, such as a singular matrix, ends the run); stop on the method's own
//! rule or when the proposed step is below the step tolerance ([`Rule::Step`]); stop at the
//! iteration budget; let the method move (a failure ends the run; halving or a line search
//! may stop it with [`Rule::NoDescent`]).
//!
//! A run that stops on a rule returns the iterate the rule judged; any other ending (a
//! failure, a budget) returns the best iterate so far, with its history. Either way the
//! certificate is computed at the returned point and decides `converged`: a rule without the
//! certificate is [`Termination::Stalled`].

use std::time::Instant;

use sysid_ode::System;

use crate::certificate::{Certificate, certify, optimality};
use crate::confidence::interval;
use crate::error::FitError;
use crate::estimate::{Estimate, Iteration};
use crate::evaluations::Evaluations;
use crate::method::start_coordinates;
use crate::options::DriverOptions;
use crate::problem::{Linearization, Problem};
use crate::termination::{Failure, Rule, Termination};

/// A point of the iteration: the unknowns' coordinates and what the method knows there.
#[derive(Clone, Debug)]
pub struct Iterate {
    /// Coordinates z.
    pub z: Vec<f64>,
    /// ε of the model at z, the measure every method reports (NaN where the method can go on
    /// without it, as quasilinearization can).
    pub cost: f64,
    /// |U| as the method sees it, for the history.
    pub gradient_norm: Option<f64>,
    /// The model's linearization at z, when the method computed it (Goodman, the
    /// Gauss–Newton baseline): the gradient rule and the certificate use it.
    pub linearization: Option<Linearization>,
    /// Quasilinearization: ε of the linear family whose optimum z is.
    pub linear_cost: Option<f64>,
}

impl Iterate {
    /// An iterate from the model's linearization at it.
    pub fn linearized(lin: Linearization) -> Self {
        Self {
            z: lin.z.clone(),
            cost: lin.cost,
            gradient_norm: Some(lin.gradient.norm()),
            linearization: Some(lin),
            linear_cost: None,
        }
    }
}

/// What a method proposes from an iterate.
#[derive(Clone, Debug)]
pub struct Proposal {
    /// The next coordinates, inside the bounds.
    pub z: Vec<f64>,
    /// Condition number of the matrix the proposal solved with, for the history.
    pub condition: Option<f64>,
    /// |U| at the current iterate as the proposal computed it, for the history where the
    /// iterate has none (quasilinearization: the linear family's).
    pub gradient_norm: Option<f64>,
    /// The method's own rule says stop here, before moving (Goodman's predicted decrease).
    pub stop: Option<Rule>,
}

/// How a method moved.
#[derive(Debug)]
pub enum Advance {
    /// To a new iterate.
    Moved(Iterate),
    /// To a new iterate, which the method's rule says to stop at (argmin's cost change).
    MovedThenStop(Iterate, Rule),
    /// Not at all: the rule that says so (step halving found no descent).
    Stop(Rule),
}

/// One iteration of a method, in its own terms.
pub trait Step<S: System> {
    /// Evaluates the start z (coordinates, inside the bounds). A failure here means the start
    /// cannot be used.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure>;

    /// Proposes the next point from `current`.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure>;

    /// Moves to (or towards) the proposal, evaluating the new iterate.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure>;
}

/// How the loop ended, before the certificate judges it.
enum Ending {
    Rule(Rule),
    MaxIterations,
    Failed { iteration: usize, failure: Failure },
}

/// Runs `step` from `start` (values of the unknowns) on `problem` and returns the estimate
/// of method `method`. `Err` only for misuse: invalid options or start.
pub fn drive<S: System>(
    problem: &Problem<S>,
    method: &str,
    options: &DriverOptions,
    step: &mut impl Step<S>,
    start: &[f64],
) -> Result<Estimate, FitError> {
    options.validate()?;
    let started = Instant::now();
    let z0 = start_coordinates(problem, start)?;
    let ev = Evaluations::new(problem, options.integration_budget(problem.unknowns().len()));
    let gtol = options.gtol_for(problem.integrator().rtol);
    let record = Record { problem, method, options, gtol, started };
    let mut current = match step.start(&ev, z0.clone()) {
        Ok(start) => start,
        Err(failure) => return Ok(record.start_failed(&ev, z0, failure)),
    };
    let step_tolerance = problem.resolvable_step(options.step_tolerance);
    let mut history: Vec<Iteration> = Vec::new();
    let mut best: Option<(usize, Iterate)> = None;
    let (mut iteration, mut step_norm, mut pending) = (0, None, None);
    // Steps taken past a stopping rule that fired where the certificate fails, and the
    // certificate of the iterate the last rule stopped at.
    let (mut extra, mut verdict) = (0, None);
    let ending = loop {
        let measure = current.linearization.as_ref().map(|l| optimality(problem, l, gtol).0);
        history.push(Iteration {
            iteration,
            cost: current.cost,
            gradient_norm: current.gradient_norm.unwrap_or(f64::NAN),
            step_norm,
            condition: None,
            optimality: measure,
            values: problem.unknowns().values(&current.z),
            linear_cost: current.linear_cost,
        });
        if let Some(rule) = pending.take() {
            let judged = record.judge(&ev, &current);
            if judged.1.holds() || extra >= EXTRA_STEPS {
                verdict = Some(judged);
                break Ending::Rule(rule);
            }
            extra += 1;
        }
        if current.cost == 0.0 {
            break Ending::Rule(Rule::ExactFit);
        }
        if measure.is_some_and(|m| m <= options.gradient_tolerance.min(gtol)) {
            break Ending::Rule(Rule::Gradient);
        }
        let proposal = match step.propose(&ev, &current) {
            Ok(p) => p,
            Err(failure) => break Ending::Failed { iteration, failure },
        };
        if let Some(row) = history.last_mut() {
            row.condition = proposal.condition;
            if let Some(g) = proposal.gradient_norm {
                row.gradient_norm = g;
            }
        }
        let small = distance(&proposal.z, &current.z)
            <= step_tolerance * (norm(&current.z) + step_tolerance);
        if let Some(rule) = proposal.stop.or(small.then_some(Rule::Step)) {
            let judged = record.judge(&ev, &current);
            if judged.1.holds() || extra >= EXTRA_STEPS {
                verdict = Some(judged);
                break Ending::Rule(rule);
            }
            extra += 1;
        }
        if iteration >= options.max_iterations {
            break Ending::MaxIterations;
        }
        let next = match step.advance(&ev, &current, proposal) {
            Ok(Advance::Moved(next)) => next,
            Ok(Advance::MovedThenStop(next, rule)) => {
                pending = Some(rule);
                next
            }
            Ok(Advance::Stop(rule)) => break Ending::Rule(rule),
            Err(failure) => break Ending::Failed { iteration, failure },
        };
        step_norm = Some(distance(&next.z, &current.z));
        let previous = std::mem::replace(&mut current, next);
        if is_better(&previous, best.as_ref().map(|b| &b.1)) {
            best = Some((iteration, previous));
        }
        iteration += 1;
    };
    Ok(record.finish(&ev, (iteration, current, verdict), best, ending, history))
}

/// How many more steps a method may take after its stopping rule fired at a point that fails
/// the certificate. A step rule floored at the integrator's rtol can fire one or two Newton
/// steps early on an ill-conditioned problem (robertson's ln-rates near 17: a step of 2e-7
/// relative with a cosine still at 5e-6); a method that has truly stalled stays stalled.
const EXTRA_STEPS: usize = 3;

/// Whether `a` has a finite cost below `b`'s (or `b` is missing or has none).
fn is_better(a: &Iterate, b: Option<&Iterate>) -> bool {
    a.cost.is_finite() && b.is_none_or(|b| b.cost.is_nan() || a.cost < b.cost)
}

fn norm(z: &[f64]) -> f64 {
    z.iter().map(|v| v * v).sum::<f64>().sqrt()
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// The model's linearization at a point (if it could be evaluated) and the certificate there.
type Judged = (Option<Linearization>, Certificate);

/// What the assembly of the estimate needs.
struct Record<'a, S> {
    problem: &'a Problem<S>,
    method: &'a str,
    options: &'a DriverOptions,
    /// The certificate's tolerance.
    gtol: f64,
    started: Instant,
}

impl<S: System> Record<'_, S> {
    /// The estimate of a run whose start could not be evaluated: the start, no history.
    fn start_failed(&self, ev: &Evaluations<'_, S>, z: Vec<f64>, failure: Failure) -> Estimate {
        let k = z.len();
        let point = Iterate {
            z,
            cost: f64::NAN,
            gradient_norm: None,
            linearization: None,
            linear_cost: None,
        };
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
    fn finish(
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
        let termination = match ending {
            Ending::Rule(rule) => Termination::Stalled {
                rule,
                iteration: iterations,
                optimality: stalled.as_ref().map_or(f64::INFINITY, |s| s.1),
            },
            Ending::MaxIterations => Termination::MaxIterations,
            Ending::Failed { failure: Failure::Budget { integrations }, .. } => {
                Termination::IntegrationBudget { integrations }
            }
            Ending::Failed { iteration, failure } => Termination::Failed { iteration, failure },
        };
        let (at, point, lin, certificate) = match best {
            Some((i, b)) if is_better(&b, Some(&current)) => {
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
        self.estimate(ev, point, lin.as_ref(), certificate, termination, (at, iterations), history)
    }

    /// The model's linearization at `point` and the certificate there: the method's own
    /// linearization when it made one, else one more integration (outside the budget: the
    /// verdict needs it).
    fn judge(&self, ev: &Evaluations<'_, S>, point: &Iterate) -> Judged {
        let problem = self.problem;
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
            Some(lin) => certify(problem, lin, self.gtol, self.options.max_condition),
            None => Certificate::failed(point.z.len(), self.gtol),
        };
        (lin, certificate)
    }

    #[allow(clippy::too_many_arguments)]
    fn estimate(
        &self,
        ev: &Evaluations<'_, S>,
        point: Iterate,
        lin: Option<&Linearization>,
        certificate: Certificate,
        termination: Termination,
        (best_iteration, iterations): (usize, usize),
        history: Vec<Iteration>,
    ) -> Estimate {
        let problem = self.problem;
        let unknowns = problem.unknowns();
        let values = unknowns.values(&point.z);
        // Unknowns held on a bound are not estimated there: no standard error, no interval,
        // and they do not count in the degrees of freedom.
        let held: Vec<bool> = certificate.active.iter().map(Option::is_some).collect();
        let free = held.iter().filter(|h| !**h).count();
        // s² A⁻¹ is the estimate's covariance at a minimum only.
        let covariance =
            lin.filter(|_| certificate.holds()).and_then(|l| problem.covariance(l, &held));
        let std_errors: Option<Vec<f64>> = covariance.as_ref().map(|c| {
            (0..c.nrows()).map(|i| if held[i] { f64::NAN } else { c[(i, i)].sqrt() }).collect()
        });
        let dof = problem.n_observations().map(|n| n.saturating_sub(free));
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
            // (the problem's integrator, with sensitivities); the method's own where there is
            // none.
            cost: lin.map_or(point.cost, |l| l.cost),
            dof,
            iterations,
            best_iteration,
            termination,
            certificate,
            history,
            elapsed: self.started.elapsed(),
            counts: ev.counts(),
        }
    }
}
