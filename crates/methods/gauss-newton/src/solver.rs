//! argmin's Executor with the Gauss–Newton solvers, and the translation of its run into an
//! [`Estimate`].

use std::sync::{Arc, Mutex};
use std::time::Instant;

use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{Error, Executor, KV, State, TerminationReason};
use argmin::solver::gaussnewton::{GaussNewton as ArgminGn, GaussNewtonLS};
use argmin::solver::linesearch::BacktrackingLineSearch;
use argmin::solver::linesearch::condition::ArmijoCondition;
use nalgebra::DVector;
use sysid_core::{
    Convergence, Estimate, FitError, Iteration, Method, NormalFactor, Problem, Run, Termination,
    start_coordinates,
};
use sysid_ode::System;

use crate::options::{GaussNewtonOptions, JacobianSource};
use crate::residuals::{Evaluation, Residuals};

/// The Gauss–Newton baseline: argmin's solver on the weighted residuals of a problem.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussNewton {
    /// The options.
    pub options: GaussNewtonOptions,
}

impl GaussNewton {
    /// With these options.
    pub fn new(options: GaussNewtonOptions) -> Self {
        Self { options }
    }
    /// `gauss-newton`: full steps, Jacobian from sensitivities.
    pub fn plain() -> Self {
        Self::default()
    }
    /// `gauss-newton-ls`: backtracking Armijo line search, Jacobian from sensitivities.
    pub fn line_search() -> Self {
        Self::new(GaussNewtonOptions { line_search: true, ..GaussNewtonOptions::default() })
    }
    /// `gauss-newton-fd`: line search, Jacobian by forward differences.
    pub fn finite_differences() -> Self {
        Self::new(GaussNewtonOptions {
            line_search: true,
            jacobian: JacobianSource::FiniteDifferences,
            ..GaussNewtonOptions::default()
        })
    }
}

/// One observed iterate: argmin's iteration count, the parameters, ‖r‖.
type Observed = (u64, Vec<f64>, f64);

/// Records every iterate argmin reports.
#[derive(Clone, Default)]
struct Recorder(Arc<Mutex<Vec<Observed>>>);

impl<I: State<Param = DVector<f64>, Float = f64>> Observe<I> for Recorder {
    fn observe_init(&mut self, _name: &str, state: &I, _kv: &KV) -> Result<(), Error> {
        self.push(0, state);
        Ok(())
    }
    fn observe_iter(&mut self, state: &I, _kv: &KV) -> Result<(), Error> {
        // argmin counts from 0 and shows the iterate after the update.
        self.push(state.get_iter() + 1, state);
        Ok(())
    }
}

impl Recorder {
    fn push<I: State<Param = DVector<f64>, Float = f64>>(&self, iteration: u64, state: &I) {
        let z = state.get_param().map(|p| p.as_slice().to_vec()).unwrap_or_default();
        let mut list = self.0.lock().unwrap_or_else(|p| p.into_inner());
        list.push((iteration, z, state.get_cost()));
    }
    fn take(&self) -> Vec<Observed> {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(|p| p.into_inner()))
    }
}

impl<S: System> Method<S> for GaussNewton {
    fn name(&self) -> &str {
        match (self.options.jacobian, self.options.line_search) {
            (JacobianSource::FiniteDifferences, _) => "gauss-newton-fd",
            (JacobianSource::Sensitivities, true) => "gauss-newton-ls",
            (JacobianSource::Sensitivities, false) => "gauss-newton",
        }
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        let opts = &self.options;
        opts.validate().map_err(FitError::InvalidOptions)?;
        let name = <Self as Method<S>>::name(self);
        if problem.unknowns().list().iter().any(|u| u.min.is_some() || u.max.is_some()) {
            return Err(FitError::Unsupported {
                method: name.into(),
                what: "bounds on unknowns (argmin's Gauss–Newton is unconstrained)".into(),
            });
        }
        let started = Instant::now();
        let z0 = start_coordinates(problem, start)?;
        let residuals = Residuals::new(problem, opts.jacobian);
        let recorder = Recorder::default();
        let finish = |z: &[f64], last: Option<&Evaluation>, iterations, termination, history| {
            let lin = last.and_then(Evaluation::linearization);
            let run = Run { iterations, termination, history, started, counts: residuals.counts() };
            Ok(problem.estimate(name, z, lin.as_ref(), run))
        };
        // argmin's stopping rule is absolute; scale it by the starting residual.
        let r0 = match argmin::core::Operator::apply(&&residuals, &DVector::from_column_slice(&z0))
        {
            Ok(r) => r.norm(),
            Err(e) => {
                let termination = Termination::IntegrationFailed { message: e.to_string() };
                return finish(&z0, None, 0, termination, Vec::new());
            }
        };
        let tolerance = opts.tolerance * r0.max(1.0);
        let outcome = run_argmin(&residuals, &recorder, opts, z0.clone(), tolerance);
        let observed = recorder.take();
        let history = history(problem, &residuals, &observed);

        let (z, iterations, termination) = match outcome {
            Ok((z, iterations, reason)) => {
                let termination = match reason {
                    Some(TerminationReason::SolverConverged) => {
                        Termination::Converged(Convergence::CostChange)
                    }
                    Some(TerminationReason::MaxItersReached) | None => Termination::MaxIterations,
                    Some(other) => Termination::SolverFailed { message: other.text().to_string() },
                };
                (z, iterations, termination)
            }
            Err(message) => {
                // The best iterate evaluated before the error.
                let (z, iterations) = observed
                    .iter()
                    .min_by(|a, b| a.2.total_cmp(&b.2))
                    .map_or((z0.clone(), 0), |o| (o.1.clone(), o.0 as usize));
                let termination = match residuals.failure() {
                    Some(e) => Termination::IntegrationFailed { message: e.to_string() },
                    None => singular(problem, &residuals, opts.max_condition)
                        .unwrap_or(Termination::SolverFailed { message }),
                };
                (z, iterations, termination)
            }
        };
        // The Jacobian at the answer for the covariance: usually already computed.
        let last = match residuals.evaluation_at(&z) {
            Some(e) => Some(e),
            None => match opts.jacobian {
                JacobianSource::Sensitivities => {
                    problem.residuals_and_jacobian(&z).ok().map(|lin| {
                        let w = lin.residuals.expect("residual form");
                        Evaluation { z: z.clone(), r: w.r, jacobian: Some(w.jacobian) }
                    })
                }
                JacobianSource::FiniteDifferences => residuals.finite_differences(&z).ok(),
            },
        };
        finish(&z, last.as_ref(), iterations, termination, history)
    }
}

/// Runs argmin; returns the best parameters, the iteration count and the reason, or the
/// error message.
fn run_argmin<S: System>(
    residuals: &Residuals<'_, S>,
    recorder: &Recorder,
    opts: &GaussNewtonOptions,
    z0: Vec<f64>,
    tolerance: f64,
) -> Result<(Vec<f64>, usize, Option<TerminationReason>), String> {
    let start = DVector::from_vec(z0);
    let max = opts.max_iterations;
    macro_rules! execute {
        ($solver:expr) => {{
            let result = Executor::new(residuals, $solver)
                .configure(|s| s.param(start).max_iters(max))
                .add_observer(recorder.clone(), ObserverMode::Always)
                .run()
                .map_err(|e| e.to_string())?;
            let state = result.state();
            let best = state.get_best_param().or(state.get_param()).map(|p| p.as_slice().to_vec());
            Ok((
                best.unwrap_or_default(),
                state.get_iter() as usize,
                state.get_termination_reason().cloned(),
            ))
        }};
    }
    if opts.line_search {
        let condition = ArmijoCondition::new(opts.armijo).map_err(|e| e.to_string())?;
        let solver = GaussNewtonLS::new(BacktrackingLineSearch::new(condition))
            .with_tolerance(tolerance)
            .map_err(|e| e.to_string())?;
        execute!(solver)
    } else {
        let solver = ArgminGn::new().with_tolerance(tolerance).map_err(|e| e.to_string())?;
        execute!(solver)
    }
}

/// The history in sysid's form: ε = ‖r‖², |U| = |Jᵀr| and the condition where the
/// Jacobian at that iterate was computed; step norms in coordinates, as for every method.
fn history<S: System>(
    problem: &Problem<S>,
    residuals: &Residuals<'_, S>,
    observed: &[Observed],
) -> Vec<Iteration> {
    let mut previous: Option<&[f64]> = None;
    observed
        .iter()
        .map(|(iteration, z, norm)| {
            let lin = residuals.evaluation_at(z).and_then(|e| e.linearization());
            let step_norm =
                previous.map(|p| p.iter().zip(z).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt());
            previous = Some(z);
            Iteration {
                iteration: *iteration as usize,
                cost: norm * norm,
                gradient_norm: lin.as_ref().map_or(f64::NAN, |l| l.gradient.norm()),
                step_norm,
                condition: lin
                    .and_then(|l| NormalFactor::new(&l.normal, f64::INFINITY).ok())
                    .map(|f| f.condition()),
                values: problem.unknowns().values(z),
                linear_cost: None,
            }
        })
        .collect()
}

/// A singular normal matrix at the last Jacobian, with the unknowns it involves.
fn singular<S: System>(
    problem: &Problem<S>,
    residuals: &Residuals<'_, S>,
    max_condition: f64,
) -> Option<Termination> {
    let lin = residuals.last_with_jacobian()?.linearization()?;
    let singular = NormalFactor::new(&lin.normal, max_condition).err()?;
    let names = problem.names();
    Some(Termination::SingularNormalMatrix {
        unknowns: singular.unknowns.iter().map(|&i| names[i].clone()).collect(),
        condition: singular.condition,
    })
}
