//! The certificate: one first-order test at the point a method returns, the same for every
//! method, that decides whether the fit converged. A method's stopping rule says when to
//! stop; the certificate says whether the point is a minimum.
//!
//! With the weighted residuals r = W^½ (h − b), their Jacobian J, ε = ‖r‖², the half
//! gradient g = Jᵀr (Goodman's U) and a_i = ‖J_i‖² (the diagonal of A), the measure of
//! unknown i is
//!
//!   m_i = min( |g_i| / (√a_i ‖r‖),  √a_i d_i / ‖r‖ ),
//!
//! where d_i is the distance from z_i to the bound that the descent direction −g_i points at
//! (∞ without one). The first term is MINPACK's gtol cosine between the residual and the
//! column J_i: scale-free, 0 at a stationary point, at most 1. The second is the relative
//! change of ‖r‖ (to first order) that moving z_i onto that bound could make: 0 for an
//! unknown held on its bound by a gradient that pushes outwards, so such an unknown counts
//! as not free (scipy's `active_mask`, Ceres' projected gradient); away from bounds it is
//! large and the cosine decides. The optimality is max_i m_i.
//!
//! An unknown the model does not respond to at the point is *flat*: moving its coordinate by
//! its own scale (an e-fold on a log scale, its magnitude on a linear one) would change ‖r‖
//! by at most gtol relative, √a_i s_i ≤ gtol ‖r‖. The first-order test says nothing about a
//! flat unknown (a plateau is as stationary as a minimum), so it does not count in the
//! optimality. A flat unknown that rests exactly on one of its bounds is held there (the
//! bounded problem's minimum may be there; it is not estimated). Any other flat unknown is
//! *undetermined*: the data do not fix it, and the cost may go on falling as it moves without
//! end (a rate running off to 0 on its log scale: an infimum, not a minimum). A point with an
//! undetermined unknown is not certified, and neither is one where every unknown is flat: a
//! run that collapses into a region where the model no longer depends on the unknowns (rates
//! underflowing to 0, every rate at a bound of a saturated model) has found a plateau, not a
//! minimum.
//!
//! An unknown on the location of its Laplace prior, where the prior |T(θ) − μ|/b has a kink
//! and no gradient, is tested by its subgradient: with w_i the prior's slope there
//! ([`Unknown::kink_slope`](crate::Unknown::kink_slope)) and g_i the rest of the half gradient
//! (the prior's row has slope 0 on its kink), it is held there, m_i = 0, when |g_i| ≤ w_i (no
//! side descends: the L1 penalty's sparse solution); otherwise leaving the kink lowers the
//! cost at the rate |g_i| − w_i, and m_i is that in place of |g_i| in the cosine (with the
//! distance to the bound −g_i points at as above). The prior determines such an unknown: it
//! is never flat.
//!
//! An unknown whose descent direction −g_i points over a kink of the objective within reach
//! of the sliver, where a switch time it moves passes a sample time ([`Problem::kinks`]), is
//! held there like a bound ([`Bound::SwitchOnSample`]), m_i the bound's second term at the
//! distance a step may go over it; the verdict on a returned point keeps it held only where
//! the slope on the other side, from one more integration there, points back at the kink
//! ([`other_side`]).
//!
//! The measure is computed from an integration, and carries its error: the driver measures
//! it again at a tenth of the integrator's tolerance and reports the difference as
//! `error`. The point is certified when no unknown is undetermined, not every unknown is
//! flat, and either optimality + error ≤ gtol or the model passes through the data to the
//! integration's accuracy: ‖r‖ ≤ τ ‖W^½ b‖ with τ = min(1e-6, max(1e-10, 10·rtol)) (1e-10
//! for a fixed step), a cost within τ² ‖W^½ b‖² of the least possible cost 0
//! ([`exact_fit_tolerance`]). Noise-free data are fitted only as exactly as the model is
//! integrated: below that the first-order test measures the integration's error, not the
//! fit; above 1e-6 a fit is not exact, however loose the integration. Non-finite r, g or A
//! never pass.

use serde::Serialize;
use sysid_ode::System;

use crate::evaluate::Linearization;
use crate::linalg::NormalFactor;
use crate::problem::Problem;

/// ‖W^½ r‖ / ‖W^½ b‖ at or below which the model passes through the data (ε = 0 to rounding).
pub const EXACT_FIT: f64 = 1e-10;

/// The largest τ: a fit whose residuals are above a millionth of the data is not exact,
/// however loosely the model is integrated (at rtol 0.05, 10·rtol would call a residual of
/// half the data an exact fit).
pub const MAX_EXACT_FIT: f64 = 1e-6;

/// τ: ‖W^½ r‖ / ‖W^½ b‖ at or below which the model passes through the data as exactly as
/// `problem` integrates it: [`EXACT_FIT`], or 10·rtol for an adaptive integration, at most
/// [`MAX_EXACT_FIT`](crate::method::MAX_EXACT_FIT).
pub fn exact_fit_tolerance<S: System>(problem: &Problem<S>) -> f64 {
    let integrator = problem.integrator();
    match integrator.fixed_step {
        Some(_) => EXACT_FIT,
        None => (10.0 * integrator.rtol).clamp(EXACT_FIT, MAX_EXACT_FIT),
    }
}

/// The bound an unknown is held on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// Its minimum.
    Lower,
    /// Its maximum.
    Upper,
    /// The location of its Laplace prior, the kink of |T(θ) − μ|/b: the rest of the
    /// objective pulls it by no more than the prior's slope (module docs).
    PriorLocation,
    /// A kink where a switch time it moves passes a sample time: the slopes on both sides
    /// point at it (module docs).
    SwitchOnSample,
}

/// A direction the data cannot see: the normal matrix is singular at the point.
#[derive(Clone, Debug, PartialEq)]
pub struct NullSpace {
    /// Names of the unknowns involved.
    pub unknowns: Vec<String>,
    /// Condition number of the Jacobi-scaled normal matrix.
    pub condition: f64,
    /// The combination of coordinate changes δz the data do not constrain (largest
    /// component ±1), one entry per unknown.
    pub direction: Vec<f64>,
    /// The coordinate of each unknown by name: its own name, "ln k" on a log scale.
    pub coordinates: Vec<String>,
}

/// The verdict on a returned point.
#[derive(Clone, Debug, PartialEq)]
pub struct Certificate {
    /// max_i m_i (module docs); 0 for an exact fit, ∞ when r, g or A is not finite.
    pub optimality: f64,
    /// The integration error of `optimality`, measured by integrating again at a tenth of
    /// the tolerance, or, within a factor 10 of the finest rtol
    /// ([`FINEST_RTOL`](crate::method::FINEST_RTOL)), at the same tolerances with another
    /// scheme ([`other_scheme`](crate::method::other_scheme)) (0 where not measured: an exact
    /// fit, a point that failed; ∞ where that integration fails,
    /// [`unchecked`](Self::unchecked)).
    pub error: f64,
    /// The integration error of ε at the point, |ε − ε′| with ε′ from the same reference
    /// integration as `error` (0 where `error` is not measured, ∞ where that integration
    /// fails).
    pub cost_error: f64,
    /// Whether `error` was measured (for an exact fit, whose measure is 0 by definition,
    /// whether the integration that checks it was made: `error` stays 0): false for a point
    /// that failed, and where
    /// at the finest rtol the other scheme it is measured against could not integrate the
    /// model (its 0 is then not a measured 0).
    pub error_measured: bool,
    /// The tolerance it was held to.
    pub gtol: f64,
    /// The model passes through the data (ε = 0 to rounding).
    pub exact_fit: bool,
    /// Per unknown: the bound it is held on, if any.
    pub active: Vec<Option<Bound>>,
    /// Per unknown: whether the model does not respond to it at the point (module docs).
    pub flat: Vec<bool>,
    /// The direction the data cannot identify, when the normal matrix is singular there.
    pub null_space: Option<NullSpace>,
    /// Why `error` could not be measured: the failure of the integration at a tenth of the
    /// tolerance (or of a fixed step's error-controlled reference) at the point. Its value
    /// then rests on an integration that a finer one contradicts (a singularity of the model
    /// that the working integration stepped over, say) or cannot confirm: `error` is ∞ and
    /// the point is not certified.
    pub unchecked: Option<String>,
    /// With noise scales set in closed form (see [`drive`](crate::method::drive)): the largest
    /// relative change |ln(ŝ/s)| their closed form would still make at the point; it must be
    /// at most gtol too. `None` without noise scales.
    pub scales: Option<f64>,
    /// Whether the integration does not resolve the model at the point: ε, integrated again
    /// as `cost_error` measures it, moves by more than a tenth of itself and by more than ten
    /// times what the tolerances allow there
    /// ([`cost_resolution`](crate::Problem::cost_resolution)). Nothing the point's
    /// sensitivities say holds then: no unknown is flat there (the flags are withdrawn, with the
    /// null space), and the point is not certified. (A state that starts far below atol is not
    /// controlled at all: Beer's bacteria from 1e-14 at atol 1e-12 gave ε = 1.1e8, 4.2e15 at a
    /// tenth of the tolerances.)
    pub unresolved: bool,
}

impl Certificate {
    /// Whether the point is certified: the first-order test holds (or ε = 0 to rounding),
    /// its integration error could be measured where it is due and resolves the model
    /// ([`unresolved`](Self::unresolved)), no unknown is undetermined and not every unknown
    /// is flat.
    pub fn holds(&self) -> bool {
        self.holds_but_for_undetermined() && !self.has_undetermined()
    }

    /// [`holds`](Self::holds), unknowns the point finds undetermined allowed: a minimum
    /// where the model does not respond to some unknowns (a structurally flat direction),
    /// as a profile asks of its optimum.
    pub fn holds_but_for_undetermined(&self) -> bool {
        (self.exact_fit || self.optimality + self.error <= self.gtol)
            && self.unchecked.is_none()
            && !self.unresolved
            && self.scales.is_none_or(|m| m <= self.gtol)
            && !self.plateau()
    }

    /// Whether the point passes the first-order test (or is an exact fit) at the working
    /// integration while the integration that checks it could not be made
    /// ([`unchecked`](Self::unchecked)): the one reason it is not certified that no further
    /// step or finer integration can remove.
    pub fn unconfirmed(&self) -> bool {
        self.unchecked.is_some() && (self.exact_fit || self.optimality <= self.gtol)
    }

    /// The unknowns (indices) the model does not respond to at the point and that do not
    /// rest on a bound: the data do not determine them, and the cost may go on falling as
    /// they move (module docs).
    pub fn undetermined(&self) -> Vec<usize> {
        (0..self.flat.len()).filter(|&i| self.flat[i] && self.active[i].is_none()).collect()
    }

    /// Whether some unknown is [`undetermined`](Self::undetermined).
    pub fn has_undetermined(&self) -> bool {
        self.flat.iter().zip(&self.active).any(|(f, a)| *f && a.is_none())
    }

    /// Whether every unknown is flat: the point is a plateau of the cost, which the
    /// first-order test cannot tell from a minimum.
    pub fn plateau(&self) -> bool {
        !self.flat.is_empty() && self.flat.iter().all(|f| *f)
    }

    /// Whether every unknown is held on a bound: a corner of the box, a stationary point of
    /// the bounded problem that is seldom the minimum sought (multistart reports it as such).
    pub fn corner(&self) -> bool {
        !self.active.is_empty()
            && self.active.iter().all(|b| matches!(b, Some(Bound::Lower | Bound::Upper)))
    }

    /// The certificate of a point that could not be evaluated.
    pub fn failed(k: usize, gtol: f64) -> Self {
        Self {
            optimality: f64::INFINITY,
            error: 0.0,
            cost_error: 0.0,
            error_measured: false,
            gtol,
            exact_fit: false,
            active: vec![None; k],
            flat: vec![false; k],
            null_space: None,
            scales: None,
            unchecked: None,
            unresolved: false,
        }
    }
}

/// The first-order optimality measure at `lin` (coordinates `lin.z`) with the bounds of
/// `problem`'s unknowns, the bound each unknown is held on, and which are flat.
pub fn optimality<S: System>(problem: &Problem<S>, lin: &Linearization, gtol: f64) -> Measure {
    let k = lin.gradient.len();
    let norm_r = lin.norm;
    let finite = lin.cost.is_finite()
        && lin.gradient.iter().all(|v| v.is_finite())
        && lin.normal.iter().all(|v| v.is_finite());
    let mut measure = Measure { value: 0.0, active: vec![None; k], flat: vec![false; k] };
    if !finite {
        measure.value = f64::INFINITY;
        return measure;
    }
    let kinks = problem.kinks(&lin.z);
    for (i, u) in problem.unknowns().list().iter().enumerate() {
        let (g, a) = (lin.gradient[i], lin.normal[(i, i)]);
        if u.at_kink(lin.z[i]) {
            // Its prior's subgradient (module docs).
            let excess = g.abs() - u.kink_slope(lin.z[i]);
            if excess <= 0.0 {
                measure.active[i] = Some(Bound::PriorLocation);
                continue;
            }
            // Leaving it lowers the cost at the rate |g_i| − w_i, unless the bound −g_i
            // points at is where the location is (a Laplace prior at 0 on c ≥ 0): held there.
            let (lo, hi) = u.coordinate_bounds();
            let (distance, bound) =
                if g > 0.0 { (lin.z[i] - lo, Bound::Lower) } else { (hi - lin.z[i], Bound::Upper) };
            let cosine = excess / (a.sqrt() * norm_r);
            let to_bound = a.sqrt() * distance.max(0.0) / norm_r;
            if to_bound < cosine && to_bound <= gtol {
                measure.active[i] = Some(bound);
            }
            let m = cosine.min(to_bound);
            measure.value = if m.is_nan() { f64::INFINITY } else { measure.value.max(m) };
            continue;
        }
        // (A NaN response counts as flat.)
        let responds = a.sqrt() * u.coordinate_scale(lin.z[i]) > gtol * norm_r;
        if !responds {
            measure.flat[i] = true;
            // Resting exactly on a bound (where the box put it), it is held there.
            let (lo, hi) = u.coordinate_bounds();
            measure.active[i] = match lin.z[i] {
                z if z <= lo => Some(Bound::Lower),
                z if z >= hi => Some(Bound::Upper),
                _ => None,
            };
            continue;
        }
        if g == 0.0 {
            continue;
        }
        let cosine = g.abs() / (a.sqrt() * norm_r);
        let (lo, hi) = u.coordinate_bounds();
        // Descent (−g) lowers z_i when g > 0.
        let (distance, bound) =
            if g > 0.0 { (lin.z[i] - lo, Bound::Lower) } else { (hi - lin.z[i], Bound::Upper) };
        let to_bound = a.sqrt() * distance.max(0.0) / norm_r;
        if to_bound < cosine && to_bound <= gtol {
            measure.active[i] = Some(bound);
        }
        let mut m = cosine.min(to_bound);
        // A kink where a switch time passes a sample time, met at once along −g_i: held
        // there like a bound, at the distance a step may go over it (the verdict checks the
        // slope on the other side, [`other_side`]).
        if let Some(around) = kinks[i]
            && around.at(lin.z[i], -g).is_some()
        {
            let limit = if g > 0.0 { around.lo } else { around.hi };
            let to_kink = a.sqrt() * (limit - lin.z[i]).abs() / norm_r;
            if to_kink < m && to_kink <= gtol {
                measure.active[i] = Some(Bound::SwitchOnSample);
                m = to_kink;
            }
        }
        measure.value = if m.is_nan() { f64::INFINITY } else { measure.value.max(m) };
    }
    measure
}

/// The verdict on the unknowns `certificate` holds on a kink where a switch time passes a
/// sample time ([`Bound::SwitchOnSample`]): the slope on the other side of the kink, from a
/// linearization there (`linearize`, the point mirrored over the kink, at least the sliver
/// from it), must point back at it. Where it does not, crossing the kink lowers the cost: the
/// unknown is not held, and its measure is the cosine of that slope. Returns the work of the
/// linearizations made; a mirrored point that cannot be integrated leaves the claim unproven
/// (∞).
pub fn other_side<S: System>(
    problem: &Problem<S>,
    lin: &Linearization,
    certificate: &mut Certificate,
    linearize: &dyn Fn(&[f64]) -> Option<Linearization>,
) -> sysid_ode::Counts {
    let mut counts = sysid_ode::Counts::default();
    let held: Vec<usize> = (0..certificate.active.len())
        .filter(|&i| certificate.active[i] == Some(Bound::SwitchOnSample))
        .collect();
    if held.is_empty() {
        return counts;
    }
    let kinks = problem.kinks(&lin.z);
    for i in held {
        let (z, g) = (lin.z[i], lin.gradient[i]);
        let Some(around) = kinks[i] else { continue };
        let (Some(kink), Some(over)) = (around.at(z, -g), around.mirror(z, -g)) else { continue };
        let mut mirrored = lin.z.clone();
        mirrored[i] = over;
        let Some(there) = linearize(&mirrored) else {
            certificate.active[i] = None;
            certificate.optimality = f64::INFINITY;
            continue;
        };
        counts += there.counts;
        let (g, a) = (there.gradient[i], there.normal[(i, i)]);
        // Descent there, −g, points back at the kink: held.
        if g * (mirrored[i] - kink) >= 0.0 {
            continue;
        }
        certificate.active[i] = None;
        let cosine = g.abs() / (a.sqrt() * there.norm);
        certificate.optimality =
            if cosine.is_nan() { f64::INFINITY } else { certificate.optimality.max(cosine) };
    }
    counts
}

/// The point `lin.z` with every undetermined unknown (flat, off its bounds) moved onto its
/// nearer bound, where the move is one the cost cannot feel: √a_i·d_i ≤ gtol‖r‖, the test by
/// which the optimality holds a responsive unknown on a bound. `None` when no unknown moves.
/// A flat unknown a hair's breadth from its bound (a rate at 1.00001e-5 against its bound
/// 1e-5) is then on it and held; one with room to run stays undetermined. The nearer bound,
/// not the one its descent direction −g_i points at: the model barely responds to a flat
/// unknown, so the sign of g_i says little, and the first-order test allows moves of an
/// e-fold or more, which the cost can feel after all (Elowitz: a flat initial value 6.6e-8
/// above its lower bound, g_i pointing up, was sent 18 e-folds to its upper bound, and the
/// cost rose by 6e-4 of itself; the driver refused the move and the fit stopped undetermined).
pub fn onto_bounds<S: System>(
    problem: &Problem<S>,
    lin: &Linearization,
    gtol: f64,
) -> Option<Vec<f64>> {
    let measure = optimality(problem, lin, gtol);
    let mut z = lin.z.clone();
    let mut moved = false;
    for (i, u) in problem.unknowns().list().iter().enumerate() {
        if !measure.flat[i] || measure.active[i].is_some() {
            continue;
        }
        let a = lin.normal[(i, i)];
        let (lo, hi) = u.coordinate_bounds();
        let target = if z[i] - lo <= hi - z[i] { lo } else { hi };
        let felt = a.sqrt() * (target - z[i]).abs();
        if target.is_finite() && felt <= gtol * lin.norm {
            z[i] = target;
            moved = true;
        }
    }
    moved.then_some(z)
}

/// The first-order optimality measure at a point ([`optimality`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Measure {
    /// max_i m_i over the unknowns that are not flat.
    pub value: f64,
    /// Per unknown: the bound it is held on (a flat unknown resting on a bound included).
    pub active: Vec<Option<Bound>>,
    /// Per unknown: flat (module docs).
    pub flat: Vec<bool>,
}

/// The certificate at `lin` (the model's linearization at the returned point): optimality,
/// active bounds, exact fit, and the null space when the normal matrix is singular (condition
/// above `max_condition`).
pub fn certify<S: System>(
    problem: &Problem<S>,
    lin: &Linearization,
    gtol: f64,
    max_condition: f64,
) -> Certificate {
    let Measure { value, active, flat } = optimality(problem, lin, gtol);
    let exact_fit =
        lin.cost.is_finite() && lin.norm <= exact_fit_tolerance(problem) * problem.data_norm();
    let null_space = if lin.normal.iter().all(|v| v.is_finite()) {
        NormalFactor::new(&lin.normal, max_condition).err().map(|s| {
            let names = problem.names();
            let coordinates = problem.unknowns().list().iter().map(|u| match u.log {
                true => format!("ln {}", u.name),
                false => u.name.clone(),
            });
            NullSpace {
                unknowns: s.unknowns.iter().map(|&i| names[i].clone()).collect(),
                condition: s.condition,
                direction: s.direction,
                coordinates: coordinates.collect(),
            }
        })
    } else {
        None
    };
    Certificate {
        optimality: if exact_fit { 0.0 } else { value },
        error: 0.0,
        cost_error: 0.0,
        error_measured: false,
        gtol,
        exact_fit,
        active,
        flat,
        null_space,
        scales: None,
        unchecked: None,
        unresolved: false,
    }
}

impl NullSpace {
    /// The combination as a readable sum, "ln k1 − 0.98·ln k2" (coordinates: ln of log-scale
    /// unknowns), terms below 1 % of the largest left out.
    pub fn combination(&self) -> String {
        let mut out = String::new();
        for (name, &c) in self.coordinates.iter().zip(&self.direction) {
            if c.abs() < 0.01 {
                continue;
            }
            let sign = if c < 0.0 { "−" } else { "+" };
            let magnitude = if (c.abs() - 1.0).abs() < 5e-3 {
                String::new()
            } else {
                format!("{:.2}·", c.abs())
            };
            if out.is_empty() {
                out = format!("{}{magnitude}{name}", if c < 0.0 { "−" } else { "" });
            } else {
                out += &format!(" {sign} {magnitude}{name}");
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn certificate(flat: Vec<bool>, active: Vec<Option<Bound>>) -> Certificate {
        Certificate {
            optimality: 1e-9,
            error: 0.0,
            cost_error: 0.0,
            error_measured: false,
            gtol: 1e-6,
            exact_fit: false,
            active,
            flat,
            null_space: None,
            scales: None,
            unchecked: None,
            unresolved: false,
        }
    }

    /// A flat unknown off its bounds is undetermined and blocks the verdict; one resting on
    /// a bound does not; every unknown flat is a plateau; scales still moving block too.
    #[test]
    fn undetermined_unknowns_and_moving_scales_are_not_converged() {
        assert!(certificate(vec![false, false], vec![None, None]).holds());
        let c = certificate(vec![false, true], vec![None, None]);
        assert_eq!(c.undetermined(), vec![1]);
        assert!(!c.holds());
        let c = certificate(vec![false, true], vec![None, Some(Bound::Lower)]);
        assert!(c.undetermined().is_empty() && c.holds());
        assert!(!certificate(vec![true, true], vec![Some(Bound::Lower); 2]).holds());
        let mut c = certificate(vec![false], vec![None]);
        c.scales = Some(2e-6);
        assert!(!c.holds());
        c.scales = Some(5e-7);
        assert!(c.holds());
        // Held on a Laplace prior's location: not undetermined, and not a corner of the box.
        let c = certificate(vec![false, false], vec![Some(Bound::PriorLocation); 2]);
        assert!(c.holds() && !c.corner());
        assert!(certificate(vec![false], vec![Some(Bound::Upper)]).corner());
        // An exact fit does not excuse an unknown the data do not see.
        let mut c = certificate(vec![false, true], vec![None, None]);
        c.exact_fit = true;
        assert!(!c.holds());
    }

    /// A point whose check integration failed is not certified, whatever its measure says:
    /// not with optimality far below gtol, not as an exact fit (a fixed step's reference that
    /// cannot be integrated proves nothing either).
    #[test]
    fn a_point_whose_check_failed_is_not_certified() {
        for exact_fit in [false, true] {
            let mut c = certificate(vec![false, false], vec![None, None]);
            c.exact_fit = exact_fit;
            assert!(c.holds(), "exact fit {exact_fit}");
            c.unchecked = Some("too many steps".into());
            assert!(!c.holds(), "exact fit {exact_fit}");
        }
    }
}
