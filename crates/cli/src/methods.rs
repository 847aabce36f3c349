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
    /// Shooting intervals of multiple-shooting (default: one per 5 sample times, at most 10).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub shooting_intervals: Option<usize>,
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
        Common { driver, ql_start, shooting_intervals: self.shooting_intervals }
    }

    /// Checks the options before anything runs.
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.shooting_intervals == Some(0) {
            anyhow::bail!("--shooting-intervals must be at least 1");
        }
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

/// `--starts`: multistart for `fit` and `compare`.
#[derive(Args, Debug, Clone, Default)]
pub struct StartsArgs {
    /// Fit from N starts instead of one, in parallel: the guess, then a Latin hypercube of
    /// N − 1 starts within the bounds of unknowns bounded on both sides, ±ρ (--start-spread)
    /// around the guess for the others. Prints the best fit and how many starts reached it,
    /// with the distinct minima found.
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub starts: Option<usize>,
    /// Seed of the starts' Latin hypercube (default 1).
    #[arg(long, value_name = "SEED", allow_negative_numbers = true)]
    pub starts_seed: Option<u64>,
    /// ρ of --starts for unknowns without two bounds: guess·(1 + ρu), u uniform on [−1, 1]
    /// (guess·(1 + ρ)^u on a log scale, ρu for a guess of 0). Default 0.5.
    #[arg(long, value_name = "RHO", allow_hyphen_values = true)]
    pub start_spread: Option<f64>,
}

impl StartsArgs {
    /// The multistart options, when --starts was given.
    pub fn options(&self) -> anyhow::Result<Option<sysid_montecarlo::MultistartOptions>> {
        let defaults = sysid_montecarlo::MultistartOptions::default();
        let spread = self.start_spread.unwrap_or(defaults.spread);
        if !(spread > 0.0 && spread.is_finite()) {
            anyhow::bail!("--start-spread must be a positive number, got {spread}");
        }
        let Some(starts) = self.starts else {
            if self.start_spread.is_some() || self.starts_seed.is_some() {
                let option =
                    if self.start_spread.is_some() { "--start-spread" } else { "--starts-seed" };
                anyhow::bail!("{option} needs --starts N");
            }
            return Ok(None);
        };
        if starts == 0 {
            anyhow::bail!("--starts must be at least 1");
        }
        Ok(Some(sysid_montecarlo::MultistartOptions {
            starts,
            seed: self.starts_seed.unwrap_or(defaults.seed),
            spread,
        }))
    }
}

/// The text of a multistart's `starts` object.
pub fn describe_starts(s: &sysid_montecarlo::multistart::Starts) -> String {
    let plural = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    let minima: Vec<String> = s
        .minima
        .iter()
        .map(|m| {
            format!("ε = {} ({})", crate::format::significant(m.cost, 10), plural(m.count, "start"))
        })
        .collect();
    format!(
        "{} in {:.1} ms (the guess, then a Latin hypercube, seed {}, ρ {}): {} converged, {} reached the best (start {}); {}: {}",
        plural(s.count, "start"),
        s.elapsed_ms,
        s.seed,
        s.spread,
        s.converged,
        s.reached_best,
        s.best_start,
        if s.minima.len() == 1 {
            "1 distinct minimum".to_string()
        } else {
            format!("{} distinct minima", s.minima.len())
        },
        if minima.is_empty() { "none".to_string() } else { minima.join(", ") }
    )
}
