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
//! linearization, with the same bounded subproblem, instead of sweeping the intervals again;
//! a step that does not lower ε is shortened along the Levenberg curve
//! ([`halve_along_curve`], as goodman-halving), not by the line search (μ no longer matters).
//! This needs residual rows, so a continuous record stays with the nodes to the end.

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Estimate, Failure, FitError, Linearization, Method, Problem, Rule,
    method::{
        Advance, BoxSolution, Curve, Evaluations, Iterate, LinearLeastSquares, Proposal, Step,
        drive, halve_along_curve, minimise_in_box,
    },
    plan::PlannedNoise,
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

    /// Each interval starts from a node of its own, so a start can fail where the guess
    /// integrates.
    fn start_point(&self) -> &str {
        "multiple shooting's starting nodes (each interval starts from the data where a state is measured, else from the guess's trajectory; the single-shooting methods start from the guess alone)"
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.options.validate()?;
        if problem.n_priors() > 0 {
            return Err(FitError::Unsupported {
                method: "multiple-shooting".into(),
                what: "priors (its condensed least squares has no rows for them)".into(),
            });
        }
        for e in problem.experiments() {
            if let Some(series) =
                e.sampled().series.iter().find(|s| matches!(s.noise, PlannedNoise::Function(_)))
            {
                return Err(FitError::Unsupported {
                    method: "multiple-shooting".into(),
                    what: format!(
                        "a σ of `{}` that depends on the model or the unknowns (its condensed least squares has a fixed weight per row)",
                        series.name(e.system().signature())
                    ),
                });
            }
        }
        let grids = (0..problem.experiments().len())
            .map(|e| Grid::new(problem, e, self.options.intervals))
            .collect();
        let mut step = Shooting {
            grids,
            max_condition: self.options.driver.max_condition,
            nodes: Vec::new(),
            shots: None,
            penalty: 0.0,
            proposed: None,
            merged: false,
            curve: Curve::default(),
            step_tolerance: self.options.driver.step_tolerance,
        };
        drive(problem, "multiple-shooting", &self.options.driver, &mut step, start)
    }
}

/// Most step lengths tried in one line search.
const MAX_BACKTRACKS: usize = 30;
/// Armijo's constant.
const ARMIJO: f64 = 1e-4;
/// The least Levenberg damping of a condensed step the data do not determine, relative to
/// each column's squared norm (raised a hundredfold at a time, up to 1).
const DAMPING_FROM: f64 = 1e-10;
/// The least column scale of the damping, relative to the largest.
const DAMPING_FLOOR: f64 = 1e-6;

/// The state of the iteration: a grid per experiment, the node values at the current iterate
/// and the sweeps there, the penalty μ, and the direction of the last proposal.
struct Shooting {
    grids: Vec<Grid>,
    max_condition: f64,
    /// s_1 … s_{M−1} of each experiment.
    nodes: Vec<Vec<f64>>,
    shots: Option<Vec<Shot>>,
    penalty: f64,
    proposed: Option<Proposed>,
    /// The nodes have merged into the trajectory: the iteration goes on as single shooting.
    merged: bool,
    /// The Levenberg curve a merged iteration shortens its steps along.
    curve: Curve,
    /// The driver's step tolerance (the least step a merged iteration shortens to).
    step_tolerance: f64,
}

/// The step of the last proposal, which the advance takes.
enum Proposed {
    /// With the nodes: along the direction, by the line search on the merit function.
    Nodes(Direction),
    /// Merged: single shooting's Gauss–Newton step δz from the iterate's linearization.
    Merged(Vec<f64>, Box<Linearization>),
}

/// A step of the variables with what the line search needs.
struct Direction {
    dz: Vec<f64>,
    dnodes: Vec<Vec<f64>>,
    /// φ at the current point, with the penalty of this step.
    merit: f64,
    /// Dφ.
    slope: f64,
}

/// Δs_j = a_j + B_j Δz of one experiment's nodes: every a_j, then every B_j.
type NodeSteps = (Vec<DVector<f64>>, Vec<DMatrix<f64>>);

/// The condensed step problem: r̃, J̃ (every experiment's rows), and each experiment's
/// [`NodeSteps`].
struct Condensed {
    r: DVector<f64>,
    jacobian: DMatrix<f64>,
    nodes: Vec<NodeSteps>,
}

/// ‖d‖₁ over every experiment's defects.
fn defects_l1(shots: &[Shot]) -> f64 {
    shots.iter().map(|s| s.defects.lp_norm(1)).sum()
}

impl Shooting {
    fn sweep<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        (z, nodes): (&[f64], &[Vec<f64>]),
        derivatives: bool,
    ) -> Result<Vec<Shot>, Failure> {
        let problem = ev.problem();
        ev.run(z, || {
            let mut counts = sysid_ode::Counts::default();
            let mut shots = Vec::with_capacity(self.grids.len());
            for (grid, nodes) in self.grids.iter().zip(nodes) {
                let (shot, c) =
                    grid.shoot(problem, problem.integrator(), (z, nodes), derivatives)?;
                counts += c;
                shots.push(shot);
            }
            Ok((shots, counts))
        })
    }

    /// φ of a sweep with the current penalty.
    fn merit(&self, shots: &[Shot]) -> f64 {
        shots.iter().map(Shot::cost).sum::<f64>() + self.penalty * defects_l1(shots)
    }

    /// Whether every node matches to the accuracy at which single shooting takes over.
    fn matched<S: System>(&self, problem: &Problem<S>, shots: &[Shot]) -> bool {
        let tol = (100.0 * problem.integrator().rtol).max(1e-6);
        self.grids.iter().zip(shots).zip(&self.nodes).all(|((grid, shot), nodes)| {
            let n = grid.states;
            shot.defects.as_slice().chunks(n).zip(nodes.chunks(n)).all(|(d, s)| {
                let size = s.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                d.iter().all(|v| v.abs() <= tol * (1.0 + size))
            })
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
        let shots = self.shots.as_ref().expect("a sweep at the iterate");
        let defect = shots.iter().map(|s| s.defects.norm_squared()).sum::<f64>().sqrt();
        if self.matched(ev.problem(), shots) {
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

    /// Bock's condensing of the step problem at z (see the module's documentation), each
    /// experiment's rows stacked.
    fn condense<S: System>(&self, problem: &Problem<S>, z: &[f64], shots: &[Shot]) -> Condensed {
        let k = z.len();
        let rows: usize = shots.iter().map(|s| s.r.len()).sum();
        let mut r = DVector::zeros(rows);
        let mut jacobian = DMatrix::zeros(rows, k);
        let mut nodes = Vec::with_capacity(self.grids.len());
        let mut at = 0;
        for (grid, shot) in self.grids.iter().zip(shots) {
            let n = grid.states;
            let derivatives = shot.derivatives.as_ref().expect("a sweep with sensitivities");
            // ∂slot/∂z: the initial-value slots give ∂s_0/∂z, the parameter slots ∂α/∂z.
            let dz = problem.slot_matrix(grid.experiment, z);
            let mut a = DVector::zeros(n);
            let mut b = DMatrix::zeros(n, k);
            for &(slot, state) in &grid.initial {
                b.row_mut(state).copy_from(&dz.row(slot));
            }
            let (mut a_all, mut b_all) =
                (Vec::with_capacity(grid.len()), Vec::with_capacity(grid.len()));
            for j in 0..grid.len() {
                if j > 0 {
                    let end = &derivatives.ends[j - 1];
                    let g = end.columns(0, n);
                    let mut next = g * &b;
                    for &(slot, col) in &grid.parameters {
                        next += end.column(col) * dz.row(slot);
                    }
                    a = shot.defects.rows((j - 1) * n, n) + g * &a;
                    b = next;
                }
                a_all.push(a.clone());
                b_all.push(b.clone());
            }
            let d_rows = &derivatives.rows;
            for (index, j) in grid.row_intervals().enumerate() {
                let gs = d_rows.view((index, 0), (1, n));
                r[at + index] = shot.r[index] + (gs * &a_all[j])[0];
                let mut row = gs * &b_all[j];
                for &(slot, col) in &grid.parameters {
                    row += d_rows[(index, col)] * dz.row(slot);
                }
                jacobian.row_mut(at + index).copy_from(&row);
            }
            at += shot.r.len();
            nodes.push((a_all, b_all));
        }
        Condensed { r, jacobian, nodes }
    }
}

impl<S: System> Step<S> for Shooting {
    /// Node values from the data and the start (see [`Grid::initial_nodes`]), and the first
    /// sweep with sensitivities.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        self.nodes.clear();
        self.merged = false;
        for grid in &self.grids {
            let (nodes, counts) = grid.initial_nodes(ev.problem(), &z);
            ev.add(counts);
            self.nodes.push(nodes);
        }
        self.shots = Some(self.sweep(ev, (&z, &self.nodes), true)?);
        self.iterate(ev, z)
    }

    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        if self.merged {
            return self.propose_merged(ev, current);
        }
        let problem = ev.problem();
        let z = &current.z;
        if self.shots.as_ref().is_none_or(|s| s.iter().any(|s| s.derivatives.is_none())) {
            self.shots = Some(self.sweep(ev, (z, &self.nodes), true)?);
        }
        let shots = self.shots.as_ref().expect("a sweep at the iterate");
        let condensed = self.condense(problem, z, shots);
        let (solution, dz) = self.bounded_step(problem, z, &condensed.jacobian, &condensed.r)?;
        let mut dnodes = Vec::with_capacity(self.grids.len());
        for (grid, (a, b)) in self.grids.iter().zip(&condensed.nodes) {
            let mut steps = Vec::with_capacity(grid.states * grid.len().saturating_sub(1));
            for j in 1..grid.len() {
                let step = &a[j] + &b[j] * &dz;
                steps.extend_from_slice(&step.as_slice()[..grid.states]);
            }
            dnodes.push(steps);
        }
        // JΔ = r̃ − r + J̃Δz.
        let r: Vec<f64> = shots.iter().flat_map(|s| s.r.iter().copied()).collect();
        let r = DVector::from_vec(r);
        let change = &condensed.r - &r + &condensed.jacobian * &dz;
        let slope = 2.0 * r.dot(&change);
        let defects = defects_l1(shots);
        if defects > 0.0 {
            let required = (slope + change.norm_squared()) / (0.5 * defects);
            self.penalty = self.penalty.max(1.1 * required);
        }
        let shots = self.shots.as_ref().expect("a sweep at the iterate");
        let direction = Direction {
            merit: self.merit(shots),
            slope: slope - self.penalty * defects,
            dz: solution.x,
            dnodes,
        };
        Ok(self.proposal(problem, current, direction, solution.condition.value()))
    }

    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let problem = ev.problem();
        let direction = match self.proposed.take().expect("a proposal to follow") {
            Proposed::Nodes(direction) => direction,
            Proposed::Merged(dz, lin) => {
                // Single shooting's Gauss–Newton step, shortened along the Levenberg curve
                // where it does not lower the cost (as goodman-halving: a line search crawls
                // where the step overshoots in a sloppy direction).
                let first = self.curve.first(&lin, DVector::from_vec(dz));
                let advance = halve_along_curve(
                    ev,
                    &lin,
                    &mut self.curve,
                    (first, proposal.z),
                    MAX_BACKTRACKS,
                    0.0,
                    self.step_tolerance,
                    self.max_condition,
                )?;
                return Ok(match advance {
                    Advance::Moved(next) => Advance::Moved(next.with(DEFECT, 0.0)),
                    other => other,
                });
            }
        };
        let trial_z = |alpha: f64, full: bool| {
            if full {
                proposal.z.clone()
            } else {
                problem.unknowns().moved(&current.z, &direction.dz, alpha)
            }
        };
        let accepted = line_search(problem, &direction, |alpha, full| {
            let z = trial_z(alpha, full);
            let nodes: Vec<Vec<f64>> = self
                .nodes
                .iter()
                .zip(&direction.dnodes)
                .map(|(s, d)| s.iter().zip(d).map(|(s, d)| s + alpha * d).collect())
                .collect();
            // The full step is evaluated with sensitivities: accepted, it is the next
            // linearization; shorter steps without.
            let shots = tolerate(self.sweep(ev, (&z, &nodes), full))?;
            Ok(shots.map(|shots| (self.merit(&shots), (z, nodes, shots))))
        })?;
        let Some((z, nodes, shots)) = accepted else { return Ok(Advance::Stop(Rule::NoDescent)) };
        self.nodes = nodes;
        self.shots = Some(shots);
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
        let (solution, _) = self.bounded_step(problem, &current.z, &w.jacobian, &w.r)?;
        let z = problem.unknowns().moved(&current.z, &solution.x, 1.0);
        self.proposed = Some(Proposed::Merged(solution.x, Box::new(lin)));
        Ok(Proposal {
            z,
            condition: Some(solution.condition.value()),
            gradient_norm: None,
            stop: None,
        })
    }

    /// The minimiser of ‖r + JΔz‖² over the box the bounds leave around z.
    fn bounded_step<S: System>(
        &self,
        problem: &Problem<S>,
        z: &[f64],
        jacobian: &DMatrix<f64>,
        r: &DVector<f64>,
    ) -> Result<(BoxSolution, DVector<f64>), Failure> {
        let (lo, hi) = problem.unknowns().step_box(z, jacobian.tr_mul(r).as_slice());
        let origin = vec![0.0; z.len()];
        let subproblem = LinearLeastSquares { b: jacobian, a: r };
        let singular = match minimise_in_box(&subproblem, (&lo, &hi), &origin, self.max_condition) {
            Ok(solution) => {
                let dz = DVector::from_column_slice(&solution.x);
                return Ok((solution, dz));
            }
            Err(singular) => singular,
        };
        // Directions the data do not see: Levenberg's damping λ·diag(J̃ᵀJ̃) (Marquardt's
        // scaling), the least λ from DAMPING_FROM up that makes the step solvable. The step
        // still satisfies the linearised matching conditions (the nodes follow Δz), and it
        // descends the merit function: λ only shortens Δz towards the gradient's direction.
        let (rows, k) = jacobian.shape();
        let norms: Vec<f64> = jacobian.column_iter().map(|c| c.norm()).collect();
        let largest = norms.iter().copied().fold(0.0, f64::max);
        let floor = if largest > 0.0 { DAMPING_FLOOR * largest } else { 1.0 };
        // [J̃; √λ D] and [r̃; 0], the damping rows set again for each λ.
        let mut b = DMatrix::zeros(rows + k, k);
        b.rows_mut(0, rows).copy_from(jacobian);
        let mut a = DVector::zeros(rows + k);
        a.rows_mut(0, rows).copy_from(r);
        let mut lambda = DAMPING_FROM;
        while lambda <= 1.0 {
            for (i, d) in norms.iter().enumerate() {
                b[(rows + i, i)] = lambda.sqrt() * d.max(floor);
            }
            let damped = LinearLeastSquares { b: &b, a: &a };
            if let Ok(solution) = minimise_in_box(&damped, (&lo, &hi), &origin, self.max_condition)
            {
                let dz = DVector::from_column_slice(&solution.x);
                return Ok((solution, dz));
            }
            lambda *= 100.0;
        }
        Err(Failure::singular(&singular, &problem.names()))
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
        self.proposed = Some(Proposed::Nodes(direction));
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
