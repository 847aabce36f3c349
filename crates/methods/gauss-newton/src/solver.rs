//! argmin's Gauss–Newton solvers as a [`Step`] of the shared driver: each driver iteration
//! is one `next_iter` of argmin's solver on the residual operator, in the free coordinates
//! of the bounds' change of variables.

use std::cell::RefCell;

use argmin::core::{IterState, Problem as ArgminProblem, Solver, State};
use argmin::solver::gaussnewton::{GaussNewton as ArgminGn, GaussNewtonLS};
use argmin::solver::linesearch::BacktrackingLineSearch;
use argmin::solver::linesearch::condition::ArmijoCondition;
use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Advance, Estimate, Evaluations, Failure, FitError, Iterate, Method, NormalFactor, Problem,
    Proposal, Rule, Step, drive,
};
use sysid_ode::System;

use crate::bounds::Map;
use crate::options::{GaussNewtonOptions, JacobianSource};
use crate::residuals::{Cache, Evaluation, Residuals};

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
        let mut step = Adapter {
            options: &self.options,
            maps: problem.unknowns().list().iter().map(Map::of).collect(),
            cache: RefCell::new(Cache::default()),
            w: Vec::new(),
            norm: f64::NAN,
            tolerance: f64::NAN,
        };
        drive(problem, name, &self.options.driver, &mut step, start)
    }
}

type Vector = DVector<f64>;
type Matrix = DMatrix<f64>;

/// argmin's solver between the driver's iterations: the current point in argmin's
/// coordinates and what its stopping rule compares.
struct Adapter<'o> {
    options: &'o GaussNewtonOptions,
    maps: Vec<Map>,
    cache: RefCell<Cache>,
    /// The current iterate in argmin's coordinates.
    w: Vec<f64>,
    /// ‖r‖ there.
    norm: f64,
    /// argmin's rule, |Δ‖r‖| < tolerance, made relative to the start: tolerance·max(‖r₀‖, 1).
    tolerance: f64,
}

impl Adapter<'_> {
    fn operator<'a, S: System>(&'a self, ev: &'a Evaluations<'a, S>) -> Residuals<'a, S> {
        Residuals { ev, source: self.options.jacobian, maps: &self.maps, cache: &self.cache }
    }

    /// The driver's iterate for an evaluation (at a finite point).
    fn iterate(&self, e: Evaluation) -> Iterate {
        let z = self.maps.iter().zip(&e.w).map(|(m, &w)| m.z(w)).collect();
        let norm = e.r.norm();
        let gradient_norm = e.jacobian.as_ref().map(|j| j.tr_mul(&e.r).norm());
        Iterate {
            z,
            cost: norm * norm,
            gradient_norm,
            linearization: e.linearization,
            linear_cost: None,
        }
    }

    /// Why argmin's iteration from w stopped with `message`: a failure the operator met, a
    /// singular JᵀJ (or the change of variables flattening on a bound), or argmin's own error.
    fn failure<S: System>(&self, problem: &Problem<S>, w: &[f64], message: String) -> Failure {
        if let Some(failure) = self.cache.borrow_mut().take_failure() {
            return failure;
        }
        let jacobian = self.cache.borrow().at(w).and_then(|e| e.jacobian.clone());
        let Some(j) = jacobian else { return Failure::Solver(message) };
        let Err(singular) = NormalFactor::new(&j.tr_mul(&j), self.options.driver.max_condition)
        else {
            return Failure::Solver(message);
        };
        let names = problem.names();
        let involved: Vec<String> = singular.unknowns.iter().map(|&i| names[i].clone()).collect();
        // dz/dw → 0 as w → ±∞: the column of an unknown pressed against its bound vanishes.
        let flat = |i: usize| self.maps[i] != Map::Free && self.maps[i].dz_dw(w[i]).abs() < 1e-8;
        if !singular.unknowns.is_empty() && singular.unknowns.iter().all(|&i| flat(i)) {
            return Failure::Solver(format!(
                "stopped on the bound of {} (the change of variables that keeps argmin inside the bounds flattens there)",
                involved.join(", ")
            ));
        }
        Failure::singular(&singular, &names)
    }
}

/// One `next_iter` of an argmin solver from `state` on `operator`: the new parameters.
fn next<S: System, Sv, G, R>(
    solver: &mut Sv,
    operator: &Residuals<'_, S>,
    state: IterState<Vector, G, Matrix, (), R, f64>,
) -> Result<Vec<f64>, String>
where
    for<'r> Sv: Solver<&'r Residuals<'r, S>, IterState<Vector, G, Matrix, (), R, f64>>,
{
    let mut problem = ArgminProblem::new(operator);
    let (state, _) = solver.next_iter(&mut problem, state).map_err(|e| e.to_string())?;
    state.get_param().map(|p| p.as_slice().to_vec()).ok_or_else(|| "no parameters".into())
}

impl<S: System> Step<S> for Adapter<'_> {
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        let w: Vec<f64> = self.maps.iter().zip(&z).map(|(m, &z)| m.w(z)).collect();
        let op = self.operator(ev);
        let e = op.evaluate(&w)?;
        if !e.r.iter().all(|v| v.is_finite()) {
            return Err(op.failure_at(&w));
        }
        self.norm = e.r.norm();
        self.tolerance = self.options.tolerance * self.norm.max(1.0);
        self.w = w;
        Ok(self.iterate(e))
    }

    /// One iteration of argmin's solver: the Gauss–Newton direction from (JᵀJ)⁻¹Jᵀr, taken
    /// whole or after argmin's backtracking line search.
    fn propose(
        &mut self,
        ev: &Evaluations<'_, S>,
        _current: &Iterate,
    ) -> Result<Proposal, Failure> {
        self.cache.borrow_mut().failure = None;
        let op = self.operator(ev);
        // J at the current point (free when it came with the residuals; argmin's own request
        // for it then finds it cached): the condition and |Jᵀr| of the history.
        let jacobian = op.jacobian_at(&self.w)?;
        let r = op.evaluate(&self.w)?.r;
        let gradient_norm = Some(jacobian.tr_mul(&r).norm());
        let condition = NormalFactor::new(&jacobian.tr_mul(&jacobian), f64::INFINITY)
            .ok()
            .map(|f| f.condition());
        let w = Vector::from_column_slice(&self.w);
        let outcome = if self.options.line_search {
            let condition = ArmijoCondition::new(self.options.armijo)
                .map_err(|e| Failure::Solver(e.to_string()))?;
            let mut solver = GaussNewtonLS::new(BacktrackingLineSearch::new(condition));
            next::<S, _, Vector, ()>(&mut solver, &op, IterState::new().param(w))
        } else {
            next(&mut ArgminGn::new(), &op, IterState::new().param(w).residuals(r))
        };
        let w_new = outcome.map_err(|message| self.failure(ev.problem(), &self.w, message))?;
        let z = self.maps.iter().zip(&w_new).map(|(m, &w)| m.z(w)).collect();
        self.w = w_new;
        Ok(Proposal { z, condition, gradient_norm, stop: None })
    }

    /// The point argmin moved to (already evaluated); argmin's rule judges the change of ‖r‖.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        _current: &Iterate,
        _proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let op = self.operator(ev);
        let e = op.evaluate(&self.w)?;
        if !e.r.iter().all(|v| v.is_finite()) {
            return Err(op.failure_at(&self.w));
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
