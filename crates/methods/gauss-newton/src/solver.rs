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
use sysid_ode::{Counts, System};

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
        let started = Instant::now();
        let residuals = Residuals::new(problem, opts.jacobian);
        // argmin works on free coordinates w; bounded unknowns are mapped (see `bounds`).
        let z0 = residuals.w(&start_coordinates(problem, start)?);
        let recorder = Recorder::default();
        let finish = |w: &[f64],
                      last: Option<&Evaluation>,
                      iterations,
                      termination,
                      history,
                      extra: Counts| {
            let lin = last.and_then(Evaluation::linearization);
            let mut counts = residuals.counts();
            counts += extra;
            let run = Run { iterations, termination, history, started, counts };
            Ok(problem.estimate(name, &residuals.z(w), lin.as_ref(), run))
        };
        // argmin's stopping rule is absolute; scale it by the starting residual.
        let r0 = match argmin::core::Operator::apply(&&residuals, &DVector::from_column_slice(&z0))
        {
            Ok(r) => r.norm(),
            Err(e) => {
                let termination = Termination::IntegrationFailed { message: e.to_string() };
                return finish(&z0, None, 0, termination, Vec::new(), Counts::default());
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
        // The Jacobian at the answer, in the problem's coordinates, for the covariance: usually
        // already computed; with mapped bounds evaluated again without the map.
        let at_answer = if residuals.is_mapped() { None } else { residuals.evaluation_at(&z) };
        let (last, extra) = match at_answer {
            Some(e) => (Some(e), Counts::default()),
            None => {
                let z_answer = residuals.z(&z);
                match opts.jacobian {
                    JacobianSource::Sensitivities => {
                        match problem.residuals_and_jacobian(&z_answer) {
                            Ok(lin) => {
                                let rows = lin.residuals.expect("residual form");
                                let e = Evaluation {
                                    z: z_answer,
                                    r: rows.r,
                                    jacobian: Some(rows.jacobian),
                                };
                                (Some(e), lin.counts)
                            }
                            Err(_) => (None, Counts::default()),
                        }
                    }
                    JacobianSource::FiniteDifferences => {
                        let plain = Residuals::unmapped(problem, opts.jacobian);
                        (plain.finite_differences(&z_answer).ok(), plain.counts())
                    }
                }
            }
        };
        let last = last.map(|mut e| {
            // The estimate reports z; the linearization is in z's coordinates.
            e.z = residuals.z(&z);
            e
        });
        finish(&z, last.as_ref(), iterations, termination, history, extra)
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
/// Jacobian at that iterate was computed; values and step norms in the problem's coordinates.
fn history<S: System>(
    problem: &Problem<S>,
    residuals: &Residuals<'_, S>,
    observed: &[Observed],
) -> Vec<Iteration> {
    let mut previous: Option<Vec<f64>> = None;
    observed
        .iter()
        .map(|(iteration, w, norm)| {
            let evaluation = residuals.evaluation_at(w);
            // argmin's line-search solver does not evaluate the start: take it from the log.
            let norm = if norm.is_finite() {
                *norm
            } else {
                evaluation.as_ref().map_or(f64::NAN, |e| e.r.norm())
            };
            let lin = evaluation.and_then(|e| e.linearization());
            let z = residuals.z(w);
            let step_norm = previous
                .as_ref()
                .map(|p| p.iter().zip(&z).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt());
            previous = Some(z.clone());
            Iteration {
                iteration: *iteration as usize,
                cost: norm * norm,
                gradient_norm: lin.as_ref().map_or(f64::NAN, |l| l.gradient.norm()),
                step_norm,
                condition: lin
                    .and_then(|l| NormalFactor::new(&l.normal, f64::INFINITY).ok())
                    .map(|f| f.condition()),
                values: problem.unknowns().values(&z),
                linear_cost: None,
            }
        })
        .collect()
}

/// A singular normal matrix at the last Jacobian, with the unknowns it involves; or, when
/// those unknowns sit on a bound, the change of variables saturating there.
fn singular<S: System>(
    problem: &Problem<S>,
    residuals: &Residuals<'_, S>,
    max_condition: f64,
) -> Option<Termination> {
    let last = residuals.last_with_jacobian()?;
    let singular = NormalFactor::new(&last.linearization()?.normal, max_condition).err()?;
    let names = problem.names();
    let z = residuals.z(&last.z);
    let on_bound = |i: usize| {
        let (lo, hi) = problem.unknowns().list()[i].coordinate_bounds();
        let tol = 1e-12 * z[i].abs().max(1.0);
        (z[i] - lo).abs() <= tol || (hi - z[i]).abs() <= tol
    };
    let involved: Vec<String> = singular.unknowns.iter().map(|&i| names[i].clone()).collect();
    if !singular.unknowns.is_empty() && singular.unknowns.iter().all(|&i| on_bound(i)) {
        return Some(Termination::SolverFailed {
            message: format!(
                "stopped on the bound of {} (the change of variables that keeps argmin inside the bounds flattens there)",
                involved.join(", ")
            ),
        });
    }
    Some(Termination::SingularNormalMatrix { unknowns: involved, condition: singular.condition })
}
