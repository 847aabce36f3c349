//! Quasilinearization as a [`Step`] of the shared driver: integrate the linear family around
//! the current trajectory, choose its constants by least squares, move to p + Φc.

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Advance, Estimate, Evaluations, Failure, FitError, Iterate, Method, PlannedNoise, Problem,
    Proposal, Step, drive,
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

/// A finished run: the estimate and the last trajectories p + Φ c.
pub struct QuasilinearizationRun {
    /// The estimate.
    pub estimate: Estimate,
    /// The last trajectory of the iteration in each experiment (the state at the estimate,
    /// as the linear family gives it, when the run ended on a stopping rule); empty when the
    /// start failed.
    pub trajectories: Vec<Trajectory>,
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
        let unsupported = |what: String| FitError::Unsupported { method: name.into(), what };
        if problem.n_priors() > 0 {
            return Err(unsupported(
                "priors (its linear two-point problems have no rows for them)".into(),
            ));
        }
        for e in problem.experiments() {
            for (s, w) in e.slots().iter().enumerate() {
                let log = e.slot_unknown(s).map(|j| &problem.declared()[j]).filter(|u| u.log);
                if let (sysid_ode::Wrt::InitialValue(_), Some(u)) = (w, log) {
                    return Err(unsupported(format!(
                        "a log scale on the initial value `{}` (the family is linear in it)",
                        u.name
                    )));
                }
            }
            if let Some(series) =
                e.sampled().series.iter().find(|s| matches!(s.noise, PlannedNoise::Function(_)))
            {
                return Err(unsupported(format!(
                    "a σ of `{}` that depends on the model or the unknowns (its least squares has a fixed weight per row)",
                    series.name(e.system().signature())
                )));
            }
        }
        let mut step = Quasi {
            options: &self.options,
            layouts: problem.experiments().iter().map(|e| Layout::new(problem, e)).collect(),
            trajectories: Vec::new(),
            proposed: None,
        };
        let estimate = drive(problem, name, &self.options.driver, &mut step, start)?;
        Ok(QuasilinearizationRun { estimate, trajectories: step.trajectories })
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

/// The state of the iteration: each experiment's trajectory x_k(t), and the families of the
/// last proposal.
struct Quasi<'o> {
    options: &'o QuasilinearizationOptions,
    layouts: Vec<Layout>,
    trajectories: Vec<Trajectory>,
    proposed: Option<Proposed>,
}

/// A proposal's families around x_k, with the slots' coordinates c_k and ∂c/∂z there, the
/// least-squares z and the linear family's ε at it.
struct Proposed {
    families: Vec<(Family, Vec<f64>, DMatrix<f64>)>,
    z: Vec<f64>,
    zk: Vec<f64>,
    linear_cost: f64,
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
    /// The first trajectories: the model from the guess, the data, or the caller's.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        let problem = ev.problem();
        self.trajectories.clear();
        for (e, layout) in problem.experiments().iter().zip(&self.layouts) {
            let trajectory =
                ev.run(&z, || Trajectory::start(problem, e, layout, &z, &self.options.start))?;
            self.trajectories.push(trajectory);
        }
        let cost = nonlinear_cost(ev, &z)?;
        Ok(Iterate::new(z, cost))
    }

    /// Integrates p and Φ of every experiment around x_k and chooses z by least squares (QR),
    /// projected on the bounds.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        let problem = ev.problem();
        let v = problem.values_at(&current.z);
        let mut families = Vec::with_capacity(self.layouts.len());
        let mut parts = Vec::with_capacity(self.layouts.len());
        for ((e, layout), trajectory) in
            problem.experiments().iter().zip(&self.layouts).zip(&self.trajectories)
        {
            let (y0, known) = e.point(&v);
            let family = ev.run(&current.z, || {
                integrate_family(e, problem.integrator(), layout, trajectory, (&y0, &known)).map(
                    |f| {
                        let counts = f.counts;
                        (f, counts)
                    },
                )
            })?;
            let (c, d) = layout.coordinates(problem, e, &current.z);
            parts.push((
                LeastSquares::new(e, layout, trajectory, &family, &known),
                c.clone(),
                d.clone(),
            ));
            families.push((family, c, d));
        }
        let ls = LeastSquares::stacked(&parts, &current.z);
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
        self.proposed =
            Some(Proposed { families, z: z.clone(), zk: current.z.clone(), linear_cost });
        Ok(Proposal { z, condition: Some(condition), gradient_norm, stop: None })
    }

    /// x_{k+1} = p + Φ c of every experiment, c = c_k + D (z_{k+1} − z_k), kept as dense
    /// solutions; the nonlinear model's cost at z_{k+1}.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        _current: &Iterate,
        _proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let Proposed { families, z, zk, linear_cost } =
            self.proposed.take().expect("a proposal to take");
        let step = DVector::from_column_slice(&z) - DVector::from_column_slice(&zk);
        self.trajectories = families
            .iter()
            .zip(&self.layouts)
            .map(|((family, c, d), layout)| {
                let next = DVector::from_column_slice(c) + d * &step;
                next_trajectory(layout, family, next.as_slice())
            })
            .collect();
        let cost = nonlinear_cost(ev, &z)?;
        Ok(Advance::Moved(Iterate::new(z, cost).with(LINEAR_COST, linear_cost)))
    }
}
