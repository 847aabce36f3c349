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
pub mod prelude {
    pub use sysid_core::{Data, Driven, Estimate, Method, Problem, Termination, Unknown};
    pub use sysid_gauss_newton::{GaussNewton, GaussNewtonOptions};
    pub use sysid_goodman::{Goodman, GoodmanOptions};
    pub use sysid_levenberg_marquardt::{LevenbergMarquardt, LevenbergMarquardtOptions};
    pub use sysid_multiple_shooting::{MultipleShooting, MultipleShootingOptions};
    pub use sysid_ode::{Integrator, Ode, Scalar, Signature, System};
    pub use sysid_quasilinearization::{Quasilinearization, QuasilinearizationOptions};
}
