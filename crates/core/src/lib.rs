//! # sysid-core: the vocabulary every identification method shares
//!
//! The crate root holds what a user of the methods needs:
//! * [`Problem`] (built with [`Problem::builder`]): a [`System`](sysid_ode::System), its known
//!   initial values and parameters, the [`Unknown`]s with starting guesses (optional bounds,
//!   optional log scale), and the measurements [`Data`]: discrete samples of states or outputs
//!   with a weight per output (Goodman 1966, eq. 32) or a [`Noise`] model, or a continuous
//!   record (eq. 16–17); several [`Experiment`]s when the data come from different settings.
//! * [`Problem::linearize`]: one integration with sensitivities gives the cost
//!   ε = Σ_o w_o Σ_m r_{o,m}² (no factor ½; the integral for a record), U = Σ w r S (eq. 12,
//!   22) and A = Σ w Sᵀ S (eq. 15, 24), and for discrete data the weighted residuals and
//!   their Jacobian ([`Linearization`]).
//! * [`Method`]: the trait every method implements, and [`DriverOptions`] (budgets,
//!   tolerances), set on any method's options through the [`Driven`] trait's `with_*` setters.
//! * [`Estimate`]: values, standard errors, 95 % intervals (Student's t) and covariance
//!   (s² A⁻¹, s² = ε/(N − k)), cost, iterations, [`Termination`], the [`Certificate`] (a
//!   first-order optimality test at the returned point that decides whether the fit
//!   converged), per-iteration history, time and work; the JSON of `sysid fit`
//!   ([`Estimate::record`]).
//!
//! The modules hold the rest, named for who uses them:
//! * [`method`]: for writing a method. The driver [`drive`](method::drive) owns the loop, the
//!   history, the budgets, the step test, the best iterate and the certificate; a method
//!   supplies its [`Step`](method::Step). Trust regions along a curve, bounded subproblems,
//!   geodesic acceleration and the normal equations ([`NormalFactor`](method::NormalFactor):
//!   Cholesky after Jacobi scaling, the scale-free condition number, and when singular the
//!   unknowns the data cannot tell apart).
//! * [`plan`]: a built problem's experiments and data as the methods and importers see them
//!   (samples, residual rows, noise layouts), and the traits behind [`Noise::Function`] and
//!   [`Setting::Function`] (σ or a setting as a function of the unknowns).
//! * [`confidence`]: Student's t and the intervals it gives.
//! * [`observer`]: observers of a running fit: its iterates, and its trust-region trials.
//! * [`format`](mod@format): numbers and tables for people.
//!
//! ```
//! use sysid_core::{Data, Problem, Unknown};
//! use sysid_ode::{Ode, Scalar};
//!
//! /// Exponential decay x' = −k x.
//! struct Decay;
//! impl Ode for Decay {
//!     const STATES: &[&str] = &["x"];
//!     const PARAMETERS: &[&str] = &["k"];
//!     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], dy: &mut [T]) {
//!         dy[0] = -(p[0] * y[0]);
//!     }
//! }
//!
//! let t = [0.5, 1.0, 2.0];
//! let x: Vec<f64> = t.iter().map(|t: &f64| 2.0 * (-0.7 * t).exp()).collect();
//! let problem = Problem::ode(Decay)
//!     .unknown("x", 1.0)
//!     .unknown_with(Unknown::new("k", 0.5).min(0.0).max(10.0))
//!     .data(Data::discrete().series("x", &t, &x))
//!     .build()?;
//! // The cost at the true values is zero; at the guesses it is not.
//! let lin = problem.linearize(&[2.0, 0.7])?;
//! assert!(lin.cost < 1e-12);
//! assert!(problem.linearize(&problem.guesses())?.cost > 0.1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]

mod adjoint;
mod assemble;
mod bounded;
mod certificate;
pub mod confidence;
mod data;
mod driver;
mod error;
mod estimate;
mod evaluate;
mod evaluations;
mod experiment;
mod fit;
pub mod format;
mod geodesic;
mod kinks;
mod linalg;
mod noise;
pub mod observer;
mod options;
pub mod plan;
mod problem;
mod step;
mod table;
mod termination;
mod trust;
mod unknowns;

// The user's vocabulary: a problem, its unknowns and data, the options, the estimate.
pub use adjoint::{ADJOINT_OPERATION_COST, NllGradient, Sensitivities};
pub use certificate::{Bound, Certificate, NullSpace};
pub use data::{Data, Record, Samples, Series};
pub use error::{FitError, ProblemError};
pub use estimate::{Estimate, ExperimentFit, FirstRun, FitRecord, Iteration, ScaleEstimate};
pub use evaluate::{Linearization, Observed, WeightedResiduals};
pub use experiment::{Experiment, Setting};
pub use fit::{Method, caught};
pub use kinks::{Around, SLIVER};
pub use noise::{Noise, NoiseDistribution, Transform};
pub use options::{
    DEFAULT_GTOL, Driven, DriverOptions, MAX_ITERATIONS, OptionsError, START_MAX_ITERATIONS,
};
pub use problem::{Problem, ProblemBuilder};
pub use step::Diagnostics;
pub use termination::{Failure, Rule, Termination};
pub use unknowns::{Distribution, Initialization, Prior, Unknown, Unknowns};

pub mod method {
    //! For writing a method: the driver that owns the loop, the step a method proposes, trust
    //! regions along a curve, bounded subproblems, geodesic acceleration, the normal equations,
    //! and the first-order certificate. A user who calls methods needs none of it.
    //!
    //! A method implements [`Step`] and calls [`drive`]; docs/methods.md ("Adding a method") walks
    //! through one.

    pub use crate::bounded::{
        BoxSolution, LinearLeastSquares, Quadratic, Subproblem, minimise_in_box,
    };
    pub use crate::certificate::{
        EXACT_FIT, MAX_EXACT_FIT, Measure, certify, exact_fit_tolerance, onto_bounds, optimality,
        other_side,
    };
    pub use crate::driver::drive;
    pub use crate::evaluations::{
        COARSE_RTOL, Evaluations, FINEST_RTOL, REFERENCE_RTOL, coarser, finer, other_scheme,
    };
    pub use crate::fit::start_coordinates;
    pub use crate::geodesic::{Accelerated, GEODESIC_H, GEODESIC_RATIO, Geodesic};
    pub use crate::linalg::{Condition, NormalFactor, Singular, as_faer};
    pub use crate::options::MAX_DERIVED_GTOL;
    pub use crate::step::{Advance, Iterate, Proposal, Step};
    pub use crate::termination::{PROGRESS, PROGRESS_WINDOW, SETTLE, SETTLE_WINDOW};
    pub use crate::trust::{
        Curve, CurveStep, SCALE_MEMORY, actual_decrease, differenced_hessian, halve_along_curve,
        one_sided,
    };
}
