//! argmin's Gauss–Newton solvers as a [`Step`] of the shared driver: each driver iteration
//! is one `next_iter` of argmin's solver on the residual operator, in the free coordinates
//! of the bounds' change of variables.

use std::cell::RefCell;

use argmin::core::{
    Executor, IterState, Jacobian, LineSearch, Operator, Problem as ArgminProblem, Solver, State,
    TerminationReason,
};
use argmin::solver::gaussnewton::GaussNewton as ArgminGn;
use argmin::solver::linesearch::BacktrackingLineSearch;
use argmin::solver::linesearch::condition::ArmijoCondition;
use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Bound, Estimate, Failure, FitError, Method, Problem, Rule,
    method::{
        Advance, Evaluations, Iterate, NormalFactor, Proposal, Quadratic, Step, drive,
        minimise_in_box,
    },
};
use sysid_ode::System;

use crate::bounds::Map;
use crate::options::{GaussNewtonOptions, JacobianSource};
use crate::residuals::{Cache, Evaluation, HalfSquares, Residuals, Space};

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

impl<S: System> Method<S> for GaussNewton {
    fn name(&self) -> &str {
        match (self.options.jacobian, self.options.line_search) {
            (JacobianSource::FiniteDifferences, _) => "gauss-newton-fd",
            (JacobianSource::Sensitivities, true) => "gauss-newton-ls",
            (JacobianSource::Sensitivities, false) => "gauss-newton",
        }
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.options.validate()?;
        let name = <Self as Method<S>>::name(self);
        let k = problem.unknowns().len();
        let mut step = Adapter {
            options: &self.options,
            space: Space {
                maps: problem.unknowns().list().iter().map(Map::of).collect(),
                held: vec![None; k],
                w: Vec::new(),
            },
            typical: Vec::new(),
            cache: RefCell::new(Cache::default()),
            norm: f64::NAN,
            tolerance: f64::NAN,
        };
        drive(problem, name, &self.options.driver, &mut step, start)
    }
}

/// How many times a step that changed the held unknowns and raised the cost is halved as a
/// whole before it is taken again with the unknowns held as before (2⁻¹²: a step that short
/// is no longer the model's).
const MAX_WHOLE_HALVINGS: usize = 12;

/// The largest change of a bounded unknown's free coordinate w that a line search starts
/// with (softplus: a factor e⁴ ≈ 55 near the bound, 4 coordinate units far from it).
const MAX_MAPPED_MOVE: f64 = 4.0;

type Vector = DVector<f64>;
type Matrix = DMatrix<f64>;

/// argmin's solver between the driver's iterations: argmin's coordinates (which unknowns
/// are held on a bound, the others' w) and what argmin's stopping rule compares.
struct Adapter<'o> {
    options: &'o GaussNewtonOptions,
    space: Space,
    /// Typical magnitudes of the coordinates, from the start (1 where it is 0).
    typical: Vec<f64>,
    cache: RefCell<Cache>,
    /// ‖r‖ at the current iterate.
    norm: f64,
    /// argmin's rule, |Δ‖r‖| < tolerance, made relative to the start: tolerance·max(‖r₀‖, 1).
    tolerance: f64,
}

impl Adapter<'_> {
    fn operator<'a, S: System>(&'a self, ev: &'a Evaluations<'a, S>) -> Residuals<'a, S> {
        Residuals {
            ev,
            source: self.options.jacobian,
            space: &self.space,
            typical: &self.typical,
            cache: &self.cache,
        }
    }

    /// The driver's iterate for an evaluation (at a finite point).
    fn iterate(&self, e: Evaluation) -> Iterate {
        let norm = e.r.norm();
        let gradient_norm = e.jacobian.as_ref().map(|j| j.tr_mul(&e.r).norm());
        Iterate { gradient_norm, linearization: e.linearization, ..Iterate::new(e.z, norm * norm) }
    }

    /// Chooses the unknowns to hold on their bounds for this step, from the Gauss–Newton
    /// model at `here` (∂r/∂z and r): those its bounded minimiser holds
    /// ([`minimise_in_box`], the projected Gauss–Newton step's active set), each snapped onto
    /// its bound (or its Laplace prior's kink, which [`step_box`](sysid_core::Unknowns::step_box) makes one); a held unknown the model lets go is released where the model moves it. argmin then
    /// moves the others. (The change of variables alone only approaches a bound: the step
    /// in w would have to be infinite.)
    fn hold<S: System>(&mut self, problem: &Problem<S>, here: &Evaluation) {
        let Some(jacobian) = &here.jacobian else { return };
        let (normal, gradient) = (jacobian.tr_mul(jacobian), jacobian.tr_mul(&here.r));
        let (lo, hi) = problem.unknowns().step_box(&here.z, gradient.as_slice());
        let model = Quadratic { h: &normal, c: &gradient };
        let k = here.z.len();
        let Ok(step) =
            minimise_in_box(&model, (&lo, &hi), &vec![0.0; k], self.options.driver.max_condition)
        else {
            return;
        };
        for (i, u) in problem.unknowns().list().iter().enumerate() {
            let (zlo, zhi) = u.coordinate_bounds();
            match (self.space.held[i], step.active[i]) {
                (_, Some(bound)) => {
                    // The box's bound: one of the unknown's, or its Laplace prior's kink.
                    let (target, own) = match bound {
                        Bound::Upper => (here.z[i] + hi[i], zhi),
                        _ => (here.z[i] + lo[i], zlo),
                    };
                    // Whichever of the two the box's bound is: the nearer to z + δ (which
                    // rounding may leave some ulps from either).
                    self.space.held[i] = Some(match u.kink() {
                        Some(kink) if (target - kink).abs() <= (target - own).abs() => kink,
                        _ => own,
                    });
                }
                (Some(_), None) => {
                    // Released where the model moves it, not a hair inside the bound, from
                    // where the curved map would let it crawl out by a factor e⁴ a step.
                    self.space.held[i] = None;
                    self.space.w[i] = self.space.maps[i].w(here.z[i] + step.x[i]);
                }
                (None, None) => {}
            }
        }
    }

    /// Why argmin's iteration stopped with `message`: a failure the operator met, a singular
    /// JᵀJ, or argmin's own error.
    fn failure<S: System>(
        &self,
        problem: &Problem<S>,
        jacobian: &Matrix,
        message: String,
    ) -> Failure {
        if let Some(failure) = self.cache.borrow_mut().failure.take() {
            return failure;
        }
        match NormalFactor::new(&jacobian.tr_mul(jacobian), self.options.driver.max_condition) {
            Err(singular) => {
                let free = self.space.free();
                let names: Vec<String> = free.iter().map(|&i| problem.names()[i].clone()).collect();
                Failure::singular(&singular, &names)
            }
            Ok(_) => Failure::Solver(message),
        }
    }
}

/// The residual operator as argmin's Gauss–Newton step sees it: r and J divided by one power
/// of two c, the largest not above J's largest entry. The step (JᵀJ)⁻¹Jᵀr is the same to the
/// bit (a power of two scales every operation exactly), but JᵀJ's entries are near 1:
/// nalgebra inverts a matrix of up to 3 × 3 by its cofactors, whose determinant, a product
/// of three entries, overflows once they pass about 1e102 (a weight of 1e150 on the falling
/// body's data), and the step came back infinite ("the initial value of `y` became
/// non-finite") where a weight is documented to be as large as a float holds.
struct Scaled<'a, 'b, S> {
    op: &'b Residuals<'a, S>,
    c: f64,
}

impl<'a, 'b, S: System> Scaled<'a, 'b, S> {
    fn new(op: &'b Residuals<'a, S>, jacobian: &Matrix) -> Self {
        let largest = jacobian.amax();
        let c = if largest.is_normal() { 2f64.powi(largest.log2().floor() as i32) } else { 1.0 };
        Self { op, c }
    }
}

impl<S: System> Operator for &Scaled<'_, '_, S> {
    type Param = Vector;
    type Output = Vector;
    fn apply(&self, w: &Vector) -> Result<Vector, argmin::core::Error> {
        Operator::apply(&self.op, w).map(|r| r / self.c)
    }
}

impl<S: System> Jacobian for &Scaled<'_, '_, S> {
    type Param = Vector;
    type Jacobian = Matrix;
    fn jacobian(&self, w: &Vector) -> Result<Matrix, argmin::core::Error> {
        Jacobian::jacobian(&self.op, w).map(|j| j / self.c)
    }
}

/// One `next_iter` of an argmin solver from `state` on `operator`: the new parameters.
fn next<O, Sv, G, R>(
    solver: &mut Sv,
    operator: O,
    state: IterState<Vector, G, Matrix, (), R, f64>,
) -> Result<Vec<f64>, String>
where
    Sv: Solver<O, IterState<Vector, G, Matrix, (), R, f64>>,
{
    let mut problem = ArgminProblem::new(operator);
    let (state, _) = solver.next_iter(&mut problem, state).map_err(|e| e.to_string())?;
    state.get_param().map(|p| p.as_slice().to_vec()).ok_or_else(|| "no parameters".into())
}

impl<S: System> Step<S> for Adapter<'_> {
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        // A new start (the driver's next round with other noise scales) evaluates afresh.
        *self.cache.borrow_mut() = Cache::default();
        self.space.w = self.space.maps.iter().zip(&z).map(|(m, &z)| m.w(z)).collect();
        self.typical = z.iter().map(|v| if *v == 0.0 { 1.0 } else { v.abs() }).collect();
        let z = self.space.current_z();
        let op = self.operator(ev);
        let e = op.evaluate(&z)?;
        if !e.is_finite() {
            return Err(op.failure_at(&z));
        }
        self.norm = e.r.norm();
        self.tolerance = self.options.tolerance * self.norm.max(1.0);
        Ok(self.iterate(e))
    }

    /// The unknowns to hold from the projected Gauss–Newton model ([`Adapter::hold`]),
    /// then one step of argmin's solver on the others ([`Adapter::step`]).
    fn propose(
        &mut self,
        ev: &Evaluations<'_, S>,
        _current: &Iterate,
    ) -> Result<Proposal, Failure> {
        self.cache.borrow_mut().failure = None;
        // The unknowns the projected Gauss–Newton model holds on their bounds are held
        // there; argmin moves the others.
        let here = self.operator(ev).with_jacobian(&self.space.current_z())?;
        let before = self.space.clone();
        self.hold(ev.problem(), &here);
        let proposal = self.step(ev)?;
        if !self.options.line_search || !self.space.holds_otherwise(&before) {
            return Ok(proposal);
        }
        // The line search moves the free unknowns only: the holding and releasing, made from
        // the Gauss–Newton model alone, is kept only where the whole step does not raise the
        // cost (beyond its accuracy). Far from a minimum that model can pin an unknown on
        // the far bound and release others by factors of e¹⁸ (Boehm from its nominal
        // values, k_imp_homo = 9.8e4: ε from 48 to 908 in one step). Otherwise the step is
        // halved as a whole, in the coordinates z, where the box is convex: the unknowns
        // held before and after stay held, the others are free where the shorter step puts
        // them. Where no such step lowers the cost, the step is taken again with the
        // unknowns held as they were.
        let cost = 0.5 * here.r.norm_squared();
        let resolution = ev.problem().integrator().rtol * cost;
        let moved = self.operator(ev).evaluate(&proposal.z)?;
        if 0.5 * moved.r.norm_squared() <= cost + resolution {
            return Ok(proposal);
        }
        let mut alpha = 0.5;
        for _ in 0..MAX_WHOLE_HALVINGS {
            let z: Vec<f64> =
                here.z.iter().zip(&proposal.z).map(|(a, b)| a + alpha * (b - a)).collect();
            let trial = self.operator(ev).evaluate(&z)?;
            if trial.is_finite() && 0.5 * trial.r.norm_squared() < cost {
                self.space.hold_between(&before, &z);
                return Ok(Proposal { z: self.space.current_z(), ..proposal });
            }
            alpha *= 0.5;
        }
        self.space = before;
        // The point it was taken from is evaluated, its Jacobian too; the failure met at a
        // rejected point (if any) is not this step's.
        *self.cache.borrow_mut() = Cache { last: Some(here), failure: None };
        self.step(ev)
    }

    /// The driver's iterate at a point argmin moved to (already evaluated); argmin's rule
    /// judges the change of ‖r‖.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        _current: &Iterate,
        _proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let op = self.operator(ev);
        let z = self.space.current_z();
        let e = op.evaluate(&z)?;
        if !e.is_finite() {
            return Err(op.failure_at(&z));
        }
        let norm = e.r.norm();
        let change = (self.norm - norm).abs();
        self.norm = norm;
        let next = self.iterate(e);
        Ok(if change < self.tolerance {
            Advance::MovedThenStop(next, Rule::CostChange)
        } else {
            Advance::Moved(next)
        })
    }
}

impl Adapter<'_> {
    /// One Gauss–Newton step by argmin's solver on the unknowns not held: the full step, or
    /// argmin's backtracking Armijo line search along it on ½‖r‖² with its gradient Jᵀr.
    fn step<S: System>(&mut self, ev: &Evaluations<'_, S>) -> Result<Proposal, Failure> {
        let w = Vector::from_vec(self.space.free_w());
        if w.is_empty() {
            let z = self.space.current_z();
            return Ok(Proposal { z, condition: None, gradient_norm: None, stop: None });
        }
        let op = self.operator(ev);
        let z = self.space.current_z();
        let jacobian = Jacobian::jacobian(&&op, &w).map_err(|_| op.failure_at(&z))?;
        let r = Operator::apply(&&op, &w).map_err(|_| op.failure_at(&z))?;
        let gradient = jacobian.tr_mul(&r);
        let condition = NormalFactor::new(&jacobian.tr_mul(&jacobian), f64::INFINITY)
            .ok()
            .map(|f| f.condition());
        let scaled = Scaled::new(&op, &jacobian);
        let state = IterState::new().param(w.clone()).residuals(&r / scaled.c);
        let full = next(&mut ArgminGn::new(), &scaled, state)
            .map_err(|message| self.failure(ev.problem(), &jacobian, message))?;
        let w_new = if self.options.line_search {
            let direction = Vector::from_vec(full) - &w;
            let first = self.first_step(&w, &direction);
            let cost = 0.5 * r.norm_squared();
            let resolution = ev.problem().integrator().rtol * cost;
            match self.within_resolution(&op, &w, &jacobian, &r, &direction * first, resolution)? {
                Some(w_new) => w_new,
                None => self.line_search(&op, &w, direction, gradient.clone(), cost, first)?,
            }
        } else {
            full
        };
        self.space.set_free_w(&w_new);
        Ok(Proposal {
            z: self.space.current_z(),
            condition,
            gradient_norm: Some(gradient.norm()),
            stop: None,
        })
    }

    /// Whether the free unknown i sits on the curved part of its map at w.
    fn curved(&self, i: usize, w: f64) -> bool {
        let map = self.space.maps[i];
        map != Map::Free && map.dz_dw(w).abs() < 0.5 * map.dz_dw_far()
    }

    /// The step length a line search starts from: 1, or less so that no w on the curved part
    /// of its map moves by more than [`MAX_MAPPED_MOVE`] (the Gauss–Newton step through a
    /// bound's change of variables can ask for hundreds there, sending the trial point to
    /// rates that make the model stiff). Unknowns where the map is nearly the identity, and
    /// unbounded ones, are not limited.
    fn first_step(&self, w: &Vector, direction: &Vector) -> f64 {
        let largest = self
            .space
            .free()
            .iter()
            .zip(w.iter().zip(direction.iter()))
            .filter(|(i, (w, _))| self.curved(**i, **w))
            .fold(0.0f64, |m, (_, (_, d))| m.max(d.abs()));
        if largest > MAX_MAPPED_MOVE { MAX_MAPPED_MOVE / largest } else { 1.0 }
    }

    /// The step at the minimum's noise floor: where the Gauss–Newton model predicts a
    /// decrease of ½‖r‖² no larger than its accuracy (`resolution`, rtol relative), an
    /// Armijo search can only halve to nothing; the step is taken when the cost changes by
    /// no more than that accuracy, as Goodman's halving does. `None`: search as usual.
    /// (rtol·cost, not the bound of [`Problem::cost_resolution`] that Levenberg–Marquardt's
    /// ratio test uses: this rule takes steps whose cost rises within it, and that bound,
    /// far above the error an integration makes on Boehm's problem, let ε rise by 4e-6 there
    /// in one step. Near an exact fit the rule then misses steps below the noise, and the
    /// run may stop on argmin's cost-change rule short of certified.)
    fn within_resolution<S: System>(
        &self,
        op: &Residuals<'_, S>,
        w: &Vector,
        jacobian: &Matrix,
        r: &Vector,
        step: Vector,
        resolution: f64,
    ) -> Result<Option<Vec<f64>>, Failure> {
        let jd = jacobian * &step;
        let predicted = -(r.dot(&jd) + 0.5 * jd.norm_squared());
        if predicted > resolution {
            return Ok(None);
        }
        let trial = w + step;
        let trial_r = Operator::apply(&op, &trial).map_err(|e| {
            self.cache.borrow_mut().failure.take().unwrap_or(Failure::Solver(e.to_string()))
        })?;
        let change = 0.5 * trial_r.norm_squared() - 0.5 * r.norm_squared();
        Ok((change <= resolution).then(|| trial.as_slice().to_vec()))
    }

    /// argmin's backtracking line search (Armijo, contraction 1/2) from w along `direction`,
    /// on ½‖r‖² with gradient `gradient` and value `cost` at w, from the step length `first`
    /// (1: the full step, already evaluated by argmin's Gauss–Newton solver, costs nothing).
    /// At most 60 contractions (2⁻⁶⁰): a line search that finds no decrease leaves w where it
    /// is.
    fn line_search<S: System>(
        &self,
        op: &Residuals<'_, S>,
        w: &Vector,
        direction: Vector,
        gradient: Vector,
        cost: f64,
        first: f64,
    ) -> Result<Vec<f64>, Failure> {
        let solver = || -> Result<_, argmin::core::Error> {
            let condition = ArmijoCondition::new(self.options.armijo)?;
            let mut search = BacktrackingLineSearch::new(condition).rho(0.5)?;
            search.search_direction(direction.clone());
            search.initial_step_length(first)?;
            Executor::new(HalfSquares(op), search)
                .configure(|s| {
                    s.param(w.clone()).gradient(gradient.clone()).cost(cost).max_iters(60)
                })
                .run()
        };
        let result = solver().map_err(|e| {
            self.cache.borrow_mut().failure.take().unwrap_or(Failure::Solver(e.to_string()))
        })?;
        let state = result.state();
        Ok(match state.get_termination_reason() {
            Some(TerminationReason::SolverConverged) => {
                state.get_param().map_or_else(|| w.as_slice().to_vec(), |p| p.as_slice().to_vec())
            }
            _ => w.as_slice().to_vec(),
        })
    }
}
