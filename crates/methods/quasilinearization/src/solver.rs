//! The iteration loop and its termination.

use std::time::Instant;

use sysid_core::{
    Convergence, Estimate, FitError, Iteration, Linearization, Method, Problem, Run, Termination,
    start_coordinates,
};
use sysid_ode::{Counts, System};

use crate::options::{QuasilinearizationOptions, Start};
use crate::step::{LeastSquares, integrate_family, next_trajectory};
use crate::trajectory::{Layout, Trajectory};

/// Quasilinearization with its options.
#[derive(Clone, Debug, Default)]
pub struct Quasilinearization {
    /// The options.
    pub options: QuasilinearizationOptions,
}

/// A finished run: the estimate and the last trajectory p + Φ c.
pub struct QuasilinearizationRun {
    /// The estimate.
    pub estimate: Estimate,
    /// The trajectory the method ended on (the state at the estimate, as the linear family
    /// gives it).
    pub trajectory: Trajectory,
}

impl Quasilinearization {
    /// With these options.
    pub fn new(options: QuasilinearizationOptions) -> Self {
        Self { options }
    }

    /// Starting from the data for measured states (`quasilinearization-data`).
    pub fn from_data() -> Self {
        Self::new(QuasilinearizationOptions::default().with_start(Start::Data))
    }

    fn method_name(&self) -> &'static str {
        match self.options.start {
            Start::Guess => "quasilinearization",
            Start::Data => "quasilinearization-data",
            Start::Trajectory(_) => "quasilinearization-trajectory",
        }
    }

    /// Fits from `start` and returns the final trajectory too.
    pub fn run<S: System>(
        &self,
        problem: &Problem<S>,
        start: &[f64],
    ) -> Result<QuasilinearizationRun, FitError> {
        let opts = &self.options;
        opts.validate().map_err(FitError::InvalidOptions)?;
        let name = self.method_name();
        if let Some(u) =
            problem.unknowns().list().iter().zip(problem.unknowns().wrt()).find_map(|(u, w)| {
                (u.log && matches!(w, sysid_ode::Wrt::InitialValue(_))).then_some(u)
            })
        {
            return Err(FitError::Unsupported {
                method: name.into(),
                what: format!(
                    "a log scale on the initial value `{}` (the family is linear in it)",
                    u.name
                ),
            });
        }
        let started = Instant::now();
        let mut z = start_coordinates(problem, start)?;
        let layout = Layout::new(problem);
        let mut counts = Counts::default();
        let mut history = Vec::new();
        let finish = |z: &[f64],
                      last: Option<&Linearization>,
                      trajectory,
                      iterations,
                      termination,
                      history,
                      counts| {
            let run = Run { iterations, termination, history, started, counts };
            Ok(QuasilinearizationRun { estimate: problem.estimate(name, z, last, run), trajectory })
        };
        // The nonlinear model's cost at an iterate: the measure every method reports.
        let nonlinear_cost = |z: &[f64], counts: &mut Counts| match problem.cost(z) {
            Ok((cost, c)) => {
                *counts += c;
                cost
            }
            Err(_) => f64::NAN,
        };
        let mut trajectory = match Trajectory::start(problem, &z, &opts.start) {
            Ok((t, c)) => {
                counts += c;
                t
            }
            Err(e) => {
                let termination = Termination::IntegrationFailed { message: e.to_string() };
                let empty = Trajectory::linear(sysid_ode::DenseSolution::new(layout.n), z.clone());
                return finish(&z, None, empty, 0, termination, history, counts);
            }
        };
        let mut cost = nonlinear_cost(&z, &mut counts);
        let (mut iterations, mut step_norm, mut linear_cost) = (0, None, None);
        let mut last: Option<Linearization> = None;
        let termination = loop {
            let family = match integrate_family(problem, &layout, &trajectory) {
                Ok(f) => f,
                Err(e) => break Termination::IntegrationFailed { message: e.to_string() },
            };
            counts += family.counts;
            let ls = LeastSquares::new(problem, &layout, &trajectory, &family);
            let mut here = ls.linearization(&z, Counts::default());
            if cost.is_finite() {
                // Report the nonlinear model's cost, the measure all methods share.
                here.cost = cost;
            }
            history.push(Iteration {
                iteration: iterations,
                cost,
                gradient_norm: here.gradient.norm(),
                step_norm,
                condition: None,
                values: problem.unknowns().values(&z),
                linear_cost,
            });
            last = Some(here);
            let (mut c, condition) = match ls.solve(opts.max_condition) {
                Ok(solution) => solution,
                Err(singular) => {
                    let names = problem.names();
                    break Termination::SingularNormalMatrix {
                        unknowns: singular.unknowns.iter().map(|&i| names[i].clone()).collect(),
                        condition: singular.condition,
                    };
                }
            };
            if let Some(row) = history.last_mut() {
                row.condition = Some(condition);
            }
            problem.unknowns().project(c.as_mut_slice());
            let step = c.iter().zip(&z).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
            let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
            let tolerance = problem.resolvable_step(opts.step_tolerance);
            if step <= tolerance * (z_norm + tolerance) {
                break Termination::Converged(Convergence::Step);
            }
            if iterations >= opts.max_iterations {
                break Termination::MaxIterations;
            }
            linear_cost = Some(ls.residual(c.as_slice()).norm_squared());
            trajectory = next_trajectory(&layout, &family, c.as_slice());
            z = c.as_slice().to_vec();
            cost = nonlinear_cost(&z, &mut counts);
            step_norm = Some(step);
            iterations += 1;
        };
        finish(&z, last.as_ref(), trajectory, iterations, termination, history, counts)
    }
}

impl<S: System> Method<S> for Quasilinearization {
    fn name(&self) -> &str {
        self.method_name()
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.run(problem, start).map(|r| r.estimate)
    }
}
