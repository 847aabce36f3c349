//! What every method's iteration shares: the budgets, the stopping tolerances the driver
//! applies, and the certificate's tolerance; and the errors of invalid options.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// An option that cannot be used, with its name and value.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum OptionsError {
    /// A tolerance or constant must be a non-negative finite number.
    #[error("{name} must be a finite non-negative number, got {value}")]
    Negative {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A tolerance or constant must be a positive finite number.
    #[error("{name} must be a finite positive number, got {value}")]
    NotPositive {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A number must lie in an open interval.
    #[error("{name} must lie in ({low}, {high}), got {value}")]
    OutOfRange {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
        /// Lower end (excluded).
        low: f64,
        /// Upper end (excluded).
        high: f64,
    },
    /// A count must be at least 1.
    #[error("{name} must be at least 1")]
    Zero {
        /// The option.
        name: &'static str,
    },
    /// A count must be at most `most`.
    #[error("{name} must be at most {most}, got {value}")]
    TooMany {
        /// The option.
        name: &'static str,
        /// Its value.
        value: usize,
        /// The largest allowed.
        most: usize,
    },
}

impl OptionsError {
    /// The option, as its field is named (`gtol`, `max_iterations`): a caller names it as
    /// its user spells it (`--gtol`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Negative { name, .. }
            | Self::NotPositive { name, .. }
            | Self::OutOfRange { name, .. }
            | Self::Zero { name }
            | Self::TooMany { name, .. } => name,
        }
    }

    /// What is wrong, without the name: "must lie in (0, 1), got 2".
    pub fn problem(&self) -> String {
        let text = self.to_string();
        text.strip_prefix(self.name()).map_or(text.clone(), |rest| rest.trim_start().to_string())
    }

    /// Checks that `value` is finite and ≥ 0.
    pub fn non_negative(name: &'static str, value: f64) -> Result<(), Self> {
        if value >= 0.0 && value.is_finite() { Ok(()) } else { Err(Self::Negative { name, value }) }
    }
    /// Checks that `value` is finite and > 0.
    pub fn positive(name: &'static str, value: f64) -> Result<(), Self> {
        if value > 0.0 && value.is_finite() {
            Ok(())
        } else {
            Err(Self::NotPositive { name, value })
        }
    }
    /// Checks that `value` lies in (low, high).
    pub fn within(name: &'static str, value: f64, low: f64, high: f64) -> Result<(), Self> {
        if value > low && value < high {
            Ok(())
        } else {
            Err(Self::OutOfRange { name, value, low, high })
        }
    }
}

/// The certificate's default tolerance on the first-order optimality measure, at the
/// default integrator tolerance (rtol 1e-8); looser integrations get 100·rtol, up to
/// [`MAX_DERIVED_GTOL`]. The
/// integration error alone moves the measure at the true minima of the catalogue to at most
/// 8.8e-8 at rtol 1e-8 (about 9·rtol), so 1e-6 leaves a factor 11: tighter, it would certify
/// the integrator's error rather than the model's minimum. A point that passes is within about
/// k·κ·gtol² (κ the scaled condition number) of the minimum's cost. docs/methods.md (the
/// certificate) has the measurements.
pub const DEFAULT_GTOL: f64 = 1e-6;

/// The largest tolerance the certificate derives from a loose integrator: a cosine of 1e-3
/// between the residual and a sensitivity is as loose as "stationary" can sensibly mean
/// (100·rtol would pass anything at rtol ≥ 0.01).
pub const MAX_DERIVED_GTOL: f64 = 1e-3;

/// The iteration budget of one fit ([`DriverOptions::default`]). Real problems need more than
/// fides' 1 000: of the PEtab benchmark problems fitted from nominal and from nominal + 0.1,
/// five fits were still going at 1 000; at 3 000 Crauste (from nominal + 0.1) certifies after
/// 1 088 iterations, Giordano (both starts) stops by the progress rule after about 2 500
/// naming its sloppy direction, and Borghans from nominal + 0.1 stops at iteration 1 311
/// naming the unknowns it cannot determine. Only Borghans from nominal, an oscillator whose
/// phase the fit crawls along, still ends at the limit. docs/terminations.md has the figures.
pub const MAX_ITERATIONS: usize = 3000;

/// The iteration budget of each start of a multistart where the caller names none (the
/// command line's `--starts`, Python's `starts=`, the report's PEtab multistarts; the
/// library's `sysid_montecarlo::multistart` runs the method it is given, with that method's
/// budget). A start that crawls past 1 000 iterations seldom ends at the best optimum, and
/// another start costs less: of 11 PEtab problems × 40 random starts, 3 000 iterations a start
/// changed two problems only, Okuonghae (2.5 times the time, 17 certified instead of 12, the
/// same 4 within 0.1 of the best) and Crauste (12 % more time, the same counts).
pub const START_MAX_ITERATIONS: usize = 1000;

/// Options of the iteration driver, the same for every method (a method's options embed
/// them). Defaults: [`MAX_ITERATIONS`] (3 000) iterations, step tolerance 1e-10, gradient
/// tolerance 1e-10, gtol 100·rtol within [[`DEFAULT_GTOL`], [`MAX_DERIVED_GTOL`]], singular
/// above condition 1e12, integration budget 10·(k + 1)·(max_iterations + 1)·E for k unknowns and E experiments.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DriverOptions {
    /// Most updates of the unknowns.
    pub max_iterations: usize,
    /// Stop when the step satisfies ‖δz‖ ≤ tol·(‖z‖ + tol), tol not below the integrator's
    /// rtol ([`Problem::resolvable_step`](crate::Problem::resolvable_step)).
    pub step_tolerance: f64,
    /// Stop when the first-order optimality measure at an iterate (where the method computed
    /// the model's sensitivities there) is at most this.
    pub gradient_tolerance: f64,
    /// The certificate: the returned point counts as converged when its first-order
    /// optimality measure is at most this (or the model passes through the data). `None`:
    /// 100·rtol within [[`DEFAULT_GTOL`], [`MAX_DERIVED_GTOL`]] for the problem's
    /// integrator, whose error moves the measure by about 10·rtol.
    pub gtol: Option<f64>,
    /// A normal matrix counts as singular when the condition number of its Jacobi-scaled
    /// form exceeds this.
    pub max_condition: f64,
    /// The hard budget of model integrations (trial points of line searches and halvings
    /// included); `None`: 10·(k + 1)·(max_iterations + 1)·E for E experiments.
    pub max_integrations: Option<u64>,
    /// The wall-clock limit of one fit in seconds, read between iterations (an iteration
    /// begun runs to its end): the fit then stops with its best point, `time_limit`.
    /// `None` (the default): no limit.
    pub max_seconds: Option<f64>,
    /// Whether a method that [asks for it](crate::method::Step::coarse_first) (the trust
    /// regions) integrates at rtol [`COARSE_RTOL`](crate::method::COARSE_RTOL) until it
    /// closes in on a minimum, then at the problem's own tolerances (default true).
    pub coarse_first: bool,
}

impl Default for DriverOptions {
    fn default() -> Self {
        Self {
            max_iterations: MAX_ITERATIONS,
            step_tolerance: 1e-10,
            gradient_tolerance: 1e-10,
            gtol: None,
            max_condition: 1e12,
            max_integrations: None,
            max_seconds: None,
            coarse_first: true,
        }
    }
}

/// Options that hold the driver's ([`DriverOptions`]): a setter for each of its budgets and
/// tolerances, the same on every method's options.
///
/// ```
/// use sysid_core::{Driven, DriverOptions};
///
/// let options = DriverOptions::default().with_max_iterations(200).with_gtol(1e-8);
/// assert_eq!((options.max_iterations, options.gtol), (200, Some(1e-8)));
/// ```
pub trait Driven: Sized {
    /// The driver's options inside.
    fn driver_mut(&mut self) -> &mut DriverOptions;

    /// With these driver options.
    fn with_driver(mut self, driver: DriverOptions) -> Self {
        *self.driver_mut() = driver;
        self
    }

    /// With at most `max_iterations` updates of the unknowns.
    fn with_max_iterations(mut self, max_iterations: usize) -> Self {
        self.driver_mut().max_iterations = max_iterations;
        self
    }

    /// With the step tolerance ([`DriverOptions::step_tolerance`]).
    fn with_step_tolerance(mut self, step_tolerance: f64) -> Self {
        self.driver_mut().step_tolerance = step_tolerance;
        self
    }

    /// With the gradient tolerance ([`DriverOptions::gradient_tolerance`]).
    fn with_gradient_tolerance(mut self, gradient_tolerance: f64) -> Self {
        self.driver_mut().gradient_tolerance = gradient_tolerance;
        self
    }

    /// With the certificate's tolerance ([`DriverOptions::gtol`]).
    fn with_gtol(mut self, gtol: f64) -> Self {
        self.driver_mut().gtol = Some(gtol);
        self
    }

    /// With the condition number above which a normal matrix is singular.
    fn with_max_condition(mut self, max_condition: f64) -> Self {
        self.driver_mut().max_condition = max_condition;
        self
    }

    /// With at most `max_integrations` integrations of the model.
    fn with_max_integrations(mut self, max_integrations: u64) -> Self {
        self.driver_mut().max_integrations = Some(max_integrations);
        self
    }

    /// With a wall-clock limit of `max_seconds` per fit ([`DriverOptions::max_seconds`]).
    fn with_max_seconds(mut self, max_seconds: f64) -> Self {
        self.driver_mut().max_seconds = Some(max_seconds);
        self
    }

    /// With the coarse stage on or off ([`DriverOptions::coarse_first`]).
    fn with_coarse_first(mut self, coarse_first: bool) -> Self {
        self.driver_mut().coarse_first = coarse_first;
        self
    }
}

impl Driven for DriverOptions {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        self
    }
}

impl DriverOptions {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), OptionsError> {
        OptionsError::non_negative("step_tolerance", self.step_tolerance)?;
        OptionsError::non_negative("gradient_tolerance", self.gradient_tolerance)?;
        if let Some(gtol) = self.gtol {
            OptionsError::within("gtol", gtol, 0.0, 1.0)?;
        }
        if self.max_condition.is_nan() || self.max_condition <= 1.0 {
            return Err(OptionsError::OutOfRange {
                name: "max_condition",
                value: self.max_condition,
                low: 1.0,
                high: f64::INFINITY,
            });
        }
        if self.max_integrations == Some(0) {
            return Err(OptionsError::Zero { name: "max_integrations" });
        }
        if let Some(s) = self.max_seconds {
            OptionsError::non_negative("max_seconds", s)?;
        }
        Ok(())
    }

    /// The certificate's tolerance for an integrator of relative tolerance `rtol`.
    pub fn gtol_for(&self, rtol: f64) -> f64 {
        self.gtol.unwrap_or((100.0 * rtol).clamp(DEFAULT_GTOL, MAX_DERIVED_GTOL))
    }

    /// The integration budget for k unknowns and a problem of `experiments` experiments:
    /// 10·(k + 1)·(max_iterations + 1) evaluations of the model, each integrating every
    /// experiment once (saturating: a huge iteration count gives a huge budget, never a
    /// wrapped one).
    pub fn integration_budget(&self, k: usize, experiments: usize) -> u64 {
        self.max_integrations.unwrap_or_else(|| {
            (10 * (k as u64 + 1))
                .saturating_mul((self.max_iterations as u64).saturating_add(1))
                .saturating_mul(experiments.max(1) as u64)
        })
    }
}
