//! `sysid study` and `sysid merge`: Monte-Carlo robustness studies.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sysid_model::Model;
use sysid_montecarlo::files::{self, RunOptions, Shard};
use sysid_montecarlo::{Scenario, Study, StudySpec, basin};
use sysid_ode::System;
use sysid_systems::{Case, Visit};

use crate::Outcome;
use crate::fit::{fit, prepare};
use crate::integrator::IntegratorArgs;
use crate::methods::{MethodArgs, method, parse_list};

/// The methods a study compares unless told otherwise: the three classical ones.
const DEFAULT_METHODS: &str = "goodman,quasilinearization,gauss-newton-ls";

/// Arguments of `sysid study`.
#[derive(Args, Debug)]
pub struct StudyArgs {
    /// A catalogue system (`sysid systems` lists them).
    #[arg(long, value_name = "NAME", required_unless_present = "model", conflicts_with = "model")]
    system: Option<String>,
    /// A model file: the truth is its fit to its data, the noise what the fit leaves.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// The data file for --model (default: the model's `[data] file`).
    #[arg(long, value_name = "CSV", requires = "model", conflicts_with = "system")]
    data: Option<PathBuf>,
    /// Comma-separated methods (default: goodman, quasilinearization, gauss-newton-ls).
    #[arg(long, value_name = "A,B,C")]
    methods: Option<String>,
    /// The method of the reference fit from the truth that decides success.
    #[arg(long, default_value = "goodman-halving", value_name = "METHOD")]
    reference: String,
    /// Number of trials.
    #[arg(long, default_value_t = 100, value_name = "N", allow_negative_numbers = true)]
    trials: usize,
    /// Noise level, a multiple of the system's σ.
    #[arg(long, default_value_t = 1.0, value_name = "K", allow_negative_numbers = true)]
    noise: f64,
    /// Start perturbation ρ: each unknown starts at truth·(1 + ρu), u uniform on [−1, 1]
    /// (truth·(1 + ρ)^u on a log scale, truth + ρu for a truth of 0).
    #[arg(long, default_value_t = 0.2, value_name = "RHO", allow_negative_numbers = true)]
    perturb: f64,
    /// Seed: trial i draws from the random stream i of this seed.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    seed: u64,
    /// The study's directory: trials.jsonl, summary.json, summary.md (basin.json, basin.md).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Run only part i of n of the trials (1 ≤ i ≤ n); `sysid merge` combines the parts.
    #[arg(long, value_name = "I/N", allow_hyphen_values = true)]
    shard: Option<Shard>,
    /// Continue a study that was interrupted, keeping its finished trials (or start it, if
    /// --out holds none yet: batch jobs can always pass --resume). Every setting that
    /// changes results (methods, options, integrator, the model and data files' contents)
    /// must be the one the study was started with.
    #[arg(long)]
    resume: bool,
    /// Write into an --out that holds files sysid did not write. sysid still writes only
    /// its own files (study.json, trials.jsonl, summary.json, summary.md, basin.json,
    /// basin.md, .sysid.lock), replacing any of those names it finds, and leaves the rest.
    #[arg(long)]
    force: bool,
    /// Instead of trials: a basin map over a grid of starts for these two unknowns (the
    /// others at the truth), spread by --perturb.
    #[arg(long, value_name = "U1,U2")]
    basin: Option<String>,
    /// When stderr is not a terminal (a batch job's log), print a plain line with the
    /// count of trials done every this many seconds (0: never).
    #[arg(long, default_value_t = 60.0, value_name = "SECONDS", allow_negative_numbers = true)]
    log_every: f64,
    /// Points per axis of the basin map.
    #[arg(
        long,
        default_value_t = 41,
        value_name = "G",
        requires = "basin",
        allow_negative_numbers = true
    )]
    grid: usize,
    #[command(flatten)]
    options: MethodArgs,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// Arguments of `sysid merge`.
#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The shard directories of one study.
    #[arg(required = true, value_name = "DIR")]
    shards: Vec<PathBuf>,
    /// The merged study's directory: new, empty, or holding this same merge (merging again
    /// rewrites the same files).
    #[arg(long, value_name = "DIR", required_unless_present = "check")]
    out: Option<PathBuf>,
    /// Only tell how many trials each shard has done (from its files, while it runs too):
    /// exit 0 when every shard of the study is complete, 1 when not.
    #[arg(long, conflicts_with = "out")]
    check: bool,
    /// Write into an --out that holds files sysid did not write (see `sysid study --help`).
    #[arg(long)]
    force: bool,
}

/// Runs `sysid study`.
pub fn run(args: &StudyArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    if !(args.log_every >= 0.0 && args.log_every.is_finite()) {
        bail!(
            "--log-every must be a non-negative number of seconds (0: never), got {}",
            args.log_every
        );
    }
    let methods = parse_list(args.methods.as_deref().unwrap_or(DEFAULT_METHODS))?;
    parse_list(&args.reference)?;
    if args.basin.is_some() && (args.shard.is_some() || args.resume) {
        bail!("a basin map runs in one go: --shard and --resume are for trials");
    }
    match (&args.system, &args.model) {
        (Some(name), _) => {
            let settings = method_settings(args);
            sysid_systems::visit(name, FromCase { args, methods, settings }).ok_or_else(|| {
                anyhow!("unknown system `{name}` (systems: {})", sysid_systems::NAMES.join(", "))
            })?
        }
        (None, Some(path)) => {
            let model = Model::load(path)?;
            let data = match &args.data {
                Some(data) => data.clone(),
                None => model.data_path()?.to_path_buf(),
            };
            let mut settings = method_settings(args);
            settings.insert("model".into(), sha256(path)?);
            settings.insert("data".into(), sha256(&data)?);
            let problem =
                prepare(model.problem(args.data.as_deref())?, &args.integrator, &args.options)?;
            // The truth of a model file: its fit to its own data.
            let fitted = fit(&problem, &args.reference, args.options.common())?;
            if !fitted.converged() {
                bail!(
                    "{}: the fit to the data that gives the study its truth did not converge ({})",
                    path.display(),
                    fitted.termination
                );
            }
            let scenario = Scenario::from_residuals(problem, fitted.values)?;
            run_scenario(args, &path.display().to_string(), scenario, methods, settings)
        }
        (None, None) => bail!("give --system NAME or --model FILE"),
    }
}

struct FromCase<'a> {
    args: &'a StudyArgs,
    methods: Vec<String>,
    settings: BTreeMap<String, String>,
}

/// The method options beyond the driver's that change results, for study.json.
fn method_settings(args: &StudyArgs) -> BTreeMap<String, String> {
    let ql_start = format!("{:?}", args.options.ql_start).to_lowercase();
    let intervals = args.options.shooting_intervals.map_or("data".to_string(), |m| m.to_string());
    BTreeMap::from([
        ("ql_start".to_string(), ql_start),
        ("shooting_intervals".to_string(), intervals),
    ])
}

/// "sha256:…" of a file's contents.
fn sha256(path: &Path) -> anyhow::Result<String> {
    use sha2::{Digest, Sha256};
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let digest = Sha256::digest(&bytes);
    Ok(format!("sha256:{}", digest.iter().map(|b| format!("{b:02x}")).collect::<String>()))
}

impl Visit for FromCase<'_> {
    type Output = anyhow::Result<Outcome>;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, mut case: Case<S>) -> Self::Output {
        case.integrator = self.args.integrator.apply_to(case.integrator)?;
        let scenario = Scenario::from_case(&case)
            .and_then(|s| s.with_fixed(&self.args.options.fix))
            .with_context(|| format!("system {}", case.name))?;
        run_scenario(self.args, case.name, scenario, self.methods, self.settings)
    }
}

fn run_scenario<S: System + Clone + Send + Sync + 'static>(
    args: &StudyArgs,
    system: &str,
    scenario: Scenario<S>,
    methods: Vec<String>,
    settings: BTreeMap<String, String>,
) -> anyhow::Result<Outcome> {
    let common = args.options.common();
    let spec = StudySpec {
        system: system.to_string(),
        methods: methods.clone(),
        reference: args.reference.clone(),
        trials: args.trials,
        noise: args.noise,
        perturb: args.perturb,
        seed: args.seed,
        fixed: args.options.fix.clone(),
        driver: common.driver,
        settings,
    };
    let fits =
        methods.iter().map(|m| method::<S>(m, &common)).collect::<anyhow::Result<Vec<_>>>()?;
    let study = Study::new(spec, scenario, fits, method::<S>(&args.reference, &common)?)?;
    if let Some(axes) = &args.basin {
        let names = study.scenario().problem().names();
        let index = |n: &str| {
            names.iter().position(|x| x == n.trim()).ok_or_else(|| {
                anyhow!(
                    "--basin: `{}` is not an unknown (unknowns: {})",
                    n.trim(),
                    names.join(", ")
                )
            })
        };
        let (a, b) =
            axes.split_once(',').ok_or_else(|| anyhow!("--basin takes two unknowns, U1,U2"))?;
        let bar = progress_bar((args.grid * args.grid) as u64, "starts");
        let map = basin(&study, (index(a)?, index(b)?), args.grid, &|done, _| {
            bar.set_position(done as u64)
        })?;
        bar.finish_and_clear();
        map.write(&args.out, args.force)?;
        crate::emit(&map.markdown())?;
        return Ok(Outcome::Success);
    }
    let total = study.spec().trials;
    let bar = progress_bar(total as u64, "trials");
    let label = match args.shard {
        Some(s) => format!("{system} shard {}/{}", s.index, s.count),
        None => system.to_string(),
    };
    let log = LogLines::new(label, args.log_every);
    let options = RunOptions { shard: args.shard, resume: args.resume, force: args.force };
    let summary = files::run(&study, &args.out, options, &|done, todo| {
        bar.set_length(todo as u64);
        bar.set_position(done as u64);
        log.tick(done, todo);
    })?;
    bar.finish_and_clear();
    crate::emit(&summary.markdown())?;
    eprintln!("{}: {} trials written to {}", system, summary.trials, args.out.display());
    Ok(Outcome::Success)
}

/// Plain progress lines on stderr for batch logs, where the progress bar is hidden: one
/// every `every` seconds while trials run.
struct LogLines {
    label: String,
    every: Option<std::time::Duration>,
    started: std::time::Instant,
    last: std::sync::Mutex<std::time::Instant>,
}

impl LogLines {
    fn new(label: String, every: f64) -> Self {
        use std::io::IsTerminal;
        let on = every > 0.0 && !std::io::stderr().is_terminal();
        let now = std::time::Instant::now();
        let every = on.then(|| std::time::Duration::from_secs_f64(every));
        Self { label, every, started: now, last: std::sync::Mutex::new(now) }
    }

    fn tick(&self, done: usize, todo: usize) {
        let Some(every) = self.every else { return };
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if done > 0 && done < todo && last.elapsed() >= every {
            *last = std::time::Instant::now();
            let secs = self.started.elapsed().as_secs_f64();
            eprintln!("{}: {done}/{todo} trials done, {secs:.0} s", self.label);
        }
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub(crate) fn progress_bar(total: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    let template = format!("{{bar:40}} {{pos}}/{{len}} {unit}, {{per_sec}}, {{eta}} left");
    bar.set_style(ProgressStyle::with_template(&template).expect("a valid template"));
    bar
}

/// Runs `sysid merge`.
pub fn merge(args: &MergeArgs) -> anyhow::Result<Outcome> {
    let Some(out) = &args.out else { return check(&args.shards) };
    let summary = files::merge(&args.shards, out, args.force)?;
    crate::emit(&summary.markdown())?;
    eprintln!(
        "{} shards merged into {} ({} trials)",
        args.shards.len(),
        out.display(),
        summary.trials
    );
    Ok(Outcome::Success)
}

/// `sysid merge --check`: a line per shard, the shards not given, and a last line
/// `incomplete: 3,7` (shard indices) or `complete`.
fn check(dirs: &[PathBuf]) -> anyhow::Result<Outcome> {
    let shards = files::progress(dirs)?;
    let mut text = String::new();
    let mut incomplete = std::collections::BTreeSet::new();
    for s in &shards {
        text += &format!(
            "{:<12} {}/{} trials  {}\n",
            files::shard_name(s.shard),
            s.done,
            s.expected,
            s.dir.display()
        );
        if s.done < s.expected {
            incomplete.insert(s.shard.map_or(1, |s| s.index));
        }
    }
    for index in files::missing_shards(shards.iter().map(|s| s.shard)) {
        let count = shards[0].shard.map_or(1, |s| s.count);
        text += &format!("{:<12} no directory given\n", format!("{index}/{count}"));
        incomplete.insert(index);
    }
    if incomplete.is_empty() {
        text += "complete\n";
        crate::emit(&text)?;
        return Ok(Outcome::Success);
    }
    let list: Vec<String> = incomplete.iter().map(usize::to_string).collect();
    text += &format!("incomplete: {}\n", list.join(","));
    crate::emit(&text)?;
    Ok(Outcome::NotConverged)
}
