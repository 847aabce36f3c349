//! The iteration loop and its termination.

use std::time::Instant;

use sysid_core::{
    Convergence, Estimate, FitError, Iteration, Linearization, Method, Problem, Run, Termination,
    start_coordinates,
};
use sysid_ode::{Counts, OdeError, System};

use crate::options::GoodmanOptions;
use crate::step::{gradient_measure, newton_step};

/// Goodman's method with its options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Goodman {
    /// The options.
    pub options: GoodmanOptions,
}

impl Goodman {
    /// The method with these options.
    pub fn new(options: GoodmanOptions) -> Self {
        Self { options }
    }
}

impl<S: System> Method<S> for Goodman {
    fn name(&self) -> &str {
        if self.options.step_halving { "goodman-halving" } else { "goodman" }
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.options.validate().map_err(FitError::InvalidOptions)?;
        let started = Instant::now();
        let mut z = start_coordinates(problem, start)?;
        let name = <Self as Method<S>>::name(self);
        let mut counts = Counts::default();
        let mut history = Vec::new();
        let finish =
            |z: &[f64], last: Option<&Linearization>, iterations, termination, history, counts| {
                let run = Run { iterations, termination, history, started, counts };
                Ok(problem.estimate(name, z, last, run))
            };
        let mut lin = match problem.linearize(&z) {
            Ok(lin) => lin,
            Err(e) => {
                let t = Termination::IntegrationFailed { message: e.to_string() };
                return finish(&z, None, 0, t, history, counts);
            }
        };
        counts += lin.counts;
        let opts = &self.options;
        let step_tolerance = problem.resolvable_step(opts.step_tolerance);
        let mut iterations = 0;
        let mut step_norm = None;
        let termination = loop {
            history.push(Iteration {
                iteration: iterations,
                cost: lin.cost,
                gradient_norm: lin.gradient.norm(),
                step_norm,
                condition: None,
                values: problem.unknowns().values(&z),
                linear_cost: None,
            });
            if lin.cost == 0.0 {
                break Termination::Converged(Convergence::ExactFit);
            }
            let held = problem.unknowns().active(&z, lin.gradient.as_slice());
            let step = match newton_step(&lin, opts.max_condition, &held) {
                Ok(step) => step,
                Err(singular) => {
                    let names = problem.names();
                    break Termination::SingularNormalMatrix {
                        unknowns: singular.unknowns.iter().map(|&i| names[i].clone()).collect(),
                        condition: singular.condition,
                    };
                }
            };
            if let Some(row) = history.last_mut() {
                row.condition = Some(step.condition);
            }
            if gradient_measure(&lin, &held) <= opts.gradient_tolerance {
                break Termination::Converged(Convergence::Gradient);
            }
            // The decrease the step predicts: ε − ε_lin(z + δ) = δᵀAδ for the Newton step.
            let predicted = step.delta.dot(&(&lin.normal * &step.delta));
            if opts.cost_tolerance > 0.0 && predicted <= opts.cost_tolerance * lin.cost {
                break Termination::Converged(Convergence::CostChange);
            }
            // The step as it would be taken: projected on the bounds.
            let mut projected: Vec<f64> = z.iter().zip(&step.delta).map(|(z, d)| z + d).collect();
            problem.unknowns().project(&mut projected);
            let moved = projected.iter().zip(&z).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
            let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
            if moved <= step_tolerance * (z_norm + step_tolerance) {
                break Termination::Converged(Convergence::Step);
            }
            if iterations >= opts.max_iterations {
                break Termination::MaxIterations;
            }
            // c ← c* + δc, then integrate again from the new initial vector.
            match update(problem, &z, &lin, &step.delta, opts, &mut counts) {
                Update::Accepted(trial, l) => {
                    let moved = trial.iter().zip(&z).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
                    step_norm = Some(moved.sqrt());
                    z = trial;
                    lin = l;
                    iterations += 1;
                }
                Update::Failed(e) => {
                    break Termination::IntegrationFailed { message: e.to_string() };
                }
                Update::NoDescent => break Termination::NoDescent,
                Update::Negligible => break Termination::Converged(Convergence::Step),
            }
        };
        finish(&z, Some(&lin), iterations, termination, history, counts)
    }
}

/// The outcome of applying a Newton step.
enum Update {
    /// The new iterate and its linearization.
    Accepted(Vec<f64>, Linearization),
    /// The model could not be integrated at the new iterate (full step, no halving).
    Failed(OdeError),
    /// Halving never reduced the cost.
    NoDescent,
    /// Halving shrank the step below the step tolerance without reducing the cost: the cost
    /// no longer changes beyond the integration's noise, so the iterate has converged.
    Negligible,
}

/// Applies z + δ (projected on the bounds). With step halving, halves δ while the cost rises
/// or the integration fails, at most `max_halvings` times.
fn update<S: System>(
    problem: &Problem<S>,
    z: &[f64],
    lin: &Linearization,
    delta: &nalgebra::DVector<f64>,
    opts: &GoodmanOptions,
    counts: &mut Counts,
) -> Update {
    let mut scale = 1.0;
    let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
    let step_tolerance = problem.resolvable_step(opts.step_tolerance);
    let negligible = step_tolerance * (z_norm + step_tolerance);
    // ε is computed to about rtol relative: a rise smaller than that says nothing.
    let resolution = problem.integrator().rtol * lin.cost;
    for _ in 0..=opts.max_halvings {
        if scale < 1.0 && scale * delta.norm() <= negligible {
            return Update::Negligible;
        }
        let mut trial: Vec<f64> = z.iter().zip(delta).map(|(z, d)| z + scale * d).collect();
        problem.unknowns().project(&mut trial);
        match problem.linearize(&trial) {
            Ok(l) => {
                *counts += l.counts;
                // The decrease the linearization predicts for this step: a step it expects
                // to change ε by less than ε's accuracy is judged by the iteration's tests,
                // not by comparing two costs that agree to their accuracy.
                let d = nalgebra::DVector::from_iterator(
                    trial.len(),
                    trial.iter().zip(z).map(|(a, b)| a - b),
                );
                let predicted = -(2.0 * lin.gradient.dot(&d) + d.dot(&(&lin.normal * &d)));
                if !opts.step_halving || l.cost <= lin.cost || predicted <= resolution {
                    return Update::Accepted(trial, l);
                }
            }
            Err(e) if !opts.step_halving => return Update::Failed(e),
            Err(_) => {}
        }
        scale *= 0.5;
    }
    Update::NoDescent
}
