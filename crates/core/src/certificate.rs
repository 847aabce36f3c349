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
//! optimality, is never "held on a bound", and a point where every unknown is flat is not
//! certified: a run that collapses into a region where the model no longer depends on the
//! unknowns (rates underflowing to 0, every rate at a bound of a saturated model) has found
//! a plateau, not a minimum.
//!
//! The measure is computed from an integration, and carries its error: the driver measures
//! it again at a tenth of the integrator's tolerance and reports the difference as
//! `error`. The point is certified when optimality + error ≤ gtol and some unknown is not
//! flat, or when the model passes through the data to the integration's accuracy:
//! ‖r‖ ≤ τ ‖W^½ b‖ with τ = max(1e-10, 10·rtol) (1e-10 for a fixed step), a cost within
//! τ² ‖W^½ b‖² of the least possible cost 0 ([`exact_fit_tolerance`]). Noise-free data are
//! fitted only as exactly as the model is integrated: below that the first-order test
//! measures the integration's error, not the fit. Non-finite r, g or A never pass.

use serde::Serialize;
use sysid_ode::System;

use crate::evaluate::Linearization;
use crate::linalg::NormalFactor;
use crate::problem::Problem;

/// ‖W^½ r‖ / ‖W^½ b‖ at or below which the model passes through the data (ε = 0 to rounding).
pub const EXACT_FIT: f64 = 1e-10;

/// τ: ‖W^½ r‖ / ‖W^½ b‖ at or below which the model passes through the data as exactly as
/// `problem` integrates it: [`EXACT_FIT`], or 10·rtol for an adaptive integration.
pub fn exact_fit_tolerance<S: System>(problem: &Problem<S>) -> f64 {
    let integrator = problem.integrator();
    match integrator.fixed_step {
        Some(_) => EXACT_FIT,
        None => EXACT_FIT.max(10.0 * integrator.rtol),
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
    /// the tolerance (0 where not measured: an exact fit, a point that failed).
    pub error: f64,
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
}

impl Certificate {
    /// Whether the point is certified: the first-order test holds (or ε = 0 to rounding).
    pub fn holds(&self) -> bool {
        self.exact_fit || (self.optimality + self.error <= self.gtol && !self.plateau())
    }

    /// Whether every unknown is flat: the point is a plateau of the cost, which the
    /// first-order test cannot tell from a minimum.
    pub fn plateau(&self) -> bool {
        !self.flat.is_empty() && self.flat.iter().all(|f| *f)
    }

    /// Whether every unknown is held on a bound: a corner of the box, a stationary point of
    /// the bounded problem that is seldom the minimum sought (multistart reports it as such).
    pub fn corner(&self) -> bool {
        !self.active.is_empty() && self.active.iter().all(Option::is_some)
    }

    /// The certificate of a point that could not be evaluated.
    pub fn failed(k: usize, gtol: f64) -> Self {
        Self {
            optimality: f64::INFINITY,
            error: 0.0,
            gtol,
            exact_fit: false,
            active: vec![None; k],
            flat: vec![false; k],
            null_space: None,
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
    for (i, u) in problem.unknowns().list().iter().enumerate() {
        let (g, a) = (lin.gradient[i], lin.normal[(i, i)]);
        // (A NaN response counts as flat.)
        let responds = a.sqrt() * u.coordinate_scale(lin.z[i]) > gtol * norm_r;
        if !responds {
            measure.flat[i] = true;
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
        let m = cosine.min(to_bound);
        measure.value = if m.is_nan() { f64::INFINITY } else { measure.value.max(m) };
    }
    measure
}

/// The first-order optimality measure at a point ([`optimality`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Measure {
    /// max_i m_i over the unknowns that are not flat.
    pub value: f64,
    /// Per unknown: the bound it is held on.
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
        gtol,
        exact_fit,
        active,
        flat,
        null_space,
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
