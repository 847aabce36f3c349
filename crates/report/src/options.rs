//! What a report covers, and who watches it being written.

use std::path::PathBuf;

use sysid_registry::Role;

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
    /// Spread of the basin maps: starts from truth·(1 − s) to truth·(1 + s).
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
}

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
        if self.grid < 2 {
            anyhow::bail!("--grid must be at least 2, got {}", self.grid);
        }
        if !(self.basin_spread >= 0.0 && self.basin_spread.is_finite()) {
            anyhow::bail!("--basin-spread must be non-negative, got {}", self.basin_spread);
        }
        Ok(())
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
