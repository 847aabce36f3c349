//! The Levenberg curve: the steps of bounded length that the Gauss–Newton model prefers, shared
//! by Levenberg–Marquardt's trust region and by Goodman's step halving.
//!
//! At an iterate with ε, U and A, the step δ(λ) minimises
//!
//!   m_λ(δ) = ε + 2Uᵀδ + δᵀAδ + λ‖Dδ‖²   over the box lo − z ≤ δ ≤ hi − z,
//!
//! with D = diag(d), d_i ← max(√A_ii, [`SCALE_MEMORY`]·d_i) at each iterate: Moré's scaling
//! (the curve does not depend on the units of the unknowns), with a memory that fades, and
//! d_i at least [`SCALE_FLOOR`] of the largest. λ = 0
//! is the Gauss–Newton step; as λ grows, ‖Dδ(λ)‖ falls and δ turns towards steepest descent.
//! [`Curve::within`] finds the λ whose step has a given scaled length Δ (within Moré's 10 %),
//! by bisection in log λ from the last λ.
//!
//! Shortening a step along the curve rather than along its line is what makes it work in a
//! sloppy direction: where the Gauss–Newton model overshoots 70 times along one direction (as
//! at Boehm's optimum), halving the line shortens every direction alike and the others crawl,
//! while the curve damps the overshooting direction first.

use nalgebra::{DMatrix, DVector};
use sysid_ode::System;

use crate::bounded::{Quadratic, minimise_in_box};
use crate::evaluate::Linearization;
use crate::evaluations::Evaluations;
use crate::linalg::{Condition, NormalFactor, Singular};
use crate::problem::Problem;
use crate::step::{Advance, Iterate};
use crate::termination::{Failure, Rule};

/// Half the Hessian of ε at the iterate `lin`, ∂U/∂z, by forward differences of U, made
/// symmetric: column j from a linearization at z + h_j e_j, h_j = √rtol·max(1, |z_j|) (the
/// gradient is accurate to about rtol, so the difference to about √rtol relative), taken
/// backwards where the box leaves no room forwards. `None` when a difference point cannot
/// be integrated (the caller keeps JᵀWJ for that iterate); a spent budget is an error.
pub fn differenced_hessian<S: System>(
    ev: &Evaluations<'_, S>,
    lin: &Linearization,
) -> Result<Option<DMatrix<f64>>, Failure> {
    let problem = ev.problem();
    let k = lin.gradient.len();
    // Differences keep to the kinks of switch times passing sample times, not even the sliver
    // over them a step may take: across one the gradient jumps.
    let (mut lo, mut hi) = problem.unknowns().step_box(&lin.z, lin.gradient.as_slice());
    problem.keep_to_kinks(&lin.z, (&mut lo, &mut hi), &|_| true, false);
    let relative = problem.integrator().rtol.sqrt();
    let mut h = DMatrix::zeros(k, k);
    for j in 0..k {
        let size = relative * lin.z[j].abs().max(1.0);
        // On a Laplace prior's kink the gradient jumps by the prior's slope over any step:
        // the difference would be that jump over h, not curvature.
        if problem.unknowns().list()[j].at_kink(lin.z[j]) {
            h.set_column(j, &lin.normal.column(j));
            continue;
        }
        let step = if hi[j] >= size {
            size
        } else if -lo[j] >= size {
            -size
        } else {
            // A box narrower than the difference: the Gauss–Newton column.
            h.set_column(j, &lin.normal.column(j));
            continue;
        };
        let mut z = lin.z.clone();
        z[j] += step;
        match ev.linearize(&z) {
            Ok(other) => h.set_column(j, &((&other.gradient - &lin.gradient) / step)),
            Err(budget @ Failure::Budget { .. }) => return Err(budget),
            Err(_) => return Ok(None),
        }
    }
    Ok(Some((&h + h.transpose()) * 0.5))
}

/// A step on the curve, with what a decision on it needs.
#[derive(Clone, Debug)]
pub struct CurveStep {
    /// δ, in coordinates.
    pub delta: DVector<f64>,
    /// ‖Dδ‖.
    pub scaled_norm: f64,
    /// The decrease the Gauss–Newton model predicts, ε − m₀(δ) = −(2Uᵀδ + δᵀAδ).
    pub predicted: f64,
    /// Its λ (0 for the Gauss–Newton step).
    pub lambda: f64,
    /// The condition number of the system solved.
    pub condition: Condition,
}

/// How much of the scaling d_i an iterate keeps when √A_ii has fallen below it.
///
/// Moré (1978) keeps the largest √A_ii seen (memory 1), so that D does not depend on the
/// units and stays bounded below. When an unknown drifts to where the data hardly see it
/// (a rate or an initial amount running towards its lower bound on a log scale, where A_ii
/// falls by orders of magnitude), that keeps its scale at the old, steep value: the trust
/// region then charges a move along it as if it were still steep, and the iteration creeps
/// there by a hundredth of a decade an iteration until the iteration budget or the progress
/// rule stops it, uncertified (Elowitz's init_Z_mRNA from the published nominal values,
/// 1 000 iterations before the progress rule). Letting d_i fall by at most a tenth per
/// iterate follows such a drift within tens of iterates and keeps D scale-free; D is still
/// bounded below on any finite run. Measured with the default method on the eleven PEtab
/// problems it imports, from nominal and from nominal + 0.1: both Elowitz fits now certify
/// (one stalled at −60.57, one stopped by the progress rule), every fit that certified before
/// certifies the same NLL, and Borghans, uncertified either way, ends 0.7 higher from
/// nominal and 20 lower from the shifted start.
pub const SCALE_MEMORY: f64 = 0.9;

/// The least d_i, as a share of the largest: a column the data hardly see is charged at
/// least this much for a move along it.
///
/// With Moré's scaling alone, a column of norm c costs c·|δ_i| in ‖Dδ‖, and the linear model
/// asks it to move about ‖r‖/c: an unknown the model does not respond to (a rate that only
/// matters once an oscillation is on, an initial amount that has long decayed) crosses its
/// whole range at almost no cost, and no radius shortens that move. Where the model responds
/// once it has moved, the step fails however small the radius: Elowitz and Borghans from
/// random starts (columns 1e-30 of the largest) stopped at iteration 0 with no descent found
/// while the residual lay along another column (optimality 0.998). A column below 1e-6 of
/// the largest has A_ii below 1e-12 of the largest diagonal entry, under what a
/// factorisation of A in double precision resolves, so charging it at that floor leaves
/// every column A can tell from zero as Moré scales it. Measured (20 and 60-start
/// multistarts on Boehm, Bruno, Sneyd, Elowitz, Borghans, Zheng, Fiedler, Crauste, Schwen,
/// Rahman, Perelson; the note of issue 41): as many starts reach the best as without the
/// floor, in 0.5–0.7 of the time, and Elowitz's 20 starts take 71 s instead of 391 s. A floor
/// of 1e-3 converged more random starts on Zheng and Borghans but brought half as many of
/// Boehm's to its best: it also charges the sloppy directions A does resolve.
pub const SCALE_FLOOR: f64 = 1e-6;

/// The share of the way to its bounds that a step may take an unknown held off them
/// ([`Curve::held_off`]): the gap to the bound shrinks tenfold a step at most, as an interior
/// trust region's steps stay inside the box (fides' θ ≥ 0.95, Coleman and Li's).
///
/// A bound can lie where the model cannot be integrated, though it can on either side of
/// it: x^n with n < 1 has an infinite slope at x = 0, so an initial amount put on its lower
/// bound 0 makes the sensitivities' first derivative ∞·0 (Borghans' Z_state^n_par, whose
/// random starts stopped on that bound's edge at NLL 1.9e3 to 2.5e5 after 11 to 30
/// iterations: every trial that put Z_state(0) on 0 failed, and the radius shrank for every
/// unknown until the steps were too short to count).
pub const HELD_OFF_SHARE: f64 = 0.9;

/// The curve's scaling and its last λ, kept from iterate to iterate.
#[derive(Clone, Debug, Default)]
pub struct Curve {
    /// d_i.
    pub scale: Vec<f64>,
    /// The λ of the last step found with λ > 0 (a start for the next search).
    pub lambda: f64,
    /// Per unknown, whether its steps keep to the kinks next to it where a switch time
    /// passes a sample time ([`Problem::kinks`](crate::Problem::kinks)); none when empty.
    pub guarded: Vec<bool>,
    /// Per unknown, whether it is held off its bounds: a trial that put it on one could not
    /// be integrated, so its steps go at most [`HELD_OFF_SHARE`] of the way to either bound;
    /// none when empty.
    pub held_off: Vec<bool>,
}

impl Curve {
    /// The box of the steps from z (corrections, as [`Problem::step_box`] gives them, with the
    /// [`guarded`](Self::guarded) unknowns kept to their kinks where `kinks`), narrowed for the
    /// unknowns [`held_off`](Self::held_off) their bounds.
    pub fn step_box<S: System>(
        &self,
        problem: &Problem<S>,
        lin: &Linearization,
        kinks: bool,
    ) -> (Vec<f64>, Vec<f64>) {
        let guarded = |i: usize| kinks && self.guarded.get(i).copied().unwrap_or(false);
        let (mut lo, mut hi) = problem.step_box(&lin.z, lin.gradient.as_slice(), &guarded);
        for (i, _) in self.held_off.iter().enumerate().filter(|(_, held)| **held) {
            lo[i] *= HELD_OFF_SHARE;
            hi[i] *= HELD_OFF_SHARE;
        }
        (lo, hi)
    }

    /// d_i ← max(√A_ii, [`SCALE_MEMORY`]·d_i); a zero column keeps its scale (1 at first);
    /// then every d_i at least [`SCALE_FLOOR`] of the largest.
    pub fn rescale(&mut self, lin: &Linearization) {
        let k = lin.gradient.len();
        self.scale.resize(k, 0.0);
        for (i, d) in self.scale.iter_mut().enumerate() {
            let now = lin.normal[(i, i)].max(0.0).sqrt();
            // A column the data do not see keeps its scale (1 if it never had one).
            if now > 0.0 {
                *d = (SCALE_MEMORY * *d).max(now);
            } else if *d == 0.0 {
                *d = 1.0;
            }
        }
        let floor = SCALE_FLOOR * self.scale.iter().copied().fold(0.0, f64::max);
        for d in self.scale.iter_mut() {
            *d = d.max(floor);
        }
    }

    /// The step `delta` (from the iterate `lin`) as a point of the curve: its scaled length
    /// and predicted decrease, after rescaling D with `lin`'s A.
    pub fn first(&mut self, lin: &Linearization, delta: DVector<f64>) -> CurveStep {
        self.rescale(lin);
        self.lambda = 0.0;
        let predicted = lin.predicted_decrease(&delta);
        CurveStep {
            scaled_norm: self.scaled_norm(delta.as_slice()),
            delta,
            predicted,
            lambda: 0.0,
            condition: Condition::known(f64::NAN),
        }
    }

    /// ‖Dv‖.
    pub fn scaled_norm(&self, v: &[f64]) -> f64 {
        v.iter().zip(&self.scale).map(|(v, d)| (v * d).powi(2)).sum::<f64>().sqrt()
    }

    /// The correction a of the step `v` from the iterate `lin`: (A + λD²) a = `rhs` solved on
    /// the unknowns `v` leaves free in the box (lo, hi), with `v`'s λ; the unknowns on a bound
    /// of the step stay there (a_i = 0). None where no unknown is free or that system is
    /// singular. Geodesic acceleration's second-order term and the crawl's chord step are
    /// such corrections.
    pub fn correction(
        &self,
        lin: &Linearization,
        v: &CurveStep,
        rhs: &DVector<f64>,
        (lo, hi): (&[f64], &[f64]),
        max_condition: f64,
    ) -> Option<DVector<f64>> {
        let k = v.delta.len();
        let free: Vec<usize> =
            (0..k).filter(|&i| v.delta[i] > lo[i] && v.delta[i] < hi[i]).collect();
        if free.is_empty() {
            return None;
        }
        let mut h = lin.normal.select_rows(&free).select_columns(&free);
        for (r, &i) in free.iter().enumerate() {
            h[(r, r)] += v.lambda * self.scale[i] * self.scale[i];
        }
        let factor = NormalFactor::new(&h, max_condition).ok()?;
        let solved = factor.solve(&rhs.select_rows(&free));
        let mut a = DVector::zeros(k);
        for (r, &i) in free.iter().enumerate() {
            a[i] = solved[r];
        }
        Some(a)
    }

    /// δ(λ) in the box, with ‖Dδ‖ and the predicted decrease.
    pub fn solve(
        &self,
        lin: &Linearization,
        (lo, hi): (&[f64], &[f64]),
        lambda: f64,
        max_condition: f64,
    ) -> Result<CurveStep, Singular> {
        let k = lin.gradient.len();
        let mut h = lin.normal.clone();
        for i in 0..k {
            h[(i, i)] += lambda * self.scale[i] * self.scale[i];
        }
        let model = Quadratic { h: &h, c: &lin.gradient };
        let solution = minimise_in_box(&model, (lo, hi), &vec![0.0; k], max_condition)?;
        let delta = DVector::from_vec(solution.x);
        let scaled_norm = self.scaled_norm(delta.as_slice());
        let predicted = lin.predicted_decrease(&delta);
        Ok(CurveStep { delta, scaled_norm, predicted, lambda, condition: solution.condition })
    }

    /// The step of scaled length about `radius` from the iterate `lin`: the Gauss–Newton step
    /// when it is that short (within 10 %), else δ(λ) with ‖Dδ(λ)‖ within 10 % of `radius`
    /// (after 60 tries, the least-λ step inside, else the most damped one). `singular` only
    /// when no λ gives a step.
    pub fn within<S: System>(
        &mut self,
        problem: &Problem<S>,
        lin: &Linearization,
        radius: f64,
        max_condition: f64,
    ) -> Result<CurveStep, Failure> {
        let (lo, hi) = self.step_box(problem, lin, true);
        let bounds = (lo.as_slice(), hi.as_slice());
        // Off the kink of a Laplace prior the model's gradient is the one-sided one, so that
        // its predicted decrease counts the prior's growth.
        let one_sided = one_sided(problem, lin);
        let lin = one_sided.as_ref().unwrap_or(lin);
        let mut singular = match self.solve(lin, bounds, 0.0, max_condition) {
            Ok(step) if step.scaled_norm <= 1.1 * radius => {
                self.lambda = 0.0;
                return Ok(step);
            }
            Ok(_) => None,
            Err(s) => Some(s),
        };
        // ‖D⁻¹U‖/Δ: the λ at which the steepest-descent limit of δ(λ) has length Δ.
        let scaled_gradient =
            lin.gradient.iter().zip(&self.scale).map(|(g, d)| (g / d).powi(2)).sum::<f64>();
        let mut lambda =
            if self.lambda > 0.0 { self.lambda } else { scaled_gradient.sqrt() / radius };
        if !(lambda > 0.0 && lambda.is_finite()) {
            lambda = 1e-3;
        }
        let (mut low, mut high) = (0.0_f64, f64::INFINITY);
        let (mut inside, mut damped): (Option<CurveStep>, Option<CurveStep>) = (None, None);
        for _ in 0..60 {
            match self.solve(lin, bounds, lambda, max_condition) {
                Ok(step) if (step.scaled_norm - radius).abs() <= 0.1 * radius => {
                    self.lambda = lambda;
                    return Ok(step);
                }
                Ok(step) if step.scaled_norm > radius => {
                    low = lambda;
                    damped = Some(step);
                }
                Ok(step) => {
                    high = lambda;
                    inside = Some(step);
                }
                Err(s) => {
                    low = lambda;
                    singular = Some(s);
                }
            }
            lambda = match (low > 0.0, high.is_finite()) {
                (_, false) => lambda * 10.0,
                (false, true) => high / 10.0,
                (true, true) => (low * high).sqrt(),
            };
        }
        match (inside.or(damped), singular) {
            (Some(step), _) => {
                self.lambda = step.lambda;
                Ok(step)
            }
            (None, singular) => {
                let k = lin.gradient.len();
                let s = singular.unwrap_or_else(|| Singular {
                    unknowns: (0..k).collect(),
                    condition: f64::INFINITY,
                    direction: vec![1.0; k],
                });
                Err(Failure::singular(&s, &problem.names()))
            }
        }
    }
}

/// The actual decrease ε(z) − ε(z⁺) of a step from `from` to `to` (both linearized) whose
/// predicted decrease is `predicted`. Below ε's accuracy (`resolution`, [`Problem::cost_resolution`]) the
/// difference of two integrated costs is noise, while the gradients from the sensitivities
/// are still accurate: where both the predicted decrease and the difference are that small,
/// the trapezoidal rule along the step, exact for a quadratic,
/// −½(∇ε(z) + ∇ε(z⁺))ᵀ(z⁺ − z) with ∇ε = 2U, measures it.
pub fn actual_decrease(
    from: &Linearization,
    to: &Linearization,
    predicted: f64,
    resolution: f64,
) -> f64 {
    let difference = from.cost - to.cost;
    if predicted <= resolution && difference.abs() <= NOISE_FLOOR * resolution {
        -(0..to.z.len())
            .map(|i| (from.gradient[i] + to.gradient[i]) * (to.z[i] - from.z[i]))
            .sum::<f64>()
    } else {
        difference
    }
}

/// `lin` with the gradient a step sees on the kinks of Laplace priors
/// ([`Unknowns::one_sided`](crate::Unknowns::one_sided)), without its residuals; `None` where
/// no unknown is on its kink.
pub fn one_sided<S: System>(problem: &Problem<S>, lin: &Linearization) -> Option<Linearization> {
    let gradient = problem.unknowns().one_sided(&lin.z, lin.gradient.as_slice())?;
    Some(Linearization {
        z: lin.z.clone(),
        cost: lin.cost,
        gradient: DVector::from_vec(gradient),
        normal: lin.normal.clone(),
        residuals: None,
        norm: lin.norm,
        experiment_costs: Vec::new(),
        counts: lin.counts,
    })
}

/// Where the costs at the two ends differ by more than this many times ε's accuracy, the
/// difference is the decrease, whatever the model predicted: the trapezoidal rule is exact
/// only for a quadratic, and a model that predicts a tiny decrease where the cost changes by
/// thousands (the first step off a plateau) is not one.
const NOISE_FLOOR: f64 = 10.0;

/// Takes the step `first` from the iterate `lin` (to `z_first`) if it lowers the cost
/// ([`actual_decrease`]) by at least `sufficient` times the decrease the model predicts (0:
/// any decrease, Goodman's rule), else halves its scaled length along the curve until one
/// does: at most `max_halvings` times, and not below the resolvable step (then
/// [`Rule::Step`]). A trial point where the model cannot be integrated counts as a step too
/// long.
#[allow(clippy::too_many_arguments)]
pub fn halve_along_curve<S: System>(
    ev: &Evaluations<'_, S>,
    lin: &Linearization,
    curve: &mut Curve,
    (mut step, mut trial): (CurveStep, Vec<f64>),
    max_halvings: usize,
    sufficient: f64,
    step_tolerance: f64,
    max_condition: f64,
) -> Result<Advance, Failure> {
    let problem = ev.problem();
    let z = &lin.z;
    let step_tolerance = problem.resolvable_step(step_tolerance);
    let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
    let negligible = step_tolerance * (z_norm + step_tolerance);
    let resolution = problem.cost_resolution(lin.cost, lin.norm);
    for halving in 0..=max_halvings {
        if halving > 0 && step.delta.norm() <= negligible {
            // Shrunk below the step tolerance without reducing the cost.
            return Ok(Advance::Stop(Rule::Step));
        }
        match ev.linearize(&trial) {
            Ok(l)
                if {
                    let actual = actual_decrease(lin, &l, step.predicted, resolution);
                    actual > 0.0 && actual >= sufficient * step.predicted
                } =>
            {
                return Ok(Advance::Moved(Iterate::linearized(l)));
            }
            Ok(_) => {}
            Err(budget @ Failure::Budget { .. }) => return Err(budget),
            Err(_) => {}
        }
        step = match curve.within(problem, lin, 0.5 * step.scaled_norm, max_condition) {
            Ok(shorter) => shorter,
            Err(_) => return Ok(Advance::Stop(Rule::NoDescent)),
        };
        trial = problem.unknowns().moved(z, step.delta.as_slice(), 1.0);
    }
    Ok(Advance::Stop(Rule::NoDescent))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(z: f64, cost: f64, gradient: f64) -> Linearization {
        Linearization {
            z: vec![z],
            cost,
            gradient: DVector::from_element(1, gradient),
            normal: DMatrix::from_element(1, 1, 1.0),
            residuals: None,
            norm: cost.sqrt(),
            experiment_costs: vec![cost],
            counts: Default::default(),
        }
    }

    #[test]
    fn an_unknown_the_data_hardly_see_moves_no_further_than_the_radius_allows() {
        // x' = −k x with k and x0 unknown, k within [−1e3, 1e3]. At the iterate the column of
        // k is 1e-15 of x0's and the residual lies along both: the Gauss–Newton step asks k
        // to move 1e15. Moré's scaling alone charges that move 1e-15 per unit, so every
        // radius lets k run to its bound; with the floor (1e-6) a radius of ½ moves k by
        // 1e-15/(λ·1e-12), λ ≈ 1: about 1e-3.
        use sysid_ode::testing::Decay;
        let problem = Problem::builder(Decay::new())
            .unknown_with(crate::Unknown::new("k", 0.0).min(-1e3).max(1e3))
            .unknown("x", 1.0)
            .data(crate::Data::discrete().series("x", &[1.0, 2.0], &[0.5, 0.25]))
            .build()
            .expect("a problem");
        let c = 1e-15;
        let lin = Linearization {
            z: vec![0.0, 1.0],
            cost: 2.0,
            gradient: DVector::from_vec(vec![-c, -1.0]),
            normal: DMatrix::from_diagonal(&DVector::from_vec(vec![c * c, 1.0])),
            residuals: None,
            norm: 2f64.sqrt(),
            experiment_costs: vec![2.0],
            counts: Default::default(),
        };
        let mut curve = Curve::default();
        curve.rescale(&lin);
        assert_eq!(curve.scale, [SCALE_FLOOR, 1.0]);
        let step = curve.within(&problem, &lin, 0.5, 1e16).expect("a step");
        assert!((step.scaled_norm - 0.5).abs() <= 0.05, "{}", step.scaled_norm);
        assert!(step.delta[0].abs() < 1e-2, "k moved {}", step.delta[0]);
        assert!(step.delta[1] > 0.4 && step.delta[1] < 0.6, "x moved {}", step.delta[1]);
    }

    #[test]
    fn the_decrease_is_the_gradients_only_within_the_noise() {
        // Within the noise (resolution 1e-4): the trapezoidal rule, −(U(0) + U(δ))·δ, exact
        // for a quadratic, here ε = 1e4 + (z − 1)² moved by δ = 1e-6.
        let (from, to) =
            (at(0.0, 1e4 + 1.0, -1.0), at(1e-6, 1e4 + (1.0 - 1e-6f64).powi(2), -(1.0 - 1e-6)));
        let exact = 1.0 - (1.0 - 1e-6f64).powi(2);
        assert!((actual_decrease(&from, &to, 2e-6, 1e-4) - exact).abs() < 1e-15);
        // The first step off a plateau: the model predicts 3e-5, the cost falls by 5634
        // (the trial point's gradient points back, so the trapezoid would say it rose).
        let (from, to) = (at(0.0, 7846.0, 1e-5), at(40.0, 2212.0, 30.0));
        assert!((actual_decrease(&from, &to, 3e-5, 7.8e-5) - 5634.0).abs() < 1e-12);
    }
}
