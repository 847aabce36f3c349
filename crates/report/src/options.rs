//! What a report covers, and who watches it being written.

use std::path::PathBuf;

use sysid_core::DriverOptions;
use sysid_registry::{Role, Settings};

/// What a report covers (the defaults are `sysid report`'s).
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// The report's directory: README.md and one directory per system. A report replaces
    /// the files an earlier report wrote there (listed in its `.sysid-report`) and no others.
    pub out: PathBuf,
    /// Catalogue systems (empty: all).
    pub systems: Vec<String>,
    /// The methods compared, by their registry names.
    pub methods: Vec<String>,
    /// Trials of each system's study.
    pub trials: usize,
    /// Start perturbation ρ of the studies.
    pub perturb: f64,
    /// Points per axis of the basin maps.
    pub grid: usize,
    /// Spread of the basin maps: starts from truth·(1 − s) to truth·(1 + s), and from
    /// truth/(1 + s) to truth·(1 + s) for a log-scale unknown.
    pub basin_spread: f64,
    /// Starts of each method's multistart on the default data.
    pub starts: usize,
    /// Seed of the data, the trials, the default-start fits and the multistarts.
    pub seed: u64,
    /// Replace files at the report's paths that no report wrote (refused otherwise).
    pub force: bool,
    /// A directory of PEtab problems (a folder each) for the report's PEtab section; none:
    /// no section.
    pub petab: Option<PathBuf>,
    /// Starts of the default method's multistart on each PEtab problem (0: none).
    pub petab_starts: usize,
    /// Wall-clock seconds after which a PEtab problem's multistart begins no further start
    /// (the starts fitted are the first ones; the report says how many).
    pub petab_budget: f64,
    /// Wall-clock seconds after which one start of a PEtab multistart stops with its best
    /// point (termination `time_limit`, not converged); none: no limit. Default
    /// [`PETAB_START_SECONDS`].
    pub petab_start_seconds: Option<f64>,
    /// Most iterations of every fit of the catalogue's sections and of every profile point
    /// (default [`CATALOGUE_ITERATIONS`]); the PEtab section's fits have one fit's default
    /// budget ([`sysid_core::MAX_ITERATIONS`]) and its multistarts a start's
    /// ([`sysid_core::START_MAX_ITERATIONS`]).
    pub max_iterations: usize,
    /// The command that makes the report, as its README names it (`sysid report --out
    /// reports` by default): every number in it comes from that one command.
    pub command: String,
}

/// The catalogue sections' iteration budget, the one the report has always been drawn with
/// (the methods' default was 50 until it grew to 1 000 for the PEtab problems): the
/// catalogue's converging fits need fewer, and a fit that fails (a slow crawl, a profile
/// point that cannot be fitted) then costs a bounded time in every study trial, basin start
/// and profile point. At 1 000, van-der-pol-three-point's section took 17 minutes, most of it in
/// profile points that do not converge.
pub const CATALOGUE_ITERATIONS: usize = 50;

/// Wall-clock seconds after which one start of a PEtab problem's multistart stops with its
/// best point, by default: one problem's multistart then takes at most about its budget plus
/// this (two random starts of Raimundez_PCB2020 took 1 652 s without a limit).
pub const PETAB_START_SECONDS: f64 = 120.0;

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            out: PathBuf::from("reports"),
            systems: Vec::new(),
            methods: Role::Report.methods().into_iter().map(String::from).collect(),
            trials: 500,
            perturb: 0.3,
            grid: 25,
            basin_spread: 0.9,
            starts: 20,
            seed: 1,
            force: false,
            petab: None,
            petab_starts: 20,
            petab_budget: 120.0,
            petab_start_seconds: Some(PETAB_START_SECONDS),
            max_iterations: CATALOGUE_ITERATIONS,
            command: "sysid report --out reports".into(),
        }
    }
}

impl ReportOptions {
    /// Checks the options, named as `sysid report` spells them (a study's own check would
    /// name the basin spread `--perturb`, and run only after the studies before it).
    pub fn validate(&self) -> anyhow::Result<()> {
        sysid_registry::parse_list(&self.methods.join(","))?;
        if self.trials == 0 {
            anyhow::bail!("--trials must be at least 1");
        }
        if !(self.perturb >= 0.0 && self.perturb.is_finite()) {
            anyhow::bail!("--perturb must be non-negative, got {}", self.perturb);
        }
        if self.starts == 0 {
            anyhow::bail!("--starts must be at least 1");
        }
        // Checked here, before the catalogue's sections: the multistart's own check came
        // only when the PEtab section began, after minutes of them.
        if self.petab_starts == 0 {
            anyhow::bail!("--petab-starts must be at least 1");
        }
        if self.max_iterations == 0 {
            anyhow::bail!("--max-iterations must be at least 1");
        }
        if !(self.petab_budget > 0.0 && self.petab_budget <= 1e9) {
            anyhow::bail!(
                "--petab-budget must be a finite positive number of seconds, got {}",
                self.petab_budget
            );
        }
        if let Some(s) = self.petab_start_seconds.filter(|s| !(*s > 0.0 && *s <= 1e9)) {
            anyhow::bail!(
                "--petab-start-seconds must be a finite positive number of seconds (or 0: no limit), got {s}"
            );
        }
        if self.grid < 2 {
            anyhow::bail!("--grid must be at least 2, got {}", self.grid);
        }
        if !(self.basin_spread >= 0.0 && self.basin_spread.is_finite()) {
            anyhow::bail!("--basin-spread must be non-negative, got {}", self.basin_spread);
        }
        Ok(())
    }

    /// The registry's settings of the catalogue sections' fits: the default ones with
    /// [`max_iterations`](Self::max_iterations).
    pub fn settings(&self) -> Settings {
        let driver = DriverOptions { max_iterations: self.max_iterations, ..Default::default() };
        Settings { driver, ..Default::default() }
    }
}

/// Who watches a report being written: long studies and basin maps report their progress,
/// each finished system a line.
pub trait Observer: Sync {
    /// A task of `total` items begins (a study's trials, a basin map's starts).
    fn begin(&self, label: &str, total: u64);
    /// `done` of `total` items are done.
    fn advance(&self, done: u64, total: u64);
    /// The task has ended.
    fn end(&self);
    /// A line of news ("robertson: done in 19.7 s").
    fn note(&self, line: &str);
}

/// An observer that shows nothing.
pub struct Quiet;

impl Observer for Quiet {
    fn begin(&self, _: &str, _: u64) {}
    fn advance(&self, _: u64, _: u64) {}
    fn end(&self) {}
    fn note(&self, _: &str) {}
}
