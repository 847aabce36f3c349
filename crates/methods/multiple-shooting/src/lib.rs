//! Multiple shooting for system identification (H. G. Bock, "Recent advances in parameter
//! identification techniques for ODE", in Numerical Treatment of Inverse Problems in
//! Differential and Integral Equations, Birkhäuser 1983; the method of PARFIT and MUSCOD).
//!
//! Single shooting integrates the whole horizon from one guess, so a poor guess gives a
//! trajectory that has nothing to do with the data, and the fit can be caught in a minimum
//! that only such trajectories have. Multiple shooting cuts the data interval at nodes
//! τ_1 < … < τ_{M−1} and starts each interval from a node value s_j of its own, initialised
//! from the data where a state is measured; the intervals are joined by the matching
//! conditions y(τ_{j+1}; τ_j, s_j, α) = s_{j+1}, which the iteration satisfies only in the
//! limit. Each step is a generalised Gauss–Newton step for the fit under the linearised
//! conditions, reduced by Bock's condensing to a least-squares problem in the original
//! unknowns, with the bounds inside it, and a line search on an exact-penalty merit function
//! that measures both the fit and the defects. The formulas are in `solver.rs` and
//! `shooting.rs`, and in docs/methods.md.
//!
//! The result is an [`Estimate`](sysid_core::Estimate) like every other method's: the driver
//! judges the returned unknowns on the original (single-shooting) problem, with the same
//! certificate and covariance, and the history carries the defect ‖d‖ of every iterate.
//!
//! ```
//! use sysid_core::Method;
//! use sysid_multiple_shooting::MultipleShooting;
//! let case = sysid_systems::van_der_pol::van_der_pol();
//! let estimate = MultipleShooting::default().fit(&case.problem(1).unwrap()).unwrap();
//! assert!(estimate.converged());
//! ```

mod options;
mod shooting;
mod solver;

pub use options::MultipleShootingOptions;
pub use solver::MultipleShooting;

/// The most shooting intervals the data choose by default.
pub const DEFAULT_MAX_INTERVALS: usize = 10;

/// The history's diagnostic of multiple shooting: ‖d‖, the Euclidean norm of the matching
/// defects of the node values at an iterate, 0 once the nodes have merged into the
/// trajectory ([`Iteration::diagnostic`](sysid_core::Iteration::diagnostic)).
pub const DEFECT: &str = "defect";
