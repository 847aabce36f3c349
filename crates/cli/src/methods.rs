//! The methods the command line offers, by name, and the options every method shares.

use clap::Args;
use sysid_core::DriverOptions;
use sysid_ode::System;
use sysid_registry::{Boxed, Registry, Start};
pub use sysid_registry::{Settings as Common, methods};

/// The methods `compare` runs by default: all of them.
pub fn default_methods() -> Vec<&'static str> {
    methods().into_iter().map(|m| m.0).collect()
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

/// The command-line options every fitting command shares.
#[derive(Args, Debug, Clone, Default)]
pub struct MethodArgs {
    /// Most updates of the unknowns (default 50).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub max_iterations: Option<usize>,
    /// The certificate's tolerance: a fit converged when the first-order optimality of the
    /// point it returns (the largest cosine between the residual and a sensitivity of a free
    /// unknown; 0 at a minimum, at most 1) is at most this (default 1e-6, or 100·rtol for an
    /// integrator looser than rtol 1e-8).
    #[arg(long, value_name = "TOL", allow_hyphen_values = true)]
    pub gtol: Option<f64>,
    /// Hard budget of model integrations per fit, line-search and halving trials included
    /// (default 10·(k + 1)·(max iterations + 1) for k unknowns).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub max_integrations: Option<u64>,
    /// First trajectory of quasilinearization: the model from the guess, or the data.
    #[arg(long, value_enum, default_value_t = QlStart::Guess)]
    pub ql_start: QlStart,
    /// Hold an unknown at a value for this run, without editing the model file; it then
    /// counts as known (degrees of freedom, certificate). Repeatable.
    #[arg(long = "fix", value_name = "NAME=VALUE", value_parser = parse_fix, allow_hyphen_values = true)]
    pub fix: Vec<(String, f64)>,
}

impl MethodArgs {
    /// The shared method options.
    pub fn common(&self) -> Common {
        let mut driver = DriverOptions::default();
        if let Some(m) = self.max_iterations {
            driver.max_iterations = m;
        }
        driver.gtol = self.gtol;
        driver.max_integrations = self.max_integrations.or(driver.max_integrations);
        let ql_start = match self.ql_start {
            QlStart::Guess => Start::Guess,
            QlStart::Data => Start::Data,
        };
        Common { driver, ql_start }
    }

    /// Checks the options before anything runs.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.common().driver.validate().map_err(|e| anyhow::anyhow!("{}", cli_names(e)))
    }
}

/// An options error with the command line's spelling of the option.
fn cli_names(e: sysid_core::OptionsError) -> String {
    e.to_string()
        .replace("gtol", "--gtol")
        .replace("max_integrations", "--max-integrations")
        .replace("max_iterations", "--max-iterations")
}

/// `NAME=VALUE` of `--fix`.
fn parse_fix(s: &str) -> Result<(String, f64), String> {
    let (name, value) =
        s.split_once('=').ok_or_else(|| format!("`{s}`: expected NAME=VALUE, as in k1=0.5"))?;
    let name = name.trim();
    if name.is_empty() {
        return Err(format!("`{s}`: the name before `=` is empty"));
    }
    let v: f64 =
        value.trim().parse().map_err(|_| format!("`{s}`: `{}` is not a number", value.trim()))?;
    if !v.is_finite() {
        return Err(format!("`{s}`: the value must be a finite number"));
    }
    Ok((name.to_string(), v))
}

/// The method called `name` (usable from several threads, as studies run them).
pub fn method<S: System>(name: &str, common: &Common) -> anyhow::Result<Boxed<S>> {
    Ok(Registry::standard().build(name, common)?)
}

/// Checks a comma-separated list of method names.
pub fn parse_list(list: &str) -> anyhow::Result<Vec<String>> {
    Ok(sysid_registry::parse_list(list)?)
}
