//! The option groups several commands share: where the problem comes from, the method and
//! its budgets, multistart, the integrator, and the output format.
//!
//! Options are checked once, by the libraries that use them (`DriverOptions`, `Settings`,
//! `MultistartOptions`, `Integrator`); each names the setting it refuses by its field, and
//! [`flag`] says how the command line spells it. Numbers are read by [`count`] and
//! [`number`], so that `--rtol -1e-8` reaches the check and is refused by name rather than
//! taken for another option.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use sysid_core::{DriverOptions, START_MAX_ITERATIONS};
use sysid_ode::{Integrator, Scheme};
use sysid_registry::{ENTRIES, Role, Settings, Start};

/// The command line's spelling of a library setting: the fields whose flag is not the
/// field's name with `-` for `_`.
const FLAGS: &[(&str, &str)] =
    &[("spread", "--start-spread"), ("starts", "--starts"), ("budget", "--starts-budget")];

/// The flag of the setting `field` (`gtol` → `--gtol`, `max_iterations` →
/// `--max-iterations`, `spread` → `--start-spread`).
pub fn flag(field: &str) -> String {
    match FLAGS.iter().find(|(f, _)| *f == field) {
        Some((_, flag)) => (*flag).to_string(),
        None => format!("--{}", field.replace('_', "-")),
    }
}

/// The error of a setting the libraries refused, with its flag.
fn refused(field: &str, problem: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{} {problem}", flag(field))
}

/// A count (`--max-iterations 20`): a whole number ≥ 0; anything else, a negative number
/// included, is refused with what was given.
pub fn count(s: &str) -> Result<usize, String> {
    // As given: `99999999999999999999` read back as a float was 100000000000000000000.
    let given = s.trim();
    given.parse::<usize>().map_err(|_| match given.parse::<f64>() {
        Ok(v) if v < 0.0 => format!("is a count, not negative: got {given}"),
        Ok(v) if v >= usize::MAX as f64 => {
            format!("must be a whole number at most {}, got {given}", usize::MAX)
        }
        Ok(_) => format!("must be a whole number, got {given}"),
        Err(_) => format!("`{s}` is not a whole number"),
    })
}

/// A seed: a whole number ≥ 0.
pub fn seed(s: &str) -> Result<u64, String> {
    let given = s.trim();
    given.parse::<u64>().map_err(|_| match given.parse::<f64>() {
        Ok(_) => format!("must be a whole number from 0 to {}, got {given}", u64::MAX),
        Err(_) => format!("`{s}` is not a whole number"),
    })
}

/// A number (`--rtol 1e-8`, `--rtol -1e-8`): any float, checked where it is used.
pub fn number(s: &str) -> Result<f64, String> {
    s.trim().parse::<f64>().map_err(|_| format!("`{s}` is not a number"))
}

/// Output format of reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// A readable table.
    #[default]
    Table,
    /// The JSON object documented in docs/json.md.
    Json,
}

/// `--system NAME` or `--model FILE [--data CSV]`.
#[derive(Args, Debug, Clone, Default)]
pub struct SourceArgs {
    /// A catalogue system (`sysid systems` lists them).
    #[arg(long, value_name = "NAME", conflicts_with = "model")]
    pub system: Option<String>,
    /// A model file (TOML; its keys in docs/model-files.md).
    #[arg(long, value_name = "FILE", conflicts_with = "petab")]
    pub model: Option<PathBuf>,
    /// A PEtab problem (its YAML file; docs/petab.md), imported as a model file with several
    /// experiments: the start is the parameter table's nominal values.
    #[arg(long, value_name = "YAML", conflicts_with_all = ["system", "data"])]
    pub petab: Option<PathBuf>,
    // A catalogue system has data of its own: --data with --system is an error, not ignored.
    // `requires = "model"` alone does not refuse it: clap drops a requirement that conflicts
    // with an argument given (--model conflicts with --system).
    /// The data file (CSV) to use instead of the model file's `[data] file`.
    #[arg(long, value_name = "CSV", requires = "model", conflicts_with = "system")]
    pub data: Option<PathBuf>,
    /// Seed of the synthetic data: a catalogue system's noise (fixed data ignore it), and a
    /// study's trials (trial i draws from the random stream i of this seed).
    #[arg(long, default_value_t = 1, value_parser = seed, allow_hyphen_values = true)]
    pub seed: u64,
}

impl SourceArgs {
    /// The model file or PEtab problem given, if any.
    pub fn file(&self) -> Option<&std::path::Path> {
        self.model.as_deref().or(self.petab.as_deref())
    }

    /// Reads `path`: a model file, or the PEtab problem imported as one.
    pub fn load(&self, path: &std::path::Path) -> anyhow::Result<sysid_model::Model> {
        Ok(self.load_with_nominal(path)?.0)
    }

    /// As [`load`](Self::load), with a PEtab problem's nominal values outside their bounds
    /// ([`sysid_petab::Imported::nominal`]).
    pub fn load_with_nominal(
        &self,
        path: &std::path::Path,
    ) -> anyhow::Result<(sysid_model::Model, Vec<(String, f64)>)> {
        match self.petab {
            Some(_) => {
                let imported = sysid_petab::import(path)?;
                for warning in &imported.warnings {
                    eprintln!("warning: {warning}");
                }
                Ok((imported.model, imported.nominal))
            }
            None => Ok((sysid_model::Model::load(path)?, Vec::new())),
        }
    }

    /// What kind of problem `file` is, in a report's words.
    pub fn kind(&self) -> &'static str {
        if self.petab.is_some() { "PEtab problem" } else { "model file" }
    }
}

/// The help of `--method`: every method of the registry, one line each.
fn method_help() -> String {
    let mut help = String::from("The method:");
    for e in &ENTRIES {
        help += &format!("\n  {:<24} {}", e.name, e.description);
    }
    help
}

/// `--method NAME` of the commands that fit with one method.
#[derive(Args, Debug, Clone)]
pub struct MethodArg {
    #[arg(long, value_name = "METHOD", default_value = Role::Default.method(), help = method_help())]
    pub method: String,
}

impl MethodArg {
    /// The method named, checked before any work ([`one_method`]).
    pub fn check(&self) -> anyhow::Result<()> {
        one_method(&self.method, "--method")
    }
}

/// `name`, given to `flag`, is one method of the registry, exactly: a list, or a name with
/// spaces around it, was let through by the check of lists and refused only once the
/// problem was loaded, as if the problem were at fault.
pub fn one_method(name: &str, flag: &str) -> anyhow::Result<()> {
    if name.contains(',') {
        anyhow::bail!(
            "{flag} `{name}`: one method here (`sysid compare --methods A,B` compares several)"
        );
    }
    sysid_registry::entry(name).map(|_| ()).map_err(|e| anyhow::anyhow!("{flag}: {e}"))
}

/// `--ql-start`: the first trajectory of quasilinearization.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
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
    /// Most updates of the unknowns (default 3000 for one fit; with --starts, 1000 for each
    /// start: a start that crawls past 1000 seldom ends at the best optimum, and another start
    /// costs less).
    #[arg(long, value_name = "N", value_parser = count, allow_hyphen_values = true)]
    pub max_iterations: Option<usize>,
    /// The certificate's tolerance: a fit converged when the first-order optimality of the
    /// point it returns (the largest cosine between the residual and a sensitivity of a free
    /// unknown; 0 at a minimum, at most 1) is at most this (default 1e-6, or 100·rtol, at
    /// most 1e-3, for an integrator looser than rtol 1e-8).
    #[arg(long, value_name = "TOL", value_parser = number, allow_hyphen_values = true)]
    pub gtol: Option<f64>,
    /// Hard budget of model integrations per fit, line-search and halving trials included
    /// (default 10·(k + 1)·(max iterations + 1)·E for k unknowns and E experiments: each
    /// experiment's integration counts as one).
    #[arg(long, value_name = "N", value_parser = seed, allow_hyphen_values = true)]
    pub max_integrations: Option<u64>,
    /// Wall-clock limit of one fit in seconds (each start's, with --starts), read between
    /// iterations: the fit then stops with its best point (termination `time_limit`).
    /// Default: none.
    #[arg(long, value_name = "SECONDS", value_parser = number, allow_hyphen_values = true)]
    pub max_seconds: Option<f64>,
    /// Integrate at the problem's own tolerances from the first iteration. By default the
    /// trust-region methods (nl2sol, levenberg-marquardt, hybrid-newton, geodesic-lm)
    /// integrate at rtol 1e-6 (atol scaled alike) until they close in on a minimum, then go
    /// on at the problem's tolerances, where the certificate judges the point.
    #[arg(long)]
    pub no_coarse_first: bool,
    /// First trajectory of quasilinearization: the model from the guess, or the data.
    #[arg(long, value_enum, default_value_t = QlStart::Guess)]
    pub ql_start: QlStart,
    /// Shooting intervals of multiple-shooting (default: one per 5 sample times, at most 10).
    #[arg(long, value_name = "N", value_parser = count, allow_hyphen_values = true)]
    pub shooting_intervals: Option<usize>,
    /// Hold an unknown at a value for this run, without editing the model file; it then
    /// counts as known (degrees of freedom, certificate). Repeatable.
    #[arg(long = "fix", value_name = "NAME=VALUE", value_parser = parse_fix, allow_hyphen_values = true)]
    pub fix: Vec<(String, f64)>,
    /// Start the fit from this value of an unknown instead of its guess (within its bounds;
    /// with --starts, the first start, and the centre the others are drawn around for an
    /// unknown without two bounds). Repeatable. Not on study, whose trials draw their starts
    /// (refused there).
    #[arg(long = "start", value_name = "NAME=VALUE", value_parser = parse_fix, allow_hyphen_values = true)]
    pub start: Vec<(String, f64)>,
    /// When stderr is not a terminal (a batch job's log), print a plain progress line every
    /// this many seconds (0: never): the iterate of a single fit, the starts done of
    /// --starts, the points fitted and the profiles traced of profile, the reference fit and
    /// the trials done of a study, the starts done of a basin map. On a terminal the line is
    /// redrawn in place.
    #[arg(long, default_value_t = 60.0, value_name = "SECONDS", value_parser = number, allow_hyphen_values = true)]
    pub log_every: f64,
}

impl MethodArgs {
    /// The settings every method shares.
    pub fn settings(&self) -> Settings {
        let mut driver = DriverOptions::default();
        if let Some(m) = self.max_iterations {
            driver.max_iterations = m;
        }
        driver.gtol = self.gtol;
        driver.max_integrations = self.max_integrations.or(driver.max_integrations);
        driver.max_seconds = self.max_seconds;
        driver.coarse_first = !self.no_coarse_first;
        let ql_start = match self.ql_start {
            QlStart::Guess => Start::Guess,
            QlStart::Data => Start::Data,
        };
        Settings { driver, ql_start, shooting_intervals: self.shooting_intervals }
    }

    /// The settings of one fit, or of each start where there are `starts` (the options of
    /// `--starts`): [`settings`](Self::settings), with [`START_MAX_ITERATIONS`] iterations
    /// for each start where `--max-iterations` is not given. Every entry point with
    /// `--starts` takes its settings here.
    pub fn settings_for(&self, starts: Option<&sysid_montecarlo::MultistartOptions>) -> Settings {
        let mut settings = self.settings();
        if starts.is_some() {
            settings.driver.max_iterations = self.max_iterations.unwrap_or(START_MAX_ITERATIONS);
        }
        settings
    }

    /// Checks the options before anything runs (the registry's check, each refusal naming
    /// its flag).
    pub fn validate(&self) -> anyhow::Result<()> {
        for (i, (name, _)) in self.fix.iter().enumerate() {
            if self.fix[..i].iter().any(|(n, _)| n == name) {
                anyhow::bail!("--fix {name}=… is given twice: fix each unknown once");
            }
        }
        for (i, (name, _)) in self.start.iter().enumerate() {
            if self.start[..i].iter().any(|(n, _)| n == name) {
                anyhow::bail!("--start {name}=… is given twice: start each unknown once");
            }
            if self.fix.iter().any(|(n, _)| n == name) {
                anyhow::bail!(
                    "{name} is given both --fix and --start: a fixed unknown does not move"
                );
            }
        }
        if !(self.log_every >= 0.0 && self.log_every.is_finite()) {
            anyhow::bail!(
                "--log-every must be a finite non-negative number of seconds (0: never), got {}",
                self.log_every
            );
        }
        self.settings().validate().map_err(|e| refused(e.name(), e.problem()))
    }
}

/// `NAME=VALUE` of `--fix` and `--start`.
pub(crate) fn parse_fix(s: &str) -> Result<(String, f64), String> {
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

/// Refuses a name that `pairs` (an option's NAME=VALUE values, as [`parse_fix`] reads them)
/// gives twice: the last was kept silently.
pub(crate) fn once_each(pairs: &[(String, f64)], option: &str) -> anyhow::Result<()> {
    for (k, (name, _)) in pairs.iter().enumerate() {
        if pairs[..k].iter().any(|(n, _)| n == name) {
            anyhow::bail!("{option} {name}: given twice");
        }
    }
    Ok(())
}

/// `--starts`: multistart for `fit`, `compare` and `profile`.
#[derive(Args, Debug, Clone, Default)]
pub struct StartsArgs {
    /// Fit from N starts instead of one, in parallel: the guess, then N − 1 starts drawn
    /// uniformly on each unknown's scale within its bounds (--start-sampling), ±ρ
    /// (--start-spread) around the guess for unknowns without two bounds. Prints the best
    /// fit, how many starts reached it (converged within 0.1 of its objective), the
    /// distinct minima and every start's outcome (the waterfall, in the JSON). Each start
    /// may take 1000 iterations (--max-iterations); the start that ran out of them lowest,
    /// below every converged start, may be fitted on once more at the end. At most a million.
    #[arg(long, value_name = "N", value_parser = count, allow_hyphen_values = true)]
    pub starts: Option<usize>,
    /// Seed of the starts' draws (default 1).
    #[arg(long, value_name = "SEED", value_parser = seed, allow_hyphen_values = true)]
    pub starts_seed: Option<u64>,
    /// How the starts after the guess are drawn: uniformly on each unknown's scale, every
    /// start independently (the field's way), or a Latin hypercube (one start in each Nth of
    /// every unknown's range).
    #[arg(long, value_enum, value_name = "HOW")]
    pub start_sampling: Option<SamplingArg>,
    /// Draw all N starts; without it the first start is the problem's guess.
    #[arg(long)]
    pub starts_without_guess: bool,
    /// ρ of --starts for unknowns without two bounds: guess·(1 + ρu), u uniform on [−1, 1]
    /// (guess·(1 + ρ)^u on a log scale, ρu for a guess of 0). Default 0.5.
    #[arg(long, value_name = "RHO", value_parser = number, allow_hyphen_values = true)]
    pub start_spread: Option<f64>,
    /// Wall-clock seconds after which no further start begins: the starts are taken in
    /// order, so those fitted are the first ones (the JSON's `not_started` counts the rest);
    /// a fit already begun runs to its end. Default: no limit.
    #[arg(long, value_name = "SECONDS", value_parser = number, allow_hyphen_values = true)]
    pub starts_budget: Option<f64>,
}

impl StartsArgs {
    /// Refuses `--start` beside `--starts-without-guess`: `--start` sets the first start,
    /// which that option draws instead (it was ignored silently).
    pub fn check_start(&self, start: &[(String, f64)]) -> anyhow::Result<()> {
        if self.starts_without_guess && !start.is_empty() {
            anyhow::bail!(
                "--start sets the first start of --starts, which --starts-without-guess draws instead: give one of them"
            );
        }
        Ok(())
    }

    /// The multistart options, when --starts was given (checked by the multistart's own
    /// check, each refusal naming its flag).
    pub fn options(&self) -> anyhow::Result<Option<sysid_montecarlo::MultistartOptions>> {
        let defaults = sysid_montecarlo::MultistartOptions::default();
        let Some(starts) = self.starts else {
            let given = [
                (self.start_spread.is_some(), "--start-spread"),
                (self.starts_seed.is_some(), "--starts-seed"),
                (self.start_sampling.is_some(), "--start-sampling"),
                (self.starts_without_guess, "--starts-without-guess"),
                (self.starts_budget.is_some(), "--starts-budget"),
            ];
            if let Some((_, option)) = given.iter().find(|g| g.0) {
                anyhow::bail!("{option} needs --starts N");
            }
            return Ok(None);
        };
        // Seconds that a Duration cannot hold are refused here, a zero budget by the
        // multistart's own check.
        let budget = self
            .starts_budget
            .map(|seconds| {
                std::time::Duration::try_from_secs_f64(seconds).map_err(|_| {
                    refused(
                        "budget",
                        format!("must be a finite positive number of seconds, got {seconds:?}"),
                    )
                })
            })
            .transpose()?;
        let options = sysid_montecarlo::MultistartOptions {
            starts,
            seed: self.starts_seed.unwrap_or(defaults.seed),
            spread: self.start_spread.unwrap_or(defaults.spread),
            sampling: match self.start_sampling {
                Some(SamplingArg::LatinHypercube) => sysid_montecarlo::Sampling::LatinHypercube,
                Some(SamplingArg::Uniform) | None => sysid_montecarlo::Sampling::Uniform,
            },
            guess: !self.starts_without_guess,
            budget,
        };
        options.validate().map_err(|e| refused(e.name(), e.problem()))?;
        Ok(Some(options))
    }
}

/// `--start-sampling`: how multistart draws its starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SamplingArg {
    /// Each unknown uniformly on its scale within its bounds, every start independently.
    Uniform,
    /// A Latin hypercube: one start in each Nth of every unknown's range.
    LatinHypercube,
}

/// The integration scheme, by its command-line name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SchemeArg {
    /// Dormand–Prince 5(4), adaptive (explicit; the default for non-stiff systems).
    Dopri5,
    /// Dormand–Prince 8(5,3), adaptive (explicit, order 8: far fewer steps than dopri5 at
    /// tight tolerances, --rtol 1e-9 and below, on non-stiff systems; mind --atol)
    Dop853,
    /// Classical Runge–Kutta 4 with the fixed step --fixed-step (explicit).
    Rk4,
    /// Rodas4, a Rosenbrock method of order 4 with exact Jacobians (implicit, for stiff
    /// systems).
    Rodas4,
    /// Rodas5P, a Rosenbrock method of order 5 with exact Jacobians (implicit, for stiff
    /// systems; about half Rodas4's steps at tight tolerances).
    Rodas5p,
    /// DOPRI5, switching to Rodas5P when the steps become limited by stability (the default of PEtab problems).
    Auto,
    /// Variable-order BDF (numerical differentiation formulas, orders 1–5), the factorised
    /// matrix kept over many steps (implicit, for large stiff systems; its error at a given
    /// --rtol is tens of times the one-step schemes': ask for a tenth; no state events).
    Bdf,
}

impl From<SchemeArg> for Scheme {
    fn from(s: SchemeArg) -> Self {
        match s {
            SchemeArg::Dopri5 => Scheme::Dopri5,
            SchemeArg::Dop853 => Scheme::Dop853,
            SchemeArg::Rk4 => Scheme::Rk4,
            SchemeArg::Rodas4 => Scheme::Rodas4,
            SchemeArg::Rodas5p => Scheme::Rodas5p,
            SchemeArg::Auto => Scheme::Auto,
            SchemeArg::Bdf => Scheme::Bdf,
        }
    }
}

/// Integrator settings that replace the system's or model file's where given.
#[derive(Args, Debug, Clone, Copy, Default)]
pub struct IntegratorArgs {
    /// Integration scheme (default: the system's or model file's).
    #[arg(long, value_enum, value_name = "SCHEME")]
    pub integrator: Option<SchemeArg>,
    /// Relative tolerance of the integrator (default: the system's).
    #[arg(long, value_name = "RTOL", value_parser = number, allow_hyphen_values = true)]
    pub rtol: Option<f64>,
    /// Absolute tolerance of the integrator, ≥ 0 (default: the system's; 0 controls the
    /// relative error alone).
    #[arg(long, value_name = "ATOL", value_parser = number, allow_hyphen_values = true)]
    pub atol: Option<f64>,
    /// A fixed step size (required by rk4; turns error control off for the others). The
    /// certificate then measures the fit against an error-controlled integration (rtol
    /// 1e-10): a step too coarse for the model shows as an integration error.
    #[arg(long = "fixed-step", value_name = "H", value_parser = number, allow_hyphen_values = true)]
    pub fixed_step: Option<f64>,
    /// Step budget of one integration (default 100000).
    #[arg(long, value_name = "N", value_parser = count, allow_hyphen_values = true)]
    pub max_steps: Option<usize>,
}

impl IntegratorArgs {
    /// Whether any integrator option was given.
    pub fn given(&self) -> bool {
        self.integrator.is_some()
            || self.rtol.is_some()
            || self.atol.is_some()
            || self.fixed_step.is_some()
            || self.max_steps.is_some()
    }

    /// `integrator` with the settings given on the command line, checked by the
    /// integrator's own check (a refusal names its flag).
    pub fn apply_to(&self, integrator: Integrator) -> anyhow::Result<Integrator> {
        let mut out = integrator;
        if let Some(scheme) = self.integrator {
            out.scheme = scheme.into();
            // A fixed step belongs to the scheme it was given for.
            out.fixed_step = None;
        }
        out.rtol = self.rtol.unwrap_or(out.rtol);
        out.atol = self.atol.unwrap_or(out.atol);
        if self.fixed_step.is_some() {
            out.fixed_step = self.fixed_step;
        }
        out.max_steps = self.max_steps.unwrap_or(out.max_steps);
        out.validate().map_err(|e| refused(e.name, e.problem))?;
        Ok(out)
    }

    /// Checks the values given before anything runs: applied to the default integrator
    /// (a model file's or system's own settings are checked again when applied to them).
    pub fn validate(&self) -> anyhow::Result<()> {
        self.apply_to(Integrator::default()).map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The budgets docs/terminations.md states: 3000 iterations for one fit, 1000 for each
    /// start of `--starts`, and `--max-iterations` for both where given (also where it is the
    /// other default's number).
    #[test]
    fn one_fit_and_each_start_have_their_documented_budgets() {
        let starts = sysid_montecarlo::MultistartOptions::default();
        let budget = |args: &MethodArgs, starts| args.settings_for(starts).driver.max_iterations;
        let none = MethodArgs::default();
        assert_eq!((budget(&none, None), budget(&none, Some(&starts))), (3000, 1000));
        for given in [7, 1000, 3000] {
            let args = MethodArgs { max_iterations: Some(given), ..MethodArgs::default() };
            assert_eq!((budget(&args, None), budget(&args, Some(&starts))), (given, given));
        }
        // Everything else of a start's settings is the fit's.
        let (fit, start) = (none.settings_for(None), none.settings_for(Some(&starts)));
        assert_eq!(DriverOptions { max_iterations: 3000, ..start.driver }, fit.driver);
        assert_eq!(start.shooting_intervals, fit.shooting_intervals);
    }
}
