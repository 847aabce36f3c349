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
//!   components (sensitivities included) and dense output; Dormand–Prince 8(5,3), Hairer's
//!   DOP853, for tight tolerances (order 8, dense output of order 7); classical RK4 with a
//!   fixed step;
//!   for stiff systems Rodas4 and Rodas5P, Rosenbrock methods of order 4 and 5 with the
//!   exact Jacobian and dense LU, or, for a system that gives its sparse Jacobian and whose
//!   factors fill little of n² ([`SPARSE_SHARE`]), a sparse LU in a fill-reducing order
//!   (its pattern analysed once), integrating the sensitivities with the same factorisation; an
//!   automatic choice that starts with DOPRI5 and switches to Rodas5P when its steps are
//!   limited by stability (Hairer's test, and the Jacobian's spectral radius by power
//!   iteration), and back where Rodas5P's steps would be well inside DOPRI5's stability
//!   region; a variable-order multistep scheme ([`Scheme::Bdf`]: the numerical differentiation
//!   formulas of orders 1–5) that keeps its factorised matrix over many steps, for large stiff
//!   models; forward and backward from t0; steps that stop exactly on
//!   declared input discontinuities; errors ([`OdeError`]) instead of panics;
//! * [`Ivp`]: the state ([`Ivp::solve`]) or the state and its sensitivities
//!   ([`Ivp::solve_sensitivities`]) at measurement times on both sides of t0, or the whole
//!   solution as a function of time ([`Ivp::dense`]);
//! * quadratures along the trajectory for a continuous record b(t)
//!   ([`Ivp::least_squares_integrals`]): ε, ∫ r·S dt and ∫ SᵀWS dt in the same integration;
//! * input signals given by samples ([`Signal`], [`Inputs`]), piecewise linear or constant.
//!
//! ## Stiff systems: why Rodas4
//!
//! A stiff model (chemical kinetics, fast actuators) limits an explicit scheme's step by
//! stability, not accuracy: DOPRI5 takes 35 000 steps on Robertson's problem up to t = 40
//! where Rodas4 takes 450. Among implicit schemes, a Rosenbrock method needs no Newton
//! iteration: each of its six stages is one linear solve with the same matrix
//! E = I/(γh) − ∂g/∂y, factorised once per step. That makes it predictable (no convergence
//! test to tune, no Jacobian reuse heuristics) and exact Jacobians are cheap here, one
//! dual-number evaluation. It also suits the variational equations: the Jacobian of the
//! state-plus-sensitivity system is block lower triangular with E on every diagonal block,
//! so the sensitivities cost one back-substitution per column with the state's LU (the
//! simultaneous approach with a shared factorisation), and the step-size control covers
//! them. Rodas4 is L-stable and stiffly accurate; order 4 with an order-3 error estimate
//! and dense output fits the 1e-6 to 1e-10 tolerances identification works at. Rodas5P
//! (Steinebach 2023) is its order-5 successor, L-stable and stiffly accurate too, with an
//! order-4 estimate and dense output: eight stages instead of six, but at rtol 1e-8 it
//! takes 2.2–3.3 times fewer steps (the PEtab problems: Boehm 539 → 214, Bachmann 42 000
//! → 16 000), so an integration with sensitivities costs about half. A multistep (BDF)
//! step costs one to three evaluations and solves and reuses its factorisation for many
//! steps, which wins on large stiff models (the NLL + gradient of the PEtab problems Smith,
//! Laske, SalazarCavazos and Lucarelli: 0.43 to 0.76 of the automatic choice's time). Its
//! error is not extrapolated as the one-step schemes' is, so at a given rtol its global error
//! is 40–240 times rtol where theirs is a few times rtol: `bdf` is chosen by name, and the
//! automatic choice stays with Rodas5P.
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

mod adjoint;
mod bdf;
mod control;
mod counts;
mod dop853;
mod dopri5;
mod driver;
mod error;
mod events;
mod implicit;
mod interpolant;
mod ivp;
mod jacobian;
mod lu;
mod options;
mod quadrature;
mod rhs;
mod rk4;
mod rodas4;
mod rodas5p;
#[cfg(test)]
mod rosenbrock_conditions;
mod signal;
mod sparse;
mod sparse_lu;
mod stepper;
mod stiffness;
mod system;
pub mod testing;
mod work;
mod wrt;

pub use counts::{Costs, Counts};
pub use driver::integrate;
pub use error::{BLOW_UP_GROWTH, OdeError, SignalError, SignatureError, shortest};
pub use implicit::{IterationMatrix, SPARSE_SHARE};
pub use interpolant::{DenseSolution, Interpolant};
pub use ivp::{
    Ivp, ModelRhs, ObservableGradient, SensitivityRhs, SensitivityTrajectory, Trajectory,
    check_times, rhs_jump, stops,
};
pub use jacobian::JacobianProducts;
pub use lu::{FactorError, Lu};
pub use options::{AUTO_DOP853_RTOL, Integrator, InvalidSetting, MIN_RTOL, STATE_FLOOR, Scheme};
pub use quadrature::{GaussKronrod, LeastSquaresIntegrals, Record, RecordedOutput};
pub use rhs::Rhs;
pub use signal::{Inputs, Interpolation, Side, Signal};
pub use sparse::{PlanCell, SparseJacobian};
pub use system::{Function, Observable, Ode, OdeSystem, Scalar, Signature, System};
pub use wrt::{Wrt, wrt_name};
