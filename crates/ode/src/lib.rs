//! # sysid-ode: the ODE and sensitivity engine every sysid method shares
//!
//! A model is a [`System`]: named states, parameters, inputs and outputs, and a right-hand
//! side dy/dt = g(t, y, α, u(t)) written once for any [`Scalar`]. Evaluated with
//! forward-mode dual numbers the same code gives exact Jacobian products, so the
//! variational equations (Goodman 1966, eq. 6–7)
//!
//! dS/dt = (∂g/∂y) S + ∂g/∂α,  S(t0) = unit columns for unknown initial values,
//!
//! are integrated together with the state without any hand-written or finite-difference
//! Jacobian.
//!
//! What it provides:
//! * integrators ([`Integrator`]): adaptive Dormand–Prince 5(4) with error control over all
//!   components (sensitivities included) and dense output; classical RK4 with a fixed step;
//!   forward and backward from t0; steps that stop exactly on declared input
//!   discontinuities; errors ([`OdeError`]) instead of panics;
//! * [`Ivp`]: the state ([`Ivp::solve`]) or the state and its sensitivities
//!   ([`Ivp::solve_sensitivities`]) at measurement times on both sides of t0, or the whole
//!   solution as a function of time ([`Ivp::dense`]);
//! * quadratures along the trajectory for a continuous record b(t)
//!   ([`Ivp::least_squares_integrals`]): ε, ∫ r·S dt and ∫ SᵀWS dt in the same integration;
//! * input signals given by samples ([`Signal`], [`Inputs`]), piecewise linear or constant.
//!
//! ```
//! use sysid_ode::{Integrator, Ivp, Scalar, Signature, System, Wrt};
//! struct Decay(Signature);
//! impl System for Decay {
//!     fn signature(&self) -> &Signature { &self.0 }
//!     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
//!         dy[0] = -p[0] * y[0];
//!     }
//! }
//! let decay = Decay(Signature::new(&["x"], &["k"]));
//! let ivp = Ivp::new(&decay, 0.0, &[2.0], &[0.5]);
//! let sol = ivp
//!     .solve_sensitivities(&Integrator::dopri5(1e-10, 1e-12), &[Wrt::Parameter(0)], &[1.0])
//!     .unwrap();
//! // x = 2 e^{-kt}, ∂x/∂k = -2 t e^{-kt}
//! assert!((sol.state(0)[0] - 2.0 * (-0.5f64).exp()).abs() < 1e-9);
//! assert!((sol.sensitivity(0)[(0, 0)] + 2.0 * (-0.5f64).exp()).abs() < 1e-9);
//! ```
#![warn(missing_docs)]

mod driver;
mod error;
mod interpolant;
mod ivp;
mod jacobian;
mod options;
mod quadrature;
mod signal;
mod system;
pub mod testing;

pub use driver::{Counts, Rhs, integrate};
pub use error::{OdeError, SignalError, SignatureError};
pub use interpolant::{DenseSolution, Interpolant};
pub use ivp::{
    Ivp, ModelRhs, ObservableGradient, SensitivityRhs, SensitivityTrajectory, Trajectory, Wrt,
    check_times, wrt_name,
};
pub use jacobian::{Function, JacobianProducts};
pub use options::{Integrator, Scheme};
pub use quadrature::{GaussKronrod, LeastSquaresIntegrals, Record, RecordedOutput};
pub use signal::{Inputs, Interpolation, Side, Signal};
pub use system::{Observable, Scalar, Signature, System};
