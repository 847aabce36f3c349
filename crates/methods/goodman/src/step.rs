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

use nalgebra::DVector;
use sysid_core::{Linearization, NormalFactor, Singular};

/// The Newton correction δc of one iteration.
#[derive(Clone, Debug, PartialEq)]
pub struct NewtonStep {
    /// δc, in the coordinates of the unknowns.
    pub delta: DVector<f64>,
    /// Condition number of the Jacobi-scaled normal matrix.
    pub condition: f64,
}

/// Solves eq. (14), A δc = −U*, at the linearization `lin`, for the unknowns not held at a
/// bound (`held[i]`: see [`Unknowns::active`](sysid_core::Unknowns::active)); held unknowns
/// do not move. Without bounds, `held` is all false and this is the paper's step.
pub fn newton_step(
    lin: &Linearization,
    max_condition: f64,
    held: &[bool],
) -> Result<NewtonStep, Singular> {
    let k = lin.gradient.len();
    let free: Vec<usize> = (0..k).filter(|&i| !held[i]).collect();
    let mut delta = DVector::zeros(k);
    if free.is_empty() {
        return Ok(NewtonStep { delta, condition: 1.0 });
    }
    let a = lin.normal.select_rows(&free).select_columns(&free);
    let u = lin.gradient.select_rows(&free);
    let factor = NormalFactor::new(&a, max_condition).map_err(|s| {
        let mut direction = vec![0.0; k];
        for (d, &i) in s.direction.iter().zip(&free) {
            direction[i] = *d;
        }
        Singular {
            unknowns: s.unknowns.iter().map(|&i| free[i]).collect(),
            condition: s.condition,
            direction,
        }
    })?;
    for (d, &i) in factor.solve(&u).iter().zip(&free) {
        delta[i] = -d;
    }
    Ok(NewtonStep { delta, condition: factor.condition() })
}
