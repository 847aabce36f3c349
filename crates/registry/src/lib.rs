//! # sysid-registry: every method and every system by name
//!
//! The one table of the identification methods sysid offers, [`ENTRIES`]: a name, what the
//! method is, the roles it plays when no method is named ([`Role`]), and how to build it with
//! the [`Settings`] every method shares. The command line (its help texts and default lists),
//! the criterion benches, the Monte-Carlo studies and the report all take their methods from
//! here, so a new method is one entry of the table (docs/methods.md, "Adding a method", lists
//! the seven files a method of a new crate touches).
//!
//! [`any`] is the other half: every system sysid fits by name (the catalogue's, a model
//! file's, a PEtab problem's) as one type, [`AnySystem`].
//!
//! ```
//! use sysid_registry::{Registry, Role, Settings};
//! use sysid_systems::falling_body::falling_body;
//!
//! let problem = falling_body().problem(1).unwrap();
//! let registry = Registry::standard();
//! let goodman = registry.build(Role::Default.method(), &Settings::default()).unwrap();
//! let estimate = goodman.fit(&problem).unwrap();
//! assert!(estimate.converged());
//! assert!(registry.build("newton", &Settings::default()).is_err());
//! ```
#![warn(missing_docs)]

pub mod any;

pub use any::AnySystem;

use sysid_core::{Driven, DriverOptions, Estimate, FitError, Method, OptionsError, Problem};
use sysid_gauss_newton::{GaussNewton, GaussNewtonOptions, JacobianSource};
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_levenberg_marquardt::{LevenbergMarquardt, LevenbergMarquardtOptions};
use sysid_multiple_shooting::{MultipleShooting, MultipleShootingOptions};
use sysid_ode::System;
pub use sysid_quasilinearization::Start;
use sysid_quasilinearization::{Quasilinearization, QuasilinearizationOptions};

/// A method ready to fit problems of system `S`, from any thread (studies run on rayon).
pub type Boxed<S> = Box<dyn Method<S> + Send + Sync>;

/// What every method shares: the driver's budgets and tolerances, and the first trajectory
/// of `quasilinearization` (`quasilinearization-data` always starts from the data).
#[derive(Clone, Debug, Default)]
pub struct Settings {
    /// The driver's budgets and tolerances.
    pub driver: DriverOptions,
    /// The first trajectory of `quasilinearization`.
    pub ql_start: Start,
    /// The number of shooting intervals of `multiple-shooting` (None: chosen from the data).
    pub shooting_intervals: Option<usize>,
}

impl Driven for Settings {
    fn driver_mut(&mut self) -> &mut DriverOptions {
        &mut self.driver
    }
}

impl Settings {
    /// Checks the settings, naming the first that cannot be used by its field
    /// ([`OptionsError::name`]): the driver's, then `shooting_intervals`.
    pub fn validate(&self) -> Result<(), OptionsError> {
        self.driver.validate()?;
        if self.shooting_intervals == Some(0) {
            return Err(OptionsError::Zero { name: "shooting_intervals" });
        }
        Ok(())
    }
}

/// Where a method is used when nobody names one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The method of `fit` and `predict` (exactly one entry has it).
    Default,
    /// The reference fit of studies and of the report, from the truth: it decides which
    /// trials succeed, and it draws the report's predictions (exactly one entry has it).
    Reference,
    /// Compared by `study` without `--methods`.
    Study,
    /// Compared by `report` without `--methods`.
    Report,
}

impl Role {
    /// The methods with this role, in table order.
    pub fn methods(self) -> Vec<&'static str> {
        ENTRIES.iter().filter(|e| e.roles.contains(&self)).map(|e| e.name).collect()
    }

    /// The method with this role (the first, for roles several methods share).
    pub fn method(self) -> &'static str {
        self.methods()[0]
    }
}

/// One method of the table.
pub struct Entry {
    /// Its name on the command line and in every table.
    pub name: &'static str,
    /// What it is, in one line.
    pub description: &'static str,
    /// Where it is used when no method is named.
    pub roles: &'static [Role],
    build: fn(&Settings) -> Built,
}

impl Entry {
    /// The method, built with the shared settings, for problems of any system.
    pub fn build(&self, settings: &Settings) -> Built {
        (self.build)(settings)
    }
}

/// Every method sysid offers, in the order tables list them.
pub static ENTRIES: [Entry; 12] = [
    Entry {
        name: "goodman",
        description: "Goodman 1966: Newton iteration on the initial values, full steps",
        roles: &[Role::Study, Role::Report],
        build: |s| Built::Goodman(Goodman::new(goodman(s))),
    },
    Entry {
        name: "goodman-halving",
        description: "Goodman 1966 with step halving while the cost rises",
        roles: &[Role::Reference],
        build: |s| Built::Goodman(Goodman::new(goodman(s).with_step_halving(true))),
    },
    Entry {
        name: "gauss-newton",
        description: "argmin Gauss–Newton, full steps, Jacobian from sensitivities",
        roles: &[],
        build: |s| Built::GaussNewton(GaussNewton::new(gauss_newton(s, false))),
    },
    Entry {
        name: "gauss-newton-ls",
        description: "argmin Gauss–Newton with Armijo line search, Jacobian from sensitivities",
        roles: &[Role::Study, Role::Report],
        build: |s| Built::GaussNewton(GaussNewton::new(gauss_newton(s, true))),
    },
    Entry {
        name: "gauss-newton-fd",
        description: "argmin Gauss–Newton with line search, forward-difference Jacobian",
        roles: &[],
        build: |s| {
            let jacobian = JacobianSource::FiniteDifferences;
            Built::GaussNewton(GaussNewton::new(GaussNewtonOptions {
                jacobian,
                ..gauss_newton(s, true)
            }))
        },
    },
    Entry {
        name: "levenberg-marquardt",
        description: "Levenberg–Marquardt, Moré's scaled trust region, bounds inside the step",
        roles: &[Role::Report],
        build: |s| Built::LevenbergMarquardt(LevenbergMarquardt::new(levenberg_marquardt(s))),
    },
    Entry {
        name: "hybrid-newton",
        description: "Fletcher–Xu 1987: Levenberg–Marquardt's trust region, on the full Hessian of ε (differenced sensitivity gradient) once ε falls slowly",
        roles: &[],
        build: |s| Built::LevenbergMarquardt(LevenbergMarquardt::hybrid(levenberg_marquardt(s))),
    },
    Entry {
        name: "nl2sol",
        description: "Dennis–Gay–Welsch's adaptive model (NL2SOL) in the same trust region: Gauss–Newton's, or Gauss–Newton's plus a structured secant correction, whichever predicts better",
        roles: &[Role::Default],
        build: |s| Built::LevenbergMarquardt(LevenbergMarquardt::adaptive(levenberg_marquardt(s))),
    },
    Entry {
        name: "geodesic-lm",
        description: "Transtrum–Sethna 2012: Levenberg–Marquardt's trust region, each step bent along the valley by its second-order term (one more plain integration per trial)",
        roles: &[],
        build: |s| Built::LevenbergMarquardt(LevenbergMarquardt::geodesic(levenberg_marquardt(s))),
    },
    Entry {
        name: "multiple-shooting",
        description: "Bock's multiple shooting: node values from the data, condensing, exact-penalty line search",
        roles: &[Role::Report],
        build: |s| {
            let options =
                MultipleShootingOptions { driver: s.driver, intervals: s.shooting_intervals };
            Built::MultipleShooting(MultipleShooting::new(options))
        },
    },
    Entry {
        name: "quasilinearization",
        description: "Bellman–Kagiwada–Kalaba 1963: iterate on trajectories of the linearised model",
        roles: &[Role::Study, Role::Report],
        build: |s| Built::Quasilinearization(quasilinearization(s, s.ql_start.clone())),
    },
    Entry {
        name: "quasilinearization-data",
        description: "quasilinearization starting from the data for measured states",
        roles: &[],
        build: |s| Built::Quasilinearization(quasilinearization(s, Start::Data)),
    },
];

fn goodman(s: &Settings) -> GoodmanOptions {
    GoodmanOptions { driver: s.driver, ..GoodmanOptions::default() }
}

fn gauss_newton(s: &Settings, line_search: bool) -> GaussNewtonOptions {
    GaussNewtonOptions { driver: s.driver, line_search, ..GaussNewtonOptions::default() }
}

fn levenberg_marquardt(s: &Settings) -> LevenbergMarquardtOptions {
    LevenbergMarquardtOptions { driver: s.driver, ..Default::default() }
}

fn quasilinearization(s: &Settings, start: Start) -> Quasilinearization {
    Quasilinearization::new(
        QuasilinearizationOptions { driver: s.driver, ..Default::default() }.with_start(start),
    )
}

/// A method of the table, built: one variant per method crate, each a [`Method`] for every
/// system.
#[derive(Clone, Debug)]
pub enum Built {
    /// `goodman`, `goodman-halving`.
    Goodman(Goodman),
    /// `gauss-newton`, `gauss-newton-ls`, `gauss-newton-fd`.
    GaussNewton(GaussNewton),
    /// `levenberg-marquardt`.
    LevenbergMarquardt(LevenbergMarquardt),
    /// `multiple-shooting`.
    MultipleShooting(MultipleShooting),
    /// `quasilinearization`, `quasilinearization-data`.
    Quasilinearization(Quasilinearization),
}

/// `$body` with `$m` bound to the method inside `$built`, whichever it is.
macro_rules! with_method {
    ($built:expr, $m:ident => $body:expr) => {
        match $built {
            Built::Goodman($m) => $body,
            Built::GaussNewton($m) => $body,
            Built::LevenbergMarquardt($m) => $body,
            Built::MultipleShooting($m) => $body,
            Built::Quasilinearization($m) => $body,
        }
    };
}

impl<S: System> Method<S> for Built {
    fn name(&self) -> &str {
        with_method!(self, m => Method::<S>::name(m))
    }
    fn start_point(&self) -> &str {
        with_method!(self, m => Method::<S>::start_point(m))
    }
    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        with_method!(self, m => m.fit_from(problem, start))
    }
    fn fit_once_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        with_method!(self, m => m.fit_once_from(problem, start))
    }
}

/// A name the registry does not hold.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RegistryError {
    /// No method of that name.
    #[error("unknown method `{name}` (methods: {known})")]
    Unknown {
        /// The name asked for.
        name: String,
        /// The names there are, comma-separated.
        known: String,
    },
    /// A list of methods that is empty, has an empty name or a name twice.
    #[error("{0}")]
    List(String),
}

/// A comma-separated list of names of [`ENTRIES`], each checked: no empty names, no name
/// twice.
pub fn parse_list(list: &str) -> Result<Vec<String>, RegistryError> {
    check_list(list, |name| entry(name).map(|_| ()))
}

/// The entry of [`ENTRIES`] called `name`.
pub fn entry(name: &str) -> Result<&'static Entry, RegistryError> {
    ENTRIES.iter().find(|e| e.name == name).ok_or_else(|| RegistryError::Unknown {
        name: name.into(),
        known: ENTRIES.iter().map(|e| e.name).collect::<Vec<_>>().join(", "),
    })
}

fn check_list(
    list: &str,
    known: impl Fn(&str) -> Result<(), RegistryError>,
) -> Result<Vec<String>, RegistryError> {
    let names: Vec<String> = list.split(',').map(|s| s.trim().to_string()).collect();
    if names.iter().all(String::is_empty) {
        return Err(RegistryError::List("no methods given".into()));
    }
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() {
            return Err(RegistryError::List(format!(
                "`{list}`: an empty name in the list of methods (two commas, or one at an end)"
            )));
        }
        known(name)?;
        if names[..i].contains(name) {
            return Err(RegistryError::List(format!(
                "`{list}`: the method `{name}` is listed twice"
            )));
        }
    }
    Ok(names)
}

/// How a method of a [`Registry`] is built.
enum Builder<S> {
    Standard(&'static Entry),
    Own { name: &'static str, build: fn(&Settings) -> Boxed<S> },
}

/// The methods available for problems of system `S`: [`ENTRIES`], and any added with
/// [`with`](Self::with) (a method of your own, compared on the same footing).
pub struct Registry<S> {
    methods: Vec<Builder<S>>,
}

impl<S: System> Registry<S> {
    /// Every method sysid offers.
    pub fn standard() -> Self {
        Self { methods: ENTRIES.iter().map(Builder::Standard).collect() }
    }

    /// With one more method.
    pub fn with(mut self, name: &'static str, build: fn(&Settings) -> Boxed<S>) -> Self {
        self.methods.push(Builder::Own { name, build });
        self
    }

    /// The names, in table order.
    pub fn names(&self) -> Vec<&'static str> {
        self.methods
            .iter()
            .map(|b| match b {
                Builder::Standard(e) => e.name,
                Builder::Own { name, .. } => name,
            })
            .collect()
    }

    /// The method called `name`, built with `settings`.
    pub fn build(&self, name: &str, settings: &Settings) -> Result<Boxed<S>, RegistryError> {
        let names = self.names();
        let Some(i) = names.iter().position(|n| *n == name) else {
            return Err(RegistryError::Unknown { name: name.into(), known: names.join(", ") });
        };
        Ok(match &self.methods[i] {
            Builder::Standard(e) => Box::new(e.build(settings)),
            Builder::Own { build, .. } => build(settings),
        })
    }

    /// Every method, built with `settings`, with its name, in table order.
    pub fn build_all(&self, settings: &Settings) -> Vec<(&'static str, Boxed<S>)> {
        let names = self.names();
        names.iter().map(|n| (*n, self.build(n, settings).expect("a listed name"))).collect()
    }

    /// A comma-separated list of names, each checked: no empty names, no name twice.
    pub fn parse_list(&self, list: &str) -> Result<Vec<String>, RegistryError> {
        let names = self.names();
        check_list(list, |name| {
            if names.contains(&name) {
                Ok(())
            } else {
                Err(RegistryError::Unknown { name: name.into(), known: names.join(", ") })
            }
        })
    }
}
