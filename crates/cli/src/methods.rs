//! The methods the command line offers, by name.

use sysid_core::Method;
use sysid_gauss_newton::{GaussNewton, GaussNewtonOptions, JacobianSource};
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_ode::System;
use sysid_quasilinearization::{Quasilinearization, QuasilinearizationOptions, Start};

/// Method names and what they are, in the order tables list them.
pub const METHODS: &[(&str, &str)] = &[
    ("goodman", "Goodman 1966: Newton iteration on the initial values, full steps"),
    ("goodman-halving", "Goodman 1966 with step halving while the cost rises"),
    ("gauss-newton", "argmin Gauss–Newton, full steps, Jacobian from sensitivities"),
    ("gauss-newton-ls", "argmin Gauss–Newton with Armijo line search, Jacobian from sensitivities"),
    ("gauss-newton-fd", "argmin Gauss–Newton with line search, forward-difference Jacobian"),
    (
        "quasilinearization",
        "Bellman–Kagiwada–Kalaba 1963: iterate on trajectories of the linearised model",
    ),
    ("quasilinearization-data", "quasilinearization starting from the data for measured states"),
];

/// The methods `compare` runs by default.
pub fn default_methods() -> Vec<&'static str> {
    METHODS.iter().map(|m| m.0).collect()
}

/// Options shared by every method, from the command line.
#[derive(Clone, Copy, Debug, Default)]
pub struct Common {
    /// Iteration budget, if given.
    pub max_iterations: Option<usize>,
    /// The first trajectory of `quasilinearization`.
    pub ql_start: QlStart,
    /// Goodman's cost tolerance (see `GoodmanOptions::cost_tolerance`), if given.
    pub cost_tolerance: Option<f64>,
}

/// `--ql-start`: the first trajectory of quasilinearization.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum QlStart {
    /// The model integrated from the starting guess.
    #[default]
    Guess,
    /// The data for measured states, the guess's trajectory for the others.
    Data,
}

/// The method called `name` (usable from several threads, as studies run them).
pub fn method<S: System>(
    name: &str,
    common: Common,
) -> anyhow::Result<Box<dyn Method<S> + Send + Sync>> {
    let mut goodman = GoodmanOptions::default();
    let mut gn = GaussNewtonOptions::default();
    let mut ql = QuasilinearizationOptions::default();
    if let Some(c) = common.cost_tolerance {
        goodman.cost_tolerance = c;
    }
    if let Some(m) = common.max_iterations {
        goodman.max_iterations = m;
        gn.max_iterations = m as u64;
        ql.max_iterations = m;
    }
    let ql_start = match common.ql_start {
        QlStart::Guess => Start::Guess,
        QlStart::Data => Start::Data,
    };
    Ok(match name {
        "goodman" => Box::new(Goodman::new(goodman)),
        "goodman-halving" => Box::new(Goodman::new(goodman.with_step_halving(true))),
        "gauss-newton" => Box::new(GaussNewton::new(gn)),
        "gauss-newton-ls" => {
            Box::new(GaussNewton::new(GaussNewtonOptions { line_search: true, ..gn }))
        }
        "gauss-newton-fd" => Box::new(GaussNewton::new(GaussNewtonOptions {
            line_search: true,
            jacobian: JacobianSource::FiniteDifferences,
            ..gn
        })),
        "quasilinearization" => Box::new(Quasilinearization::new(ql.with_start(ql_start))),
        "quasilinearization-data" => Box::new(Quasilinearization::new(ql.with_start(Start::Data))),
        _ => anyhow::bail!(
            "unknown method `{name}` (methods: {})",
            METHODS.iter().map(|m| m.0).collect::<Vec<_>>().join(", ")
        ),
    })
}

/// Checks a comma-separated list of method names.
pub fn parse_list(list: &str) -> anyhow::Result<Vec<String>> {
    let names: Vec<String> =
        list.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect();
    if names.is_empty() {
        anyhow::bail!("no methods given");
    }
    for n in &names {
        if !METHODS.iter().any(|m| m.0 == n) {
            anyhow::bail!(
                "unknown method `{n}` (methods: {})",
                METHODS.iter().map(|m| m.0).collect::<Vec<_>>().join(", ")
            );
        }
    }
    Ok(names)
}
