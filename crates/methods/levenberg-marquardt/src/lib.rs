//! Levenberg–Marquardt for system identification, as Moré implemented it in MINPACK (J. J.
//! Moré, "The Levenberg–Marquardt algorithm: implementation and theory", Lecture Notes in
//! Mathematics 630, 1978): a trust region in the scaled norm ‖Dδ‖, D the running maximum of
//! the column norms of W½J, and the radius updated from the ratio of the actual to the
//! predicted decrease of ε. Bounds are inside the step: each trial step minimises the
//! Gauss–Newton model plus λ‖Dδ‖² over the box the bounds leave (the active-set method of
//! [`sysid_core::method::minimise_in_box`]), so no step is clipped after the fact.
//!
//! The same trust region runs Fletcher and Xu's hybrid ([`LevenbergMarquardt::hybrid`],
//! `hybrid-newton`; IMA J. Numer. Anal. 7, 1987): Gauss–Newton's model while ε falls by at
//! least [`FAST_FALL`] of itself per step, the full Hessian of ε by differences of the
//! sensitivities' gradient once it falls more slowly, where large residuals make the
//! Gauss–Newton model misjudge the curvature. It also runs NL2SOL's adaptive model
//! ([`LevenbergMarquardt::adaptive`], `nl2sol`, the default) and Transtrum and Sethna's
//! geodesic acceleration ([`LevenbergMarquardt::geodesic`], `geodesic-lm`), each trial step
//! bent along the valley by the residuals' second derivative along it.
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

pub use options::{Hessian, LevenbergMarquardtOptions};
pub use solver::{CRAWL_FALL, CRAWL_WINDOW, FAST_FALL, LevenbergMarquardt, SCREEN_FROM};
