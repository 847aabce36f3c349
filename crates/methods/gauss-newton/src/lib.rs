//! # sysid-gauss-newton: the Gauss–Newton baseline on argmin
//!
//! The textbook method as a general-purpose optimisation library does it: the weighted
//! residual vector r(z) and its Jacobian are handed to argmin's `GaussNewton` (full steps,
//! `gauss-newton`) or `GaussNewtonLS` (backtracking Armijo line search, `gauss-newton-ls`).
//! The Jacobian comes from the shared forward sensitivities, residuals and Jacobian from one
//! integration; or, in `gauss-newton-fd`, from forward differences, which is what a user
//! without sensitivity equations gets.
//!
//! **What to expect.** Near a small-residual minimum Gauss–Newton and Goodman's method take
//! the same steps (Goodman's A and U are JᵀJ and Jᵀr); the differences are argmin's: it
//! inverts JᵀJ explicitly and stops when ‖r‖ stops changing (|Δ‖r‖| below a tolerance,
//! here relative to the starting ‖r‖). `gauss-newton-ls` takes argmin's Gauss–Newton step
//! as the search direction and runs argmin's backtracking Armijo line search on ½‖r‖² with
//! its gradient Jᵀr (argmin's own `GaussNewtonLS` tests ‖r‖ against the gradient of ½‖r‖²,
//! inconsistent by the factor ‖r‖, and rejects every step at large residuals). A continuous
//! record enters as residuals at Gauss–Legendre nodes
//! ([`Problem::residuals_and_jacobian`](sysid_core::Problem::residuals_and_jacobian)).
//! argmin's solver is unconstrained: bounded unknowns are mapped to free coordinates by a
//! smooth change of variables ([`bounds::Map`], softplus or logistic: finite for every w),
//! and an unknown that the projected Gauss–Newton model (the box solver of sysid-core) holds
//! on its bound is held there, and released where that model moves it inwards, so an optimum
//! on a bound is reached and reported as such.
//!
//! ```
//! use sysid_core::Method;
//! use sysid_gauss_newton::GaussNewton;
//! # use sysid_core::{Data, Problem};
//! # use sysid_ode::{Scalar, Signature, System};
//! # struct Fall(Signature);
//! # impl System for Fall {
//! #     fn signature(&self) -> &Signature { &self.0 }
//! #     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
//! #         dy[0] = y[1];
//! #         dy[1] = p[0];
//! #     }
//! # }
//! # let problem = Problem::builder(Fall(Signature::new(&["y", "v"], &["g"])))
//! #     .unknown("y", 0.0).unknown("v", 0.0).unknown("g", 32.0)
//! #     .data(Data::discrete().series("y", &[0.0, 1.0, 2.0, 3.0], &[0.0, 15.0, 65.0, 145.0]))
//! #     .build().unwrap();
//! let estimate = GaussNewton::line_search().fit(&problem).unwrap();
//! assert!((estimate.value("g").unwrap() - 32.5).abs() < 1e-9);
//! ```
#![warn(missing_docs)]

pub mod bounds;
mod options;
mod residuals;
mod solver;

pub use options::{GaussNewtonOptions, JacobianSource};
pub use residuals::{Cache, Evaluation, HalfSquares, Residuals, Space};
pub use solver::GaussNewton;
