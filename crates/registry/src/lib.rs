//! # sysid-registry: every method by name
//!
//! The one table of the identification methods sysid offers: a name, what the method is, and
//! how to build it with the [`Settings`] every method shares. The command line, the criterion
//! benches, the Monte-Carlo studies and the report all take their methods from here, so a new
//! method is one [`Entry`] in [`entries`].
//!
//! ```
//! use sysid_registry::{Registry, Settings};
//! use sysid_systems::falling_body::falling_body;
//!
//! let problem = falling_body().problem(1).unwrap();
//! let registry = Registry::standard();
//! let goodman = registry.build("goodman", &Settings::default()).unwrap();
//! let estimate = goodman.fit(&problem).unwrap();
//! assert!(estimate.converged());
//! assert!(registry.build("newton", &Settings::default()).is_err());
//! ```
#![warn(missing_docs)]

use sysid_core::{DriverOptions, Method};
use sysid_gauss_newton::{GaussNewton, GaussNewtonOptions, JacobianSource};
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_levenberg_marquardt::{LevenbergMarquardt, LevenbergMarquardtOptions};
use sysid_multiple_shooting::{MultipleShooting, MultipleShootingOptions};
use sysid_ode::System;
use sysid_ode::testing::Decay;
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

/// One method of the registry.
pub struct Entry<S> {
    /// Its name on the command line and in every table.
    pub name: &'static str,
    /// What it is, in one line.
    pub description: &'static str,
    /// Builds it with the shared settings.
    pub build: fn(&Settings) -> Boxed<S>,
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
    /// An empty list of methods.
    #[error("no methods given")]
    Empty,
}

fn goodman(s: &Settings) -> GoodmanOptions {
    GoodmanOptions { driver: s.driver, ..GoodmanOptions::default() }
}

fn gauss_newton(s: &Settings) -> GaussNewtonOptions {
    GaussNewtonOptions { driver: s.driver, ..GaussNewtonOptions::default() }
}

fn quasilinearization(s: &Settings, start: Start) -> QuasilinearizationOptions {
    QuasilinearizationOptions { driver: s.driver, ..Default::default() }.with_start(start)
}

/// Every method sysid offers, in the order tables list them.
pub fn entries<S: System>() -> Vec<Entry<S>> {
    vec![
        Entry {
            name: "goodman",
            description: "Goodman 1966: Newton iteration on the initial values, full steps",
            build: |s| Box::new(Goodman::new(goodman(s))),
        },
        Entry {
            name: "goodman-halving",
            description: "Goodman 1966 with step halving while the cost rises",
            build: |s| Box::new(Goodman::new(goodman(s).with_step_halving(true))),
        },
        Entry {
            name: "gauss-newton",
            description: "argmin Gauss–Newton, full steps, Jacobian from sensitivities",
            build: |s| Box::new(GaussNewton::new(gauss_newton(s))),
        },
        Entry {
            name: "gauss-newton-ls",
            description: "argmin Gauss–Newton with Armijo line search, Jacobian from sensitivities",
            build: |s| {
                Box::new(GaussNewton::new(GaussNewtonOptions {
                    line_search: true,
                    ..gauss_newton(s)
                }))
            },
        },
        Entry {
            name: "gauss-newton-fd",
            description: "argmin Gauss–Newton with line search, forward-difference Jacobian",
            build: |s| {
                Box::new(GaussNewton::new(GaussNewtonOptions {
                    line_search: true,
                    jacobian: JacobianSource::FiniteDifferences,
                    ..gauss_newton(s)
                }))
            },
        },
        Entry {
            name: "levenberg-marquardt",
            description: "Levenberg–Marquardt, Moré's scaled trust region, bounds inside the step",
            build: |s| {
                Box::new(LevenbergMarquardt::new(LevenbergMarquardtOptions {
                    driver: s.driver,
                    ..LevenbergMarquardtOptions::default()
                }))
            },
        },
        Entry {
            name: "multiple-shooting",
            description: "Bock's multiple shooting: node values from the data, condensing, exact-penalty line search",
            build: |s| {
                Box::new(MultipleShooting::new(MultipleShootingOptions {
                    driver: s.driver,
                    intervals: s.shooting_intervals,
                }))
            },
        },
        Entry {
            name: "quasilinearization",
            description: "Bellman–Kagiwada–Kalaba 1963: iterate on trajectories of the linearised model",
            build: |s| Box::new(Quasilinearization::new(quasilinearization(s, s.ql_start.clone()))),
        },
        Entry {
            name: "quasilinearization-data",
            description: "quasilinearization starting from the data for measured states",
            build: |s| Box::new(Quasilinearization::new(quasilinearization(s, Start::Data))),
        },
    ]
}

/// The names and descriptions of [`entries`], for help texts and lists. (They do not depend
/// on the system; the list is instantiated with the smallest one.)
pub fn methods() -> Vec<(&'static str, &'static str)> {
    entries::<Decay>().iter().map(|e| (e.name, e.description)).collect()
}

/// A comma-separated list of names of [`entries`], each checked (no system needed).
pub fn parse_list(list: &str) -> Result<Vec<String>, RegistryError> {
    Registry::<Decay>::standard().parse_list(list)
}

/// The methods available for problems of system `S`: [`entries`], and any added with
/// [`with`](Self::with).
pub struct Registry<S> {
    entries: Vec<Entry<S>>,
}

impl<S: System> Registry<S> {
    /// Every method sysid offers.
    pub fn standard() -> Self {
        Self { entries: entries() }
    }

    /// With one more method (a method of your own, compared on the same footing).
    pub fn with(mut self, entry: Entry<S>) -> Self {
        self.entries.push(entry);
        self
    }

    /// The entries, in table order.
    pub fn entries(&self) -> &[Entry<S>] {
        &self.entries
    }

    /// The names, in table order.
    pub fn names(&self) -> Vec<&'static str> {
        self.entries.iter().map(|e| e.name).collect()
    }

    /// The entry called `name`.
    pub fn entry(&self, name: &str) -> Result<&Entry<S>, RegistryError> {
        self.entries.iter().find(|e| e.name == name).ok_or_else(|| RegistryError::Unknown {
            name: name.into(),
            known: self.names().join(", "),
        })
    }

    /// The method called `name`, built with `settings`.
    pub fn build(&self, name: &str, settings: &Settings) -> Result<Boxed<S>, RegistryError> {
        self.entry(name).map(|e| (e.build)(settings))
    }

    /// A comma-separated list of names, each checked.
    pub fn parse_list(&self, list: &str) -> Result<Vec<String>, RegistryError> {
        let names: Vec<String> =
            list.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect();
        if names.is_empty() {
            return Err(RegistryError::Empty);
        }
        for name in &names {
            self.entry(name)?;
        }
        Ok(names)
    }
}
