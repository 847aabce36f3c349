//! # sysid-goodman: Goodman's 1966 boundary-condition Newton iteration
//!
//! T. R. Goodman, "System identification and prediction — an algorithm using a Newtonian
//! iteration procedure", Quart. Appl. Math. 24 (1966) 249–255.
//!
//! **The method.** Parameters are treated as states with zero derivative (eq. 4), so every
//! unknown is an initial value c. From a guess c*, the nonlinear model is integrated together
//! with its variational equations (eq. 6–7); the measurements then give U* (eq. 12) and the
//! symmetric matrix A (eq. 15), and the correction solves A δc = −U* (eq. 14). The
//! differential equations are held fixed and the boundary conditions move: every iterate is
//! an exact solution of the nonlinear model, and for a linear model one step is exact (paper,
//! Section IV). A continuous record replaces the sums by integrals (eq. 20–24); several
//! measured quantities are weighted by w_o = 1/σ_o² (eq. 32).
//!
//! **What it needs.** A model as a [`System`](sysid_ode::System), a [`Problem`] with at least
//! as many data as unknowns, and a start close enough for Newton's method: it converges
//! quadratically near a zero-residual solution and fast near a small-residual one, but takes
//! full steps, so a poor start can diverge. [`GoodmanOptions::step_halving`] adds a
//! safeguard (off by default, to keep the paper's method).
//!
//! **When it stops.** The shared driver ([`sysid_core::method::drive`]) applies the step and gradient
//! tests, the budgets and the certificate; see [`Termination`](sysid_core::Termination):
//! converged, stalled (a rule fired where the cost is not stationary), iteration or
//! integration budget, a singular normal matrix, or an integration failure with its time; a
//! failure after the start reports the best iterate.
//!
//! ```
//! use sysid_core::{Data, Method, Problem};
//! use sysid_goodman::Goodman;
//! use sysid_ode::{Scalar, Signature, System};
//!
//! /// A body falling under constant gravity g: y' = v, v' = g.
//! struct Fall(Signature);
//! impl System for Fall {
//!     fn signature(&self) -> &Signature { &self.0 }
//!     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
//!         dy[0] = y[1];
//!         dy[1] = p[0];
//!     }
//! }
//! // The paper's Table I and start (0, 0, 32).
//! let problem = Problem::builder(Fall(Signature::new(&["y", "v"], &["g"])))
//!     .unknown("y", 0.0)
//!     .unknown("v", 0.0)
//!     .unknown("g", 32.0)
//!     .data(Data::discrete().series("y", &[0.0, 1.0, 2.0, 3.0], &[0.0, 15.0, 65.0, 145.0]))
//!     .build()
//!     .unwrap();
//! let estimate = Goodman::default().fit(&problem).unwrap();
//! assert!(estimate.converged());
//! assert_eq!(estimate.iterations, 1);
//! assert!((estimate.value("g").unwrap() - 32.5).abs() < 1e-10);
//! ```
#![warn(missing_docs)]

mod options;
mod solver;
pub mod step;

pub use options::GoodmanOptions;
pub use solver::Goodman;
pub use step::{NewtonStep, newton_step};

#[doc(no_inline)]
pub use sysid_core::Problem;
