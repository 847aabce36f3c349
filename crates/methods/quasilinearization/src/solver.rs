//! Quasilinearization as a [`Step`] of the shared driver: integrate the linear family around
//! the current trajectory, choose its constants by least squares, move to p + Φc.

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Estimate, Failure, FitError, Linearization, Method, Problem, Rule,
    method::{
        Advance, Curve, CurveStep, Evaluations, Iterate, Proposal, Step, drive, halve_along_curve,
    },
    plan::PlannedNoise,
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
            if e.system().n_events() > 0 {
                return Err(unsupported(
                    "state events (its linear problems about a trajectory have no resets)".into(),
                ));
            }
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
            curve: Curve::default(),
            last_step: None,
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

/// The state of the iteration: each experiment's trajectory x_k(t), the last proposal, and
/// the Levenberg curve of the safeguard (its scaling kept from iterate to iterate).
struct Quasi<'o> {
    options: &'o QuasilinearizationOptions,
    layouts: Vec<Layout>,
    trajectories: Vec<Trajectory>,
    proposed: Option<Proposed>,
    curve: Curve,
    /// The length of the last step taken (‖z_{k+1} − z_k‖).
    last_step: Option<f64>,
}

/// What the last proposal was.
enum Proposed {
    /// Quasilinearization's own step: the families around x_k, with the slots' coordinates
    /// c_k and ∂c/∂z there, the least-squares z and the linear family's ε at it.
    Family { families: Vec<(Family, Vec<f64>, DMatrix<f64>)>, z: Vec<f64>, linear_cost: f64 },
    /// The safeguard's first step along the Levenberg curve of the model's linearization at
    /// z_k, where the linear family gave no step (its least squares singular, or its
    /// integration failed).
    Safeguard { lin: Box<Linearization>, first: CurveStep },
}

/// How many times the safeguard halves a step along the Levenberg curve before it stops
/// with no descent (as goodman-halving's default).
const MAX_HALVINGS: usize = 30;

/// The share of the predicted decrease a safeguard step must achieve (the trust-region
/// methods' ρ ≥ 1/4, Moré 1978): a step that lowers ε only by overshooting the valley's floor
/// to the other side (as the first decreasing halving of a Gauss–Newton step does where the
/// residuals' curvature dominates a sloppy direction) is halved again.
const SUFFICIENT: f64 = 0.25;

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
        self.last_step = None;
        for (e, layout) in problem.experiments().iter().zip(&self.layouts) {
            let trajectory =
                ev.run(&z, || Trajectory::start(problem, e, layout, &z, &self.options.start))?;
            self.trajectories.push(trajectory);
        }
        let cost = nonlinear_cost(ev, &z)?;
        Ok(Iterate::new(z, cost))
    }

    /// Integrates p and Φ of every experiment around x_k and chooses z by least squares (QR),
    /// projected on the bounds. Where that gives no step (a singular least-squares problem,
    /// a linear system that cannot be integrated) and the model can be integrated at z_k, the
    /// safeguard's step instead ([`Quasi::safeguard`]): `singular` only when no step can be
    /// found.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        match self.family_step(ev, current) {
            Err(failure)
                if current.cost.is_finite() && !matches!(failure, Failure::Budget { .. }) =>
            {
                let lin = self.model_at(ev, current)?;
                // No step to size from: MINPACK's first radius, ‖D z‖ (1 where it is 0).
                let radius =
                    Some(self.curve.scaled_norm(&current.z)).filter(|r| *r > 0.0).unwrap_or(1.0);
                let first = self
                    .curve
                    .within(ev.problem(), &lin, radius, self.options.driver.max_condition)
                    .map_err(|_| failure)?;
                let z = ev.problem().unknowns().moved(&current.z, first.delta.as_slice(), 1.0);
                let condition = Some(first.condition.value());
                self.proposed = Some(Proposed::Safeguard { lin: Box::new(lin), first });
                Ok(Proposal { z, condition, gradient_norm: None, stop: None })
            }
            other => other,
        }
    }

    /// Takes quasilinearization's step where it lowers the model's ε (or where ε at x_k is
    /// unknown: the model cannot be integrated there), else the safeguard's.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        _proposal: Proposal,
    ) -> Result<Advance, Failure> {
        match self.proposed.take().expect("a proposal to take") {
            Proposed::Family { families, z, linear_cost } => {
                let cost = nonlinear_cost(ev, &z)?;
                let step = DVector::from_column_slice(&z) - DVector::from_column_slice(&current.z);
                let length = step.norm();
                if current.cost.is_finite() && !self.descends(ev, current.cost, cost, length) {
                    let lin = self.model_at(ev, current)?;
                    let radius = 0.5 * self.curve.scaled_norm(step.as_slice());
                    let max_condition = self.options.driver.max_condition;
                    return match self.curve.within(ev.problem(), &lin, radius, max_condition) {
                        Ok(first) => self.safeguard(ev, &lin, first),
                        Err(_) => Ok(Advance::Stop(Rule::NoDescent)),
                    };
                }
                self.trajectories = families
                    .iter()
                    .zip(&self.layouts)
                    .map(|((family, c, d), layout)| {
                        let next = DVector::from_column_slice(c) + d * &step;
                        next_trajectory(layout, family, next.as_slice())
                    })
                    .collect();
                self.last_step = Some(length);
                Ok(Advance::Moved(Iterate::new(z, cost).with(LINEAR_COST, linear_cost)))
            }
            Proposed::Safeguard { lin, first } => self.safeguard(ev, &lin, first),
        }
    }
}

impl Quasi<'_> {
    /// The model's linearization at the iterate, where the safeguard starts: the one the
    /// safeguard's last step computed there, else integrated; the curve's scaling updated
    /// with it.
    fn model_at<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
    ) -> Result<Linearization, Failure> {
        let lin = match &current.linearization {
            Some(lin) => lin.clone(),
            None => ev.linearize(&current.z)?,
        };
        self.curve.rescale(&lin);
        Ok(lin)
    }

    /// Whether quasilinearization's step of `length` from ε = `from` to ε = `to` is taken: where
    /// ε falls by more than its accuracy (rtol relative); within that accuracy ε cannot judge
    /// the step, and the iteration's contraction does (Deuflhard's monotonicity test for
    /// Newton's method): the step is at most half the last one, as in a converging
    /// quasilinearization, whose steps shrink quadratically. (Otherwise a long step along a
    /// sloppy direction, where ε's rounding happens to be lower, is taken and undone by the
    /// safeguard, over and over.)
    fn descends<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        from: f64,
        to: f64,
        length: f64,
    ) -> bool {
        let resolution = ev.problem().integrator().rtol * from;
        to < from - resolution
            || (to <= from + resolution && self.last_step.is_some_and(|l| length <= 0.5 * l))
    }

    /// The safeguard: from z_k, where the model's own trajectory is the linear family's x_k
    /// and quasilinearization's least squares is the Gauss–Newton model, the step `first`
    /// along the Levenberg curve of that model, halved along it until ε falls (as
    /// goodman-halving); the next trajectory is the model's at the point reached.
    fn safeguard<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        lin: &Linearization,
        first: CurveStep,
    ) -> Result<Advance, Failure> {
        let problem = ev.problem();
        let trial = problem.unknowns().moved(&lin.z, first.delta.as_slice(), 1.0);
        let driver = &self.options.driver;
        let advance = halve_along_curve(
            ev,
            lin,
            &mut self.curve,
            (first, trial),
            MAX_HALVINGS,
            SUFFICIENT,
            driver.step_tolerance,
            driver.max_condition,
        )?;
        if let Advance::Moved(next) = &advance {
            self.last_step = Some(distance(&next.z, &lin.z));
            self.trajectories = self.model_trajectories(ev, &next.z)?;
        }
        Ok(advance)
    }

    /// The model's trajectory of every experiment at z.
    fn model_trajectories<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        z: &[f64],
    ) -> Result<Vec<Trajectory>, Failure> {
        let problem = ev.problem();
        problem
            .experiments()
            .iter()
            .zip(&self.layouts)
            .map(|(e, layout)| {
                ev.run(z, || Trajectory::start(problem, e, layout, z, &Start::Guess))
            })
            .collect()
    }

    /// Quasilinearization's own step: the families around x_k and their least squares.
    fn family_step<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
    ) -> Result<Proposal, Failure> {
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
        self.proposed = Some(Proposed::Family { families, z: z.clone(), linear_cost });
        Ok(Proposal { z, condition: Some(condition), gradient_norm, stop: None })
    }
}

/// ‖a − b‖.
fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}
