//! The assembly of a fit's result once the loop has ended: which point is returned, the
//! certificate there, the termination it earns, and the [`Estimate`] with its covariance,
//! standard errors and intervals.

use std::time::Instant;

use nalgebra::DMatrix;
use sysid_ode::System;

use crate::certificate::{Certificate, certify};
use crate::confidence::interval;
use crate::estimate::{Estimate, Iteration};
use crate::evaluate::Linearization;
use crate::evaluations::Evaluations;
use crate::linalg::NormalFactor;
use crate::options::DriverOptions;
use crate::problem::Problem;
use crate::step::Iterate;
use crate::termination::{Failure, Rule, Termination};

/// How the loop ended, before the certificate judges it.
pub(crate) enum Ending {
    Rule(Rule),
    MaxIterations,
    Failed { iteration: usize, failure: Failure },
}
/// Whether `a` has a finite cost below `b`'s (or `b` is missing or has none).
pub(crate) fn is_better(a: &Iterate, b: Option<&Iterate>) -> bool {
    a.cost.is_finite() && b.is_none_or(|b| b.cost.is_nan() || a.cost < b.cost)
}
/// The model's linearization at a point (if it could be evaluated) and the certificate there.
type Judged = (Option<Linearization>, Certificate);

/// What the assembly of the estimate needs.
pub(crate) struct Record<'a, S> {
    pub(crate) problem: &'a Problem<S>,
    pub(crate) method: &'a str,
    pub(crate) options: &'a DriverOptions,
    /// The certificate's tolerance.
    pub(crate) gtol: f64,
    pub(crate) started: Instant,
}

impl<S: System> Record<'_, S> {
    /// The estimate of a run whose start could not be evaluated: the start, no history.
    pub(crate) fn start_failed(
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
    pub(crate) fn finish(
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
    pub(crate) fn judge(&self, ev: &Evaluations<'_, S>, point: &Iterate) -> Judged {
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

impl<S: System> Problem<S> {
    /// Covariance of the estimates (as values) from the normal matrix at the estimate, scaled
    /// by the residual variance s² = ε / (N − k):  Cov = s² A⁻¹, transformed to values by the
    /// delta method. Unknowns `held` on a bound are not estimated there: the covariance is
    /// that of the free ones, s² (A_FF)⁻¹ with s² = ε / (N − k_free), and the held ones' rows
    /// and columns are 0. `None` when there are no more data than free unknowns (no residual
    /// variance), for a record given as a function (no count N), or when A_FF is singular.
    pub fn covariance(&self, lin: &Linearization, held: &[bool]) -> Option<DMatrix<f64>> {
        let k = self.unknowns.len();
        let free: Vec<usize> = (0..k).filter(|&i| !held.get(i).copied().unwrap_or(false)).collect();
        let n = self.n_observations()?;
        if n <= free.len() || free.is_empty() {
            return None;
        }
        let s2 = lin.cost / (n - free.len()) as f64;
        let block = lin.normal.select_rows(&free).select_columns(&free);
        let inverse = NormalFactor::new(&block, f64::INFINITY).ok()?.inverse();
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
