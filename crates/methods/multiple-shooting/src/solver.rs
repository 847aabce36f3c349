//! Multiple shooting as a [`Step`] of the shared driver.
//!
//! The variables are the unknowns z and the node values s_1 … s_{M−1} (see [`Grid`]). At a
//! point, one sweep with sensitivities gives the residuals r with their derivatives with
//! respect to (s_j, α) of their interval, the defects d_j and [G_j | P_j]. The generalised
//! Gauss–Newton step minimises ‖r + JΔ‖² subject to the linearised matching conditions
//!
//!   Δs_{j+1} = d_j + G_j Δs_j + P_j Δα,   Δs_0 = E Δz   (E picks the unknown initial values),
//!
//! and the bounds on z. Condensing (Bock's recursion) solves the conditions forward:
//! Δs_j = a_j + B_j Δz with a_0 = 0, B_0 = E, a_{j+1} = d_j + G_j a_j,
//! B_{j+1} = G_j B_j + P̂_j (P_j placed in the parameters' columns). A row of interval j,
//! with gradient (g_s, g_α), becomes r̃ = r + g_s a_j and J̃ = g_s B_j + ĝ_α, and the step is
//! the bounded linear least-squares problem min ‖r̃ + J̃ Δz‖² over the box the bounds leave
//! ([`minimise_in_box`]), followed by Δs_j = a_j + B_j Δz. With no defects, r̃ = r and J̃ is
//! single shooting's Jacobian: the iteration ends where Gauss–Newton on the original problem
//! does.
//!
//! Globalisation: a backtracking line search on the exact penalty (ℓ1 merit) function
//!
//!   φ(x) = ‖r(x)‖² + μ Σ_j ‖d_j(x)‖₁.
//!
//! The step satisfies the linearised conditions, so the slope of φ along it is
//! Dφ = 2 rᵀJΔ − μ‖d‖₁ (JΔ = r̃ − r + J̃Δz). Before each line search μ is raised, when needed,
//! to 1.1 times (2 rᵀJΔ + ‖JΔ‖²) / (½‖d‖₁), which makes Dφ ≤ −‖JΔ‖² − ½μ‖d‖₁ < 0
//! (Nocedal & Wright, Numerical Optimization, 2nd ed., eq. 18.36). The step length α starts
//! at 1 and backtracks by safeguarded quadratic interpolation (factors 0.1 to 0.5) until
//! φ(x + αΔ) ≤ φ(x) + 10⁻⁴ α Dφ; near the minimum, where |Dφ| is below φ's accuracy (rtol·φ),
//! a step that stays within that accuracy is taken.
//!
//! What the driver sees: the iterate's z and its defect ‖d‖. Until the nodes match, nothing
//! else: single shooting's ε at z is not evaluated (NaN), because z alone may not even be
//! integrable over the horizon, which is why the nodes are there. Once every node matches
//! (‖d_j‖∞ ≤ max(10⁻⁶, 100 rtol)·(1 + ‖s_{j+1}‖∞)), the iterate carries single shooting's
//! linearization at z, so that the cost, the gradient rule and the certificate are those of
//! the original problem, as for every other method.
//!
//! The nodes then merge into the trajectory (s_j = y(τ_j) of z, d = 0): with no defects the
//! condensed step is single shooting's Gauss–Newton step, so the iteration takes it from that
//! linearization, with the same bounded subproblem and line search (μ no longer matters),
//! instead of sweeping the intervals again. This needs residual rows, so a continuous record
//! stays with the nodes to the end.

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Advance, BoxSolution, Estimate, Evaluations, Failure, FitError, Iterate, LinearLeastSquares,
    Method, Problem, Proposal, Rule, Step, drive, minimise_in_box,
};
use sysid_ode::System;

use crate::DEFECT;
use crate::options::MultipleShootingOptions;
use crate::shooting::{Grid, Shot};

/// Multiple shooting with its options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MultipleShooting {
    /// The options.
    pub options: MultipleShootingOptions,
}

impl MultipleShooting {
    /// The method with these options.
    pub fn new(options: MultipleShootingOptions) -> Self {
        Self { options }
    }
}

impl<S: System> Method<S> for MultipleShooting {
    fn name(&self) -> &str {
        "multiple-shooting"
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.options.validate()?;
        let mut step = Shooting {
            grid: Grid::new(problem, self.options.intervals),
            max_condition: self.options.driver.max_condition,
            nodes: Vec::new(),
            shot: None,
            penalty: 0.0,
            proposed: None,
            merged: false,
        };
        drive(problem, "multiple-shooting", &self.options.driver, &mut step, start)
    }
}

/// Most step lengths tried in one line search.
const MAX_BACKTRACKS: usize = 30;
/// Armijo's constant.
const ARMIJO: f64 = 1e-4;

/// The state of the iteration: the grid, the node values at the current iterate and the
/// sweep there, the penalty μ, and the direction of the last proposal.
struct Shooting {
    grid: Grid,
    max_condition: f64,
    /// s_1 … s_{M−1}.
    nodes: Vec<f64>,
    shot: Option<Shot>,
    penalty: f64,
    proposed: Option<Direction>,
    /// The nodes have merged into the trajectory: the iteration goes on as single shooting.
    merged: bool,
}

/// A step of the variables with what the line search needs.
struct Direction {
    dz: Vec<f64>,
    dnodes: Vec<f64>,
    /// φ at the current point, with the penalty of this step.
    merit: f64,
    /// Dφ.
    slope: f64,
}

/// The condensed step problem: r̃, J̃, and Δs_j = a_j + B_j Δz.
struct Condensed {
    r: DVector<f64>,
    jacobian: DMatrix<f64>,
    a: Vec<DVector<f64>>,
    b: Vec<DMatrix<f64>>,
}

impl Shooting {
    fn sweep<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        (z, nodes): (&[f64], &[f64]),
        derivatives: bool,
    ) -> Result<Shot, Failure> {
        let problem = ev.problem();
        ev.run(z, || self.grid.shoot(problem, problem.integrator(), (z, nodes), derivatives))
    }

    /// φ of a sweep with the current penalty.
    fn merit(&self, shot: &Shot) -> f64 {
        shot.cost() + self.penalty * shot.defects.lp_norm(1)
    }

    /// Whether every node matches to the accuracy at which single shooting takes over.
    fn matched<S: System>(&self, problem: &Problem<S>, shot: &Shot) -> bool {
        let n = self.grid.states;
        let tol = (100.0 * problem.integrator().rtol).max(1e-6);
        shot.defects.as_slice().chunks(n).zip(self.nodes.chunks(n)).all(|(d, s)| {
            let size = s.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            d.iter().all(|v| v.abs() <= tol * (1.0 + size))
        })
    }

    /// The driver's iterate at z with the node values and sweep now current. Once the nodes
    /// match, single shooting's linearization at z, and the nodes merge into the trajectory
    /// (for discrete data: a record's linearization has no residual rows to step with).
    fn iterate<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        z: Vec<f64>,
    ) -> Result<Iterate, Failure> {
        let shot = self.shot.as_ref().expect("a sweep at the iterate");
        let defect = shot.defects.norm();
        if self.matched(ev.problem(), shot) {
            match ev.linearize(&z) {
                Ok(lin) => {
                    self.merged = lin.residuals.is_some();
                    return Ok(Iterate::linearized(lin).with(DEFECT, defect));
                }
                Err(budget @ Failure::Budget { .. }) => return Err(budget),
                Err(_) => {}
            }
        }
        Ok(unevaluated(z, defect))
    }

    /// Bock's condensing of the step problem at z (see the module's documentation).
    fn condense<S: System>(&self, problem: &Problem<S>, z: &[f64], shot: &Shot) -> Condensed {
        let grid = &self.grid;
        let (n, k) = (grid.states, z.len());
        let derivatives = shot.derivatives.as_ref().expect("a sweep with sensitivities");
        let scale: Vec<f64> =
            problem.unknowns().list().iter().zip(z).map(|(u, &zi)| u.scale(zi)).collect();
        let mut a = DVector::zeros(n);
        let mut b = DMatrix::zeros(n, k);
        for &(i, state) in &grid.initial {
            b[(state, i)] = scale[i];
        }
        let (mut a_all, mut b_all) =
            (Vec::with_capacity(grid.len()), Vec::with_capacity(grid.len()));
        for j in 0..grid.len() {
            if j > 0 {
                let end = &derivatives.ends[j - 1];
                let g = end.columns(0, n);
                let mut next = g * &b;
                for &(i, col) in &grid.parameters {
                    next.column_mut(i).axpy(1.0, &end.column(col), 1.0);
                }
                a = shot.defects.rows((j - 1) * n, n) + g * &a;
                b = next;
            }
            a_all.push(a.clone());
            b_all.push(b.clone());
        }
        let rows = &derivatives.rows;
        let mut r = shot.r.clone();
        let mut jacobian = DMatrix::zeros(rows.nrows(), k);
        for (index, j) in grid.row_intervals().enumerate() {
            let gs = rows.view((index, 0), (1, n));
            r[index] += (gs * &a_all[j])[0];
            jacobian.row_mut(index).copy_from(&(gs * &b_all[j]));
            for &(i, col) in &grid.parameters {
                jacobian[(index, i)] += rows[(index, col)];
            }
        }
        Condensed { r, jacobian, a: a_all, b: b_all }
    }
}

impl<S: System> Step<S> for Shooting {
    /// Node values from the data and the start (see [`Grid::initial_nodes`]), and the first
    /// sweep with sensitivities.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        let (nodes, counts) = self.grid.initial_nodes(ev.problem(), &z);
        ev.add(counts);
        self.nodes = nodes;
        self.shot = Some(self.sweep(ev, (&z, &self.nodes), true)?);
        self.iterate(ev, z)
    }

    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        if self.merged {
            return self.propose_merged(ev, current);
        }
        let problem = ev.problem();
        let z = &current.z;
        if self.shot.as_ref().is_none_or(|s| s.derivatives.is_none()) {
            self.shot = Some(self.sweep(ev, (z, &self.nodes), true)?);
        }
        let shot = self.shot.as_ref().expect("a sweep at the iterate");
        let condensed = self.condense(problem, z, shot);
        let (solution, dz) = self.bounded_step(problem, z, &condensed.jacobian, &condensed.r)?;
        let n = self.grid.states;
        let mut dnodes = Vec::with_capacity(self.nodes.len());
        for j in 1..self.grid.len() {
            let step = &condensed.a[j] + &condensed.b[j] * &dz;
            dnodes.extend_from_slice(&step.as_slice()[..n]);
        }
        // JΔ = r̃ − r + J̃Δz.
        let change = &condensed.r - &shot.r + &condensed.jacobian * &dz;
        let slope = 2.0 * shot.r.dot(&change);
        let defects = shot.defects.lp_norm(1);
        if defects > 0.0 {
            let required = (slope + change.norm_squared()) / (0.5 * defects);
            self.penalty = self.penalty.max(1.1 * required);
        }
        let shot = self.shot.as_ref().expect("a sweep at the iterate");
        let direction = Direction {
            merit: self.merit(shot),
            slope: slope - self.penalty * defects,
            dz: solution.x,
            dnodes,
        };
        Ok(self.proposal(problem, current, direction, solution.condition))
    }

    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let problem = ev.problem();
        let direction = self.proposed.take().expect("a proposal to follow");
        let trial_z = |alpha: f64, full: bool| {
            if full {
                proposal.z.clone()
            } else {
                problem.unknowns().moved(&current.z, &direction.dz, alpha)
            }
        };
        if self.merged {
            // Single shooting: the full step with sensitivities (accepted, it is the next
            // linearization), shorter ones without.
            let accepted = line_search(problem, &direction, |alpha, full| {
                let z = trial_z(alpha, full);
                let evaluated = if full {
                    ev.linearize(&z).map(|l| (l.cost, Some(l)))
                } else {
                    ev.residuals(&z).map(|r| (r.norm_squared(), None))
                };
                Ok(tolerate(evaluated)?.map(|(cost, lin)| (cost, (z, cost, lin))))
            })?;
            let Some((z, cost, lin)) = accepted else { return Ok(Advance::Stop(Rule::NoDescent)) };
            return Ok(Advance::Moved(
                match lin {
                    Some(lin) => Iterate::linearized(lin),
                    None => Iterate::new(z, cost),
                }
                .with(DEFECT, 0.0),
            ));
        }
        let accepted = line_search(problem, &direction, |alpha, full| {
            let z = trial_z(alpha, full);
            let nodes: Vec<f64> =
                self.nodes.iter().zip(&direction.dnodes).map(|(s, d)| s + alpha * d).collect();
            // The full step is evaluated with sensitivities: accepted, it is the next
            // linearization; shorter steps without.
            let shot = tolerate(self.sweep(ev, (&z, &nodes), full))?;
            Ok(shot.map(|shot| (self.merit(&shot), (z, nodes, shot))))
        })?;
        let Some((z, nodes, shot)) = accepted else { return Ok(Advance::Stop(Rule::NoDescent)) };
        self.nodes = nodes;
        self.shot = Some(shot);
        Ok(Advance::Moved(self.iterate(ev, z)?))
    }
}

impl Shooting {
    /// Once the nodes have merged into the trajectory: single shooting's bounded Gauss–Newton
    /// step (what condensing gives with no defects), from the iterate's linearization.
    fn propose_merged<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
    ) -> Result<Proposal, Failure> {
        let problem = ev.problem();
        let lin = match &current.linearization {
            Some(lin) => lin.clone(),
            None => ev.linearize(&current.z)?,
        };
        let w = lin.residuals.as_ref().expect("merged only with residual rows");
        let (solution, dz) = self.bounded_step(problem, &current.z, &w.jacobian, &w.r)?;
        let slope = 2.0 * w.r.dot(&(&w.jacobian * &dz));
        let direction = Direction { merit: lin.cost, slope, dz: solution.x, dnodes: Vec::new() };
        Ok(self.proposal(problem, current, direction, solution.condition))
    }

    /// The minimiser of ‖r + JΔz‖² over the box the bounds leave around z.
    fn bounded_step<S: System>(
        &self,
        problem: &Problem<S>,
        z: &[f64],
        jacobian: &DMatrix<f64>,
        r: &DVector<f64>,
    ) -> Result<(BoxSolution, DVector<f64>), Failure> {
        let (lo, hi) = problem.unknowns().step_box(z);
        let subproblem = LinearLeastSquares { b: jacobian, a: r };
        let solution =
            minimise_in_box(&subproblem, (&lo, &hi), &vec![0.0; z.len()], self.max_condition)
                .map_err(|s| Failure::singular(&s, &problem.names()))?;
        let dz = DVector::from_column_slice(&solution.x);
        Ok((solution, dz))
    }

    /// The driver's proposal for `direction`, kept for the advance.
    fn proposal<S: System>(
        &mut self,
        problem: &Problem<S>,
        current: &Iterate,
        direction: Direction,
        condition: f64,
    ) -> Proposal {
        let next = problem.unknowns().moved(&current.z, &direction.dz, 1.0);
        self.proposed = Some(direction);
        Proposal { z: next, condition: Some(condition), gradient_norm: None, stop: None }
    }
}

/// An iterate whose single-shooting ε was not evaluated (the nodes do not match yet).
fn unevaluated(z: Vec<f64>, defect: f64) -> Iterate {
    Iterate::new(z, f64::NAN).with(DEFECT, defect)
}

/// An evaluation that failed at a trial point is a step too long (None); the budget ends the
/// run.
fn tolerate<T>(evaluated: Result<T, Failure>) -> Result<Option<T>, Failure> {
    match evaluated {
        Ok(value) => Ok(Some(value)),
        Err(budget @ Failure::Budget { .. }) => Err(budget),
        Err(_) => Ok(None),
    }
}

/// Backtracking from α = 1 along `direction`: `trial(α, full)` evaluates the merit there
/// (None where it cannot be evaluated) with what the caller keeps of an accepted point.
/// Armijo's condition, or, where |Dφ| is below φ's accuracy (rtol·φ), a merit within that
/// accuracy, accepts; otherwise α shrinks by safeguarded quadratic interpolation (factor 0.1
/// to 0.5). None after [`MAX_BACKTRACKS`] step lengths.
fn line_search<S: System, T>(
    problem: &Problem<S>,
    direction: &Direction,
    mut trial: impl FnMut(f64, bool) -> Result<Option<(f64, T)>, Failure>,
) -> Result<Option<T>, Failure> {
    let resolution = problem.integrator().rtol * direction.merit;
    let mut alpha = 1.0;
    for tried in 0..MAX_BACKTRACKS {
        let evaluated = trial(alpha, tried == 0)?;
        let merit = evaluated.as_ref().map_or(f64::INFINITY, |e| e.0);
        let armijo = merit <= direction.merit + ARMIJO * alpha * direction.slope;
        let floor = -direction.slope <= resolution && merit <= direction.merit + resolution;
        if let Some((_, kept)) = evaluated.filter(|_| armijo || floor) {
            return Ok(Some(kept));
        }
        let quadratic = if merit.is_finite() {
            let curvature = merit - direction.merit - direction.slope * alpha;
            -direction.slope * alpha * alpha / (2.0 * curvature)
        } else {
            0.0
        };
        alpha = if quadratic.is_finite() {
            quadratic.clamp(0.1 * alpha, 0.5 * alpha)
        } else {
            0.5 * alpha
        };
    }
    Ok(None)
}
