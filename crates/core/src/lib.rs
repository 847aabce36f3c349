//! # sysid-core: the vocabulary every identification method shares
//!
//! * [`Problem`]: a [`System`](sysid_ode::System), its known initial values and parameters,
//!   the [`Unknown`]s with starting guesses (optional bounds, optional log scale), and the
//!   measurements [`Data`]: discrete samples of states or outputs with a weight per output
//!   (Goodman 1966, eq. 32), or a continuous record (eq. 16–17).
//! * [`Problem::linearize`]: one integration with sensitivities gives the cost
//!   ε = Σ_o w_o Σ_m r_{o,m}² (no factor ½; the integral for a record), U = Σ w r S (eq. 12,
//!   22) and A = Σ w Sᵀ S (eq. 15, 24), and for discrete data the weighted residuals and
//!   their Jacobian.
//! * [`NormalFactor`]: the symmetric normal equations solved by Cholesky after Jacobi
//!   scaling, with the scale-free condition number and, when singular, the unknowns the data
//!   cannot tell apart.
//! * [`drive`]: the iteration driver every method uses. A method supplies its [`Step`]; the
//!   driver owns the loop, the history, the budgets ([`DriverOptions`], [`Evaluations`]),
//!   the step test, the best iterate, and the [`Certificate`] at the returned point, a
//!   first-order optimality test that decides whether the fit converged.
//! * [`Estimate`]: values, standard errors, 95 % intervals (Student's t) and covariance
//!   (s² A⁻¹, s² = ε/(N − k)), cost, iterations, [`Termination`], the certificate,
//!   per-iteration history, time and work; the JSON of `sysid fit` ([`Estimate::record`]).
//! * [`Method`]: the trait every method crate implements.
#![warn(missing_docs)]

mod assemble;
mod bounded;
mod certificate;
mod confidence;
mod data;
mod driver;
mod error;
mod estimate;
mod evaluate;
mod evaluations;
mod experiment;
pub mod format;
mod geodesic;
mod linalg;
mod method;
mod noise;
mod options;
mod plan;
mod problem;
mod step;
mod table;
mod termination;
mod trust;
mod unknowns;

pub use bounded::{BoxSolution, LinearLeastSquares, Quadratic, Subproblem, minimise_in_box};
pub use certificate::{
    Bound, Certificate, EXACT_FIT, Measure, NullSpace, certify, exact_fit_tolerance, onto_bounds,
    optimality,
};
pub use confidence::{Z95, band_half_width, interval, t95};
pub use data::{Data, Record, Samples, Series};
pub use driver::drive;
pub use error::{FitError, ProblemError};
pub use estimate::{Estimate, ExperimentFit, FitRecord, Iteration, ScaleEstimate};
pub use evaluate::{Linearization, Observed, WeightedResiduals};
pub use evaluations::{Evaluations, FINEST_RTOL};
pub use experiment::{Experiment, Planned, Setting, SettingFunction, SlotJacobian};
pub use geodesic::{Accelerated, GEODESIC_H, GEODESIC_RATIO, Geodesic};
pub use linalg::{NormalFactor, Singular, as_faer};
pub use method::{Method, start_coordinates};
pub use noise::{
    LN_2PI, NOISE_ROW_SHIFT, Noise, NoiseArgs, NoiseFunction, NoiseGradient, Transform,
};
pub use options::{DEFAULT_GTOL, Driven, DriverOptions, MAX_DERIVED_GTOL, OptionsError};
pub use plan::{PlannedNoise, PlannedSeries, RESIDUAL_PANELS, Sample, Sampled};
pub use problem::{Problem, ProblemBuilder, QUADRATURE_RTOL, SINGLE_EXPERIMENT};
pub use step::{Advance, Diagnostics, Iterate, Proposal, Step};
pub use table::{Compared, Expected, compact, compact_header, comparison};
pub use termination::{Failure, PROGRESS, PROGRESS_WINDOW, Rule, Termination};
pub use trust::{
    Curve, CurveStep, SCALE_MEMORY, actual_decrease, differenced_hessian, halve_along_curve,
};
pub use unknowns::{Distribution, Initialization, Prior, Unknown, Unknowns};
