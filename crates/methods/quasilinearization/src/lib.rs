//! # sysid-quasilinearization: Bellman–Kagiwada–Kalaba quasilinearization
//!
//! R. Bellman, H. Kagiwada and R. Kalaba, "Quasilinearization, system identification, and
//! prediction", RAND RM-3812-PR (1963); the method Goodman (1966) sets his own against.
//!
//! **The method.** Parameters are constant states. Where Goodman holds the differential
//! equations fixed and moves the boundary conditions, quasilinearization holds the boundary
//! conditions fixed and moves the equations: each iteration linearises the model around the
//! whole previous trajectory x_k(t), integrates the particular solution p(t) and the
//! fundamental matrix Φ(t) of that linear system (error-controlled, dense), chooses the
//! constants c of x = p + Φ c by linear least squares (QR), and takes x_{k+1} = p + Φ c as
//! the next trajectory: it never re-integrates the nonlinear model to move on. Convergence is
//! quadratic near the solution, where x_k solves the nonlinear model.
//!
//! **The safeguard.** The full step is taken where the nonlinear model's ε falls by more than
//! its accuracy, or, within that accuracy, where the step is at most half the last
//! (Deuflhard's contraction test), or where ε at x_k is unknown. Otherwise, and where the least
//! squares is singular, the family is taken around the model's own trajectory (where it is the
//! Gauss–Newton model) and its step is halved along the Levenberg curve until ε falls by a
//! quarter of the predicted decrease; `singular` only when no step is found.
//!
//! **What it offers over Goodman's method.** The first trajectory is free: from the model
//! integrated at the guess ([`Start::Guess`]), from the data for measured states
//! ([`Start::Data`]), or any trajectory the caller has ([`Start::Trajectory`]). Since the
//! iterates need not solve the nonlinear model, a start whose nonlinear solution misbehaves
//! can still converge.
//!
//! **What it costs.** Per iteration one integration of n (1 + k) equations, like Goodman's
//! sensitivities, with k + 1 directional derivatives per stage (the columns of Φ and
//! p − x_k) and the previous trajectory interpolated at every stage; the dense solution of
//! [p; Φ] is stored. The history reports the cost of the nonlinear model re-integrated from
//! each iterate (one plain integration per iteration, so the methods compare on the same
//! measure) and, separately, the cost of the linear family.
//!
//! Discrete data, a continuous record (at the nodes of a Gauss–Legendre rule), weighted
//! outputs and an initial time inside the data are handled as in Goodman's method. With
//! bounds, c is chosen by bounded-variable least squares within them (never solved free and
//! clipped); a log scale is supported for parameters (the augmented
//! state is ln α), not for initial values.
//!
//! ```
//! use sysid_core::Method;
//! use sysid_quasilinearization::Quasilinearization;
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
//! let estimate = Quasilinearization::default().fit(&problem).unwrap();
//! assert!((estimate.value("g").unwrap() - 32.5).abs() < 1e-10);
//! ```
#![warn(missing_docs)]

mod options;
mod solver;
pub mod step;
pub mod trajectory;

pub use options::{QuasilinearizationOptions, Start, StateFunction};

/// The history's diagnostic of quasilinearization: ε of the linear family whose optimum an
/// iterate is (its `cost` is the nonlinear model's, re-integrated from the iterate)
/// ([`Iteration::diagnostic`](sysid_core::Iteration::diagnostic)).
pub const LINEAR_COST: &str = "linear_cost";
pub use solver::{Quasilinearization, QuasilinearizationRun};
pub use trajectory::Trajectory;
