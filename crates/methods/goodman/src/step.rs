//! One iteration of Goodman's method in the paper's equations.
//!
//! Given the estimated initial vector c* (every unknown, parameters being constant states,
//! eq. 4), the model and its variational equations (eq. 6) are integrated once; this gives
//! U* (eq. 12, or eq. 22 for a continuous record) and the symmetric matrix of eq. 15 (eq. 24).
//! Both are formed by [`Problem::linearize`](sysid_core::Problem::linearize). The step then
//! imposes δU = −U* (eq. 14):
//!
//! Σ_j A_ij δc_j = −U*_i,
//!
//! solved here by Cholesky after Jacobi scaling (the paper notes the matrix is symmetric).
//!
//! With bounds on the unknowns the step is the projected Newton step: δc minimises the
//! quadratic model ε + 2U*ᵀδ + δᵀAδ, whose minimiser without bounds is eq. (14), over the box
//! the bounds leave (`sysid_core::method::minimise_in_box`, an active-set method). An unknown is held
//! on its bound when the model's multiplier (U* + Aδ)_i pushes it outwards, and released only
//! when it points inwards: the active set is that of the model's minimiser, not the sign of
//! U* at the iterate, so a bound is not entered and left on alternate iterations.
//!
//! Where A is too ill-conditioned to solve (a direction the data hardly see, as two rates
//! whose product alone matters), the step is regularised at the solver's limit rather than
//! refused: the iteration goes on in the directions the data determine, and the certificate
//! at the returned point still names the combination the data cannot identify.

use nalgebra::DVector;
use sysid_core::{
    Bound, Linearization,
    method::{Quadratic, Singular, minimise_in_box},
};

/// μ of the regularised step as a multiple of k / max_condition: the Jacobi-scaled matrix
/// plus μI then has a condition of at most (k + μ)/μ ≈ max_condition / 100.
const REGULARISATION: f64 = 100.0;

/// The step of a normal matrix too ill-conditioned to solve: (A + μ diag(A)) δc = −U* with
/// μ = 100 k / max_condition (Marquardt's regularisation at the solver's limit; an unknown
/// with a zero column is damped by the largest diagonal, so its correction is 0). The
/// directions the data determine keep their Newton correction; those they do not see get
/// almost none, as a truncated SVD would give. `None` when that too cannot be solved.
fn regularised(
    lin: &Linearization,
    (lo, hi): (&[f64], &[f64]),
    max_condition: f64,
) -> Option<sysid_core::method::BoxSolution> {
    let k = lin.gradient.len();
    let largest = (0..k).map(|i| lin.normal[(i, i)]).fold(0.0, f64::max);
    if !(largest > 0.0 && largest.is_finite()) {
        return None;
    }
    let mu = REGULARISATION * k as f64 / max_condition;
    let mut h = lin.normal.clone();
    for i in 0..k {
        let d = lin.normal[(i, i)];
        h[(i, i)] += mu * if d > 0.0 { d } else { largest };
    }
    let model = Quadratic { h: &h, c: &lin.gradient };
    minimise_in_box(&model, (lo, hi), &vec![0.0; k], max_condition).ok()
}

/// The Newton correction δc of one iteration.
#[derive(Clone, Debug, PartialEq)]
pub struct NewtonStep {
    /// δc, in the coordinates of the unknowns.
    pub delta: DVector<f64>,
    /// Condition number of the Jacobi-scaled normal matrix of the free unknowns.
    pub condition: f64,
    /// The bound each unknown is held on.
    pub active: Vec<Option<Bound>>,
}

/// Solves eq. (14), A δc = −U*, at the linearization `lin` within the box `(lo, hi)` of
/// allowed corrections (the bounds minus c*; infinite without bounds, where this is the
/// paper's step).
pub fn newton_step(
    lin: &Linearization,
    (lo, hi): (&[f64], &[f64]),
    max_condition: f64,
) -> Result<NewtonStep, Singular> {
    let k = lin.gradient.len();
    let model = Quadratic { h: &lin.normal, c: &lin.gradient };
    let solution = match minimise_in_box(&model, (lo, hi), &vec![0.0; k], max_condition) {
        Ok(solution) => solution,
        Err(singular) => regularised(lin, (lo, hi), max_condition).ok_or(singular)?,
    };
    Ok(NewtonStep {
        delta: DVector::from_vec(solution.x),
        condition: solution.condition.value(),
        active: solution.active,
    })
}
