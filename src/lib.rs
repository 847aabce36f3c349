#![doc = include_str!("../README.md")]
//!
//! ## This crate
//!
//! This facade re-exports the workspace crates, each usable on its own:
//! * [`ode`] (`sysid-ode`): systems, integrators, forward sensitivities, quadratures;
//! * [`core`] (`sysid-core`): problems, unknowns, data, estimates, the `Method` trait;
//! * [`goodman`] (`sysid-goodman`): Goodman's 1966 Newton iteration;
//! * [`gauss_newton`] (`sysid-gauss-newton`): the Gauss–Newton baseline on argmin;
//! * [`quasilinearization`] (`sysid-quasilinearization`): Bellman–Kagiwada–Kalaba's method;
//! * [`levenberg_marquardt`] (`sysid-levenberg-marquardt`): Moré's trust-region
//!   Levenberg–Marquardt, bounds inside the step;
//! * [`multiple_shooting`] (`sysid-multiple-shooting`): Bock's multiple shooting with
//!   condensing and an exact-penalty line search;
//! * [`model`] (`sysid-model`): model files (TOML + expressions) and CSV data;
//! * [`petab`] (`sysid-petab`): PEtab problems imported as model files;
//! * [`systems`] (`sysid-systems`): the benchmark catalogue;
//! * [`registry`] (`sysid-registry`): every method by name, built with shared settings;
//! * [`montecarlo`] (`sysid-montecarlo`): multistart, Monte-Carlo studies and basin maps;
//! * [`profile`] (`sysid-profile`): profile likelihoods.
//!
//! Runnable examples (`examples/*.rs`): `cargo run --release --example logistic` (one method
//! on your own ODE), `--example compare_methods` (every method on a catalogue system),
//! `--example petab` (a PEtab problem from its nominal point and from 10 starts).
#![warn(missing_docs)]

pub use sysid_core as core;
pub use sysid_gauss_newton as gauss_newton;
pub use sysid_goodman as goodman;
pub use sysid_levenberg_marquardt as levenberg_marquardt;
pub use sysid_model as model;
pub use sysid_montecarlo as montecarlo;
pub use sysid_multiple_shooting as multiple_shooting;
pub use sysid_ode as ode;
pub use sysid_petab as petab;
pub use sysid_profile as profile;
pub use sysid_quasilinearization as quasilinearization;
pub use sysid_registry as registry;
pub use sysid_systems as systems;

/// The names most programs need.
///
/// A fit's [`Estimate`](sysid_core::Estimate) holds the values with their standard errors,
/// 95 % intervals and covariance, the [`Termination`](sysid_core::Termination) and the
/// certificate's verdict, the history and the work done. Goodman's falling body, fitted to
/// the paper's data:
///
/// ```
/// use sysid::prelude::*;
/// use sysid::systems::falling_body::falling_body;
///
/// let problem = falling_body().problem(1)?;
/// let fit = Goodman::default().fit(&problem)?;
/// assert!(fit.converged());
/// assert_eq!(fit.termination.code(), "converged_gradient");
/// assert_eq!(fit.names, ["y", "v", "g"]);
/// assert!((fit.value("g").unwrap() - 32.5).abs() < 1e-9); // the paper's g
/// // s² = ε/(N − k) = 1.25 with one degree of freedom; SE(g) = √(s² (A⁻¹)_gg) = √1.25.
/// let se = fit.std_errors.as_ref().unwrap();
/// assert!((se[2] - 1.25f64.sqrt()).abs() < 1e-9);
/// let [lo, hi] = fit.intervals.as_ref().unwrap()[2]; // Student's t with 1 dof: 12.706
/// assert!((hi - lo - 2.0 * 12.706_204_736 * se[2]).abs() < 1e-6);
/// println!("{fit}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub mod prelude {
    pub use sysid_core::{Data, Driven, Estimate, Method, Problem, Termination, Unknown};
    pub use sysid_gauss_newton::{GaussNewton, GaussNewtonOptions};
    pub use sysid_goodman::{Goodman, GoodmanOptions};
    pub use sysid_levenberg_marquardt::{LevenbergMarquardt, LevenbergMarquardtOptions};
    pub use sysid_multiple_shooting::{MultipleShooting, MultipleShootingOptions};
    pub use sysid_ode::{Integrator, Ode, Scalar, Signature, System};
    pub use sysid_quasilinearization::{Quasilinearization, QuasilinearizationOptions};
}
