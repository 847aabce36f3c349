//! Quasilinearization as a [`Step`] of the shared driver: integrate the linear family around
//! the current trajectory, choose its constants by least squares, move to p + Φc.

use sysid_core::{
    Advance, Estimate, Evaluations, Failure, FitError, Iterate, Method, Problem, Proposal, Step,
    drive,
};
use sysid_ode::{Counts, System};

use crate::LINEAR_COST;
use crate::options::{QuasilinearizationOptions, Start};
use crate::step::{Family, LeastSquares, integrate_family, next_trajectory};
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
    /// The last trajectory of the iteration (the state at the estimate, as the linear family
    /// gives it, when the run ended on a stopping rule).
    pub trajectory: Option<Trajectory>,
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
        self.options.validate()?;
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
        let mut step = Quasi {
            options: &self.options,
            layout: Layout::new(problem),
            trajectory: None,
            proposed: None,
        };
        let estimate = drive(problem, name, &self.options.driver, &mut step, start)?;
        Ok(QuasilinearizationRun { estimate, trajectory: step.trajectory })
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

/// The state of the iteration: the trajectory x_k(t) and the family of the last proposal.
struct Quasi<'o> {
    options: &'o QuasilinearizationOptions,
    layout: Layout,
    trajectory: Option<Trajectory>,
    /// The family around x_k, its least-squares constants c and the linear family's ε there.
    proposed: Option<(Family, Vec<f64>, f64)>,
}

/// The nonlinear model's cost at an iterate, the measure every method reports. The method
/// does not need it to move on (its iterates need not be solutions of the model), so a point
/// where the model cannot be integrated gets NaN; only a used-up budget ends the run.
fn nonlinear_cost<S: System>(ev: &Evaluations<'_, S>, z: &[f64]) -> Result<f64, Failure> {
    match ev.cost(z) {
        Ok(cost) => Ok(cost),
        Err(budget @ Failure::Budget { .. }) => Err(budget),
        Err(_) => Ok(f64::NAN),
    }
}

impl<S: System> Step<S> for Quasi<'_> {
    /// The first trajectory: the model from the guess, the data, or the caller's.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        let problem = ev.problem();
        let trajectory = ev.run(&z, || Trajectory::start(problem, &z, &self.options.start))?;
        self.trajectory = Some(trajectory);
        let cost = nonlinear_cost(ev, &z)?;
        Ok(Iterate::new(z, cost))
    }

    /// Integrates p and Φ around x_k and chooses c by least squares (QR), projected on the
    /// bounds.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        let problem = ev.problem();
        let trajectory = self.trajectory.as_ref().expect("started");
        let layout = &self.layout;
        let family = ev.run(&current.z, || {
            integrate_family(problem, layout, trajectory).map(|f| {
                let counts = f.counts;
                (f, counts)
            })
        })?;
        let ls = LeastSquares::new(problem, layout, trajectory, &family);
        let gradient_norm = Some(ls.linearization(&current.z, Counts::default()).gradient.norm());
        let (lo, hi): (Vec<f64>, Vec<f64>) =
            problem.unknowns().list().iter().map(|u| u.coordinate_bounds()).unzip();
        let (c, condition) = ls
            .solve((&lo, &hi), &current.z, self.options.driver.max_condition)
            .map_err(|s| Failure::singular(&s, &problem.names()))?;
        let mut z = c.as_slice().to_vec();
        // On the bounds exactly where it reaches them (rounding only).
        problem.unknowns().project(&mut z);
        let linear_cost = ls.residual(&z).norm_squared();
        self.proposed = Some((family, z.clone(), linear_cost));
        Ok(Proposal { z, condition: Some(condition), gradient_norm, stop: None })
    }

    /// x_{k+1} = p + Φ c, kept as a dense solution; the nonlinear model's cost at c.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        _current: &Iterate,
        _proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let (family, z, linear_cost) = self.proposed.take().expect("a proposal to take");
        self.trajectory = Some(next_trajectory(&self.layout, &family, &z));
        let cost = nonlinear_cost(ev, &z)?;
        Ok(Advance::Moved(Iterate::new(z, cost).with(LINEAR_COST, linear_cost)))
    }
}
