//! Levenberg–Marquardt for system identification, as Moré implemented it in MINPACK (J. J.
//! Moré, "The Levenberg–Marquardt algorithm: implementation and theory", Lecture Notes in
//! Mathematics 630, 1978): a trust region in the scaled norm ‖Dδ‖, D the running maximum of
//! the column norms of W½J, and the radius updated from the ratio of the actual to the
//! predicted decrease of ε. Bounds are inside the step: each trial step minimises the
//! Gauss–Newton model plus λ‖Dδ‖² over the box the bounds leave (the active-set method of
//! [`sysid_core::minimise_in_box`]), so no step is clipped after the fact.
//!
//! Why written here rather than taken from a crate: the step needs the shared driver's
//! Jacobian from forward sensitivities, its integration budget and its certificate, and a box
//! inside the subproblem; the MINPACK ports on crates.io (levenberg-marquardt 0.14) have no
//! bounds and own their loop.
//!
//! ```
//! use sysid_core::Method;
//! use sysid_levenberg_marquardt::LevenbergMarquardt;
//! let case = sysid_systems::falling_body::falling_body();
//! let estimate = LevenbergMarquardt::default().fit(&case.problem(1).unwrap()).unwrap();
//! assert!(estimate.converged());
//! ```

mod options;
mod solver;

pub use options::LevenbergMarquardtOptions;
pub use solver::LevenbergMarquardt;
