//! `sysid report`: the command line of the comparison report; the report itself is written
//! by [`sysid_report::write_report`].

use std::path::PathBuf;
use std::sync::Mutex;

use clap::Args;
use indicatif::ProgressBar;
use sysid_report::{Observer, ReportOptions, ScalingOptions, write_report, write_scaling};

use crate::Outcome;
use crate::output::progress_bar;

/// Arguments of `sysid report`.
#[derive(Args, Debug)]
pub struct ReportArgs {
    /// The report's directory: README.md and one directory per system (replaced).
    #[arg(long, default_value = "reports", value_name = "DIR")]
    out: PathBuf,
    /// Comma-separated catalogue systems (default: all).
    #[arg(long, value_name = "A,B")]
    systems: Option<String>,
    #[arg(long, value_name = "A,B", help = methods_help())]
    methods: Option<String>,
    /// Trials of each system's study.
    #[arg(long, default_value_t = 500, value_name = "N", value_parser = crate::options::count, allow_hyphen_values = true)]
    trials: usize,
    /// Start perturbation ρ of the studies (see `sysid study --help`).
    #[arg(long, default_value_t = 0.3, value_name = "RHO", value_parser = crate::options::number, allow_hyphen_values = true)]
    perturb: f64,
    /// Points per axis of the basin maps.
    #[arg(long, default_value_t = 25, value_name = "G", value_parser = crate::options::count, allow_hyphen_values = true)]
    grid: usize,
    /// Spread of the basin maps: starts from truth·(1 − s) to truth·(1 + s), and from
    /// truth/(1 + s) to truth·(1 + s) for a log-scale unknown.
    #[arg(long, default_value_t = 0.9, value_name = "S", value_parser = crate::options::number, allow_hyphen_values = true)]
    basin_spread: f64,
    /// Starts of each method's multistart on the default data.
    #[arg(long, default_value_t = 20, value_name = "N", value_parser = crate::options::count, allow_hyphen_values = true)]
    starts: usize,
    /// Seed of the data, the trials, the default-start fits and the multistarts.
    #[arg(long, default_value_t = 1, value_parser = crate::options::seed, allow_hyphen_values = true)]
    seed: u64,
    /// Replace files at the report's paths that no report wrote. Without it such files are
    /// refused; the files an earlier report wrote (listed in OUT/.sysid-report) are always
    /// replaced, and nothing else in OUT is touched.
    #[arg(long)]
    force: bool,
    /// A directory of PEtab problems, a folder each, for the report's PEtab section (the NLL
    /// at nominal against `references.tsv` there, and fits from nominal); skipped when the
    /// directory does not exist.
    #[arg(long, default_value = "tests/data/petab", value_name = "DIR")]
    petab: PathBuf,
    /// Starts of the default method's multistart on each PEtab problem, drawn uniformly on
    /// each unknown's scale within its bounds (or from its initialization prior); 0: none.
    #[arg(long, default_value_t = 20, value_name = "N", value_parser = crate::options::count, allow_hyphen_values = true)]
    petab_starts: usize,
    /// Wall-clock seconds after which a PEtab problem's multistart begins no further start
    /// (the first starts are the ones fitted; the report gives how many).
    #[arg(long, default_value_t = 120.0, value_name = "SECONDS", value_parser = crate::options::number, allow_hyphen_values = true)]
    petab_budget: f64,
    /// Wall-clock seconds after which one start of a PEtab problem's multistart stops with
    /// its best point (termination `time_limit`, not converged), so that one problem's
    /// multistart takes at most about --petab-budget plus this; 0: no limit (a start begun
    /// runs to its end: two random starts of Raimundez_PCB2020 took 1 652 s).
    #[arg(long, default_value_t = sysid_report::PETAB_START_SECONDS, value_name = "SECONDS", value_parser = crate::options::number, allow_hyphen_values = true)]
    petab_start_seconds: f64,
    /// Most iterations of every fit in the catalogue's sections (studies, basin maps,
    /// multistarts, profiles) and of every PEtab profile point; the PEtab section's fits have
    /// one fit's default budget (3000), its multistarts a start's (1000).
    #[arg(long, default_value_t = sysid_report::CATALOGUE_ITERATIONS, value_name = "N", value_parser = crate::options::count, allow_hyphen_values = true)]
    max_iterations: usize,
    /// Instead of the report: time one NLL + gradient at nominal of every PEtab problem in
    /// DIR (a folder each: `<name>/<name>.yaml`, `problem.yaml` or its only YAML file) on one thread, the gradient by the counted
    /// choice between forward and adjoint sensitivities (`--sensitivities auto`), and draw the times against states ×
    /// parameters on log–log axes with the least-squares power law, into OUT/scaling
    /// (README.md with the table, scaling.png and .svg, scaling.csv).
    #[arg(long, value_name = "DIR")]
    pub scaling: Option<PathBuf>,
    /// With --scaling: timed evaluations per problem, at most (the median is reported).
    #[arg(long, default_value_t = 5, value_name = "N", value_parser = crate::options::count, allow_hyphen_values = true)]
    scaling_repeat: usize,
    /// With --scaling: seconds of timed evaluations after which a problem is evaluated no
    /// more (it is always evaluated once, after the untimed evaluation that makes the
    /// choice).
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS", value_parser = crate::options::number, allow_hyphen_values = true)]
    scaling_seconds: f64,
}

/// The help of `--methods`: the registry's report methods.
fn methods_help() -> String {
    let methods = sysid_registry::Role::Report.methods().join(", ");
    format!("Comma-separated methods compared (default: {methods}).")
}

/// Runs `sysid report`.
pub fn run(args: &ReportArgs) -> anyhow::Result<Outcome> {
    if let Some(dir) = &args.scaling {
        if args.scaling_repeat == 0 {
            anyhow::bail!("--scaling-repeat 0: at least one timed evaluation");
        }
        if !(args.scaling_seconds >= 0.0 && args.scaling_seconds.is_finite()) {
            anyhow::bail!("--scaling-seconds {}: a number of seconds ≥ 0", args.scaling_seconds);
        }
        if !dir.is_dir() {
            anyhow::bail!("--scaling {}: not a directory of PEtab problems", dir.display());
        }
        let out = args.out.join("scaling");
        if out.canonicalize().ok() == dir.canonicalize().ok() {
            anyhow::bail!(
                "--out {}: the figure would be written into {}, where it reads the problems (--scaling): choose another --out",
                args.out.display(),
                dir.display()
            );
        }
        let options = ScalingOptions {
            dir: dir.clone(),
            out,
            repeat: args.scaling_repeat,
            seconds: args.scaling_seconds,
            force: args.force,
        };
        let path = write_scaling(&options, &Bars::default())?;
        eprintln!("written to {}", path.display());
        return Ok(Outcome::Success);
    }
    let systems = match &args.systems {
        Some(list) => {
            list.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect()
        }
        None => Vec::new(),
    };
    for name in &systems {
        if !sysid_systems::NAMES.contains(&name.as_str()) {
            anyhow::bail!("unknown system `{name}` (systems: {})", sysid_systems::NAMES.join(", "));
        }
    }
    let methods = match &args.methods {
        Some(list) => sysid_registry::parse_list(list)?,
        None => ReportOptions::default().methods,
    };
    // The report writes README.md in --out and a folder per PEtab problem in --out/petab:
    // neither may be where it reads the PEtab problems from.
    if args.petab.is_dir() {
        for written in [args.out.clone(), args.out.join("petab")] {
            if written.canonicalize().ok() == args.petab.canonicalize().ok() {
                anyhow::bail!(
                    "--out {}: the report would write into {}, where it reads the PEtab problems (--petab): choose another --out",
                    args.out.display(),
                    args.petab.display()
                );
            }
        }
    }
    let options = ReportOptions {
        out: args.out.clone(),
        systems,
        methods,
        trials: args.trials,
        perturb: args.perturb,
        grid: args.grid,
        basin_spread: args.basin_spread,
        starts: args.starts,
        seed: args.seed,
        force: args.force,
        petab: args.petab.is_dir().then(|| args.petab.clone()),
        petab_starts: args.petab_starts,
        petab_budget: args.petab_budget,
        petab_start_seconds: (args.petab_start_seconds != 0.0).then_some(args.petab_start_seconds),
        max_iterations: args.max_iterations,
        command: command_line(),
    };
    write_report(&options, &Bars::default())?;
    Ok(Outcome::Success)
}

/// The command as it was run, `sysid report …`, each argument quoted for a shell where it
/// needs to be, for the report's README to name.
fn command_line() -> String {
    let quoted = |a: String| {
        let plain = !a.is_empty()
            && a.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
        match plain {
            true => a,
            false => format!("'{}'", a.replace('\'', r"'\''")),
        }
    };
    std::iter::once("sysid".to_string())
        .chain(std::env::args().skip(1).map(quoted))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Progress bars on stderr for the report's studies and basin maps.
#[derive(Default)]
struct Bars(Mutex<Option<ProgressBar>>);

impl Observer for Bars {
    fn begin(&self, label: &str, total: u64) {
        *self.0.lock().expect("the bar's lock") = Some(progress_bar(total, label));
    }
    fn advance(&self, done: u64, total: u64) {
        if let Some(bar) = self.0.lock().expect("the bar's lock").as_ref() {
            bar.set_length(total);
            bar.set_position(done);
        }
    }
    fn end(&self) {
        if let Some(bar) = self.0.lock().expect("the bar's lock").take() {
            bar.finish_and_clear();
        }
    }
    fn note(&self, line: &str) {
        eprintln!("{line}");
    }
}
