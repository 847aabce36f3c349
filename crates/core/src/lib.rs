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
//! * [`Estimate`]: values, standard errors and covariance (s² A⁻¹, s² = ε/(N − k)), cost,
//!   iterations, [`Termination`], per-iteration history, time and work; the JSON of
//!   `sysid fit` ([`Estimate::to_json`]).
//! * [`Method`]: the trait every method crate implements.
#![warn(missing_docs)]

mod data;
mod error;
mod estimate;
mod linalg;
mod method;
mod problem;
pub mod table;
mod unknowns;

pub use data::{Data, Record, Samples, Series};
pub use error::{FitError, ProblemError};
pub use estimate::{Convergence, Estimate, FitRecord, Iteration, Termination};
pub use linalg::{NormalFactor, Singular, as_faer};
pub use method::{Method, start_coordinates};
pub use problem::{
    Linearization, Observed, Problem, ProblemBuilder, QUADRATURE_RTOL, Run, WeightedResiduals, Z95,
};
pub use unknowns::{Unknown, Unknowns};
