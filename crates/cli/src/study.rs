//! `sysid study` and `sysid merge`: Monte-Carlo robustness studies.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use anyhow::{Context as _, anyhow, bail};
use clap::Args;
use sysid_core::Termination;
use sysid_montecarlo::files::{self, RunOptions, Shard};
use sysid_montecarlo::{Scenario, Study, StudyError, StudySpec, basin};
use sysid_registry::Role;

use crate::Outcome;
use crate::options::{IntegratorArgs, MethodArgs, SourceArgs};
use crate::output::{Watch, emit, not_an_input, progress_bar};
use crate::problem::{blame, case, fit, method, no_source, prepare, watching};
use sysid_registry::any::{AnySystem, model_problem};

/// The help of `--methods`: the registry's study methods.
fn methods_help() -> String {
    format!("Comma-separated methods (default: {}).", Role::Study.methods().join(", "))
}

/// Arguments of `sysid study`.
#[derive(Args, Debug)]
pub struct StudyArgs {
    /// A catalogue system, or a model file: then the truth is its fit to its data, and the
    /// noise what that fit leaves.
    #[command(flatten)]
    source: SourceArgs,
    #[arg(long, value_name = "A,B,C", help = methods_help())]
    methods: Option<String>,
    /// The method of the reference fit from the truth that decides success.
    #[arg(long, default_value = Role::Reference.method(), value_name = "METHOD")]
    reference: String,
    /// Number of trials.
    #[arg(long, default_value_t = 100, value_name = "N", value_parser = crate::options::count, allow_hyphen_values = true)]
    trials: usize,
    /// Noise level, a multiple of the system's σ.
    #[arg(long, default_value_t = 1.0, value_name = "K", value_parser = crate::options::number, allow_hyphen_values = true)]
    noise: f64,
    /// Start perturbation ρ: each unknown starts at truth·(1 + ρu), u uniform on [−1, 1]
    /// (truth·(1 + ρ)^u on a log scale, truth + ρu for a truth of 0).
    #[arg(long, default_value_t = 0.2, value_name = "RHO", value_parser = crate::options::number, allow_hyphen_values = true)]
    perturb: f64,
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
    /// Points per axis of the basin map.
    #[arg(
        long,
        default_value_t = 41,
        value_name = "G",
        requires = "basin",
        value_parser = crate::options::count, allow_hyphen_values = true
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

/// The study's specification from its options.
fn spec(
    args: &StudyArgs,
    system: &str,
    methods: Vec<String>,
    settings: BTreeMap<String, String>,
) -> StudySpec {
    StudySpec {
        system: system.to_string(),
        methods,
        reference: args.reference.clone(),
        trials: args.trials,
        noise: args.noise,
        perturb: args.perturb,
        seed: args.source.seed,
        fixed: args.options.fix.clone(),
        driver: args.options.settings().driver,
        settings,
    }
}

/// Runs `sysid study`.
pub fn run(args: &StudyArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.integrator.validate()?;
    if let Some((name, _)) = args.options.start.first() {
        bail!(
            "--start {name}=… is for one fit (fit, compare, profile, predict): a study draws each trial's start itself (--perturb)"
        );
    }
    let methods = match &args.methods {
        Some(list) => sysid_registry::parse_list(list)?,
        None => Role::Study.methods().into_iter().map(String::from).collect(),
    };
    // One method listed twice under two names is refused; the names stay as given, as
    // study.json records them (with `settings.ql_start`), so that a study's shards and
    // resumed runs compare equal.
    crate::problem::as_run(&methods, &args.options.settings())?;
    crate::options::one_method(&args.reference, "--reference")?;
    // The numbers checked before any work: a model file's reference fit comes first and can
    // take minutes (`--trials 0` on Fujita was refused only after it).
    spec(args, "", methods.clone(), BTreeMap::new()).validate()?;
    if args.basin.is_some() && (args.shard.is_some() || args.resume) {
        bail!("a basin map runs in one go: --shard and --resume are for trials");
    }
    if args.basin.is_some() {
        // Before the reference fit too (a model file's can take minutes).
        sysid_montecarlo::Basin::check_dir(&args.out, args.force)?;
    }
    match (&args.source.system, args.source.file()) {
        (Some(name), _) => {
            let settings = method_settings(args);
            let mut case = case(name)?;
            case.integrator = args.integrator.apply_to(case.integrator)?;
            let scenario = Scenario::from_case(&case)
                .and_then(|s| s.with_fixed(&args.options.fix))
                .with_context(|| format!("system {}", case.name))?;
            run_scenario(args, case.name, scenario, methods, settings)
        }
        (None, Some(path)) => {
            let model = args.source.load(path)?;
            let inputs: Vec<PathBuf> =
                model.inputs().into_iter().chain(args.source.data.clone()).collect();
            for name in files::OWNED {
                not_an_input(&args.out.join(name), &inputs, "--out")?;
            }
            let mut settings = method_settings(args);
            // A PEtab problem's SBML and tables are in the model it was imported as and the
            // data tables it holds in memory.
            let held = |e: &sysid_model::ExperimentSpec| {
                model.file.tables.iter().find(|t| t.0 == e.file).map(|t| format!("{:?}", t.1))
            };
            settings.insert(
                "model".into(),
                match args.source.petab {
                    Some(_) => sha256_of(model.file.text.as_bytes()),
                    None => sha256(path)?,
                },
            );
            if model.file.experiments.is_empty() {
                let data = match &args.source.data {
                    Some(data) => data.clone(),
                    None => model.data_path()?.to_path_buf(),
                };
                settings.insert("data".into(), sha256(&data)?);
            }
            for e in &model.file.experiments {
                let digest = match held(e) {
                    Some(table) => sha256_of(table.as_bytes()),
                    None => sha256(&e.file)?,
                };
                settings.insert(format!("data of {}", e.name), digest);
            }
            let problem = prepare(
                model_problem(model.problem(args.source.data.as_deref())?),
                &args.integrator,
                &args.options,
            )?;
            // The truth of a model file: its fit to its own data, which on a real problem
            // can take as long as the trials.
            let watch = Rc::new(Watch::new(
                format!("{} {} (the reference fit)", path.display(), args.reference),
                args.options.log_every,
            ));
            let fitted =
                watching(&watch, || fit(&problem, &args.reference, &args.options.settings()))
                    .map_err(|e| blame(&path.display().to_string(), e))?;
            if fitted.termination == Termination::Interrupted {
                return Ok(stopped(&format!(
                    "stopped during the fit to {}'s data that gives the study its truth: no trial was run",
                    path.display()
                )));
            }
            if !fitted.converged() {
                bail!(
                    "{}: the fit to the data that gives the study its truth did not converge ({})",
                    path.display(),
                    fitted.termination
                );
            }
            // The noise scales at the values the fit estimated them at.
            let scales: Vec<f64> = fitted.scales.iter().map(|s| s.value).collect();
            let problem = problem.with_scales(&scales);
            let scenario = Scenario::from_residuals(problem, fitted.values)
                .map_err(|e| blame(&path.display().to_string(), e.into()))?;
            run_scenario(args, &path.display().to_string(), scenario, methods, settings)
        }
        (None, None) => Err(no_source()),
    }
}

/// The method options beyond the driver's that change results, for study.json.
fn method_settings(args: &StudyArgs) -> BTreeMap<String, String> {
    let ql_start = format!("{:?}", args.options.ql_start).to_lowercase();
    let intervals = args.options.shooting_intervals.map_or("data".to_string(), |m| m.to_string());
    BTreeMap::from([
        ("build".to_string(), this_build()),
        ("ql_start".to_string(), ql_start),
        ("shooting_intervals".to_string(), intervals),
    ])
}

/// The build running the study: its version and the SHA-256 of its executable, so that
/// `--resume` and `merge` refuse to mix two builds' trials (another build may integrate with
/// other steps, and its counts and last digits differ). Read once per study.
fn this_build() -> String {
    let version = env!("CARGO_PKG_VERSION");
    // The running image (/proc/self/exe, readable where the file itself is execute-only),
    // else the file at the executable's path.
    let read = std::fs::read("/proc/self/exe")
        .or_else(|_| std::env::current_exe().and_then(std::fs::read));
    match read {
        Ok(bytes) => format!("sysid {version}, executable {}", sha256_of(&bytes)),
        // Unreadable: its size and time tell builds apart where its bytes cannot.
        Err(e) => {
            let meta = std::env::current_exe().and_then(std::fs::metadata);
            let stamp = meta.map_or(String::new(), |m| {
                let modified =
                    m.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
                format!(", {} bytes, modified {}", m.len(), modified.map_or(0, |d| d.as_secs()))
            });
            format!("sysid {version}, executable not read ({e}){stamp}")
        }
    }
}

/// "sha256:…" of a file's contents.
fn sha256(path: &Path) -> anyhow::Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(sha256_of(&bytes))
}

fn sha256_of(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    let digest = Sha256::digest(bytes);
    format!("sha256:{}", digest.iter().map(|b| format!("{b:02x}")).collect::<String>())
}

fn run_scenario(
    args: &StudyArgs,
    system: &str,
    scenario: Scenario<AnySystem>,
    methods: Vec<String>,
    settings: BTreeMap<String, String>,
) -> anyhow::Result<Outcome> {
    let method_settings = args.options.settings();
    let spec = spec(args, system, methods.clone(), settings);
    let build = |m: &str| method(m, &method_settings);
    let fits = methods.iter().map(|m| build(m)).collect::<anyhow::Result<Vec<_>>>()?;
    let study = Study::new(spec, scenario, fits, build(&args.reference)?)
        .map_err(|e| blame(system, e.into()))?;
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
        let (a, b) = axes
            .split_once(',')
            .filter(|(_, b)| !b.contains(','))
            .ok_or_else(|| anyhow!("--basin takes two unknowns, U1,U2: got `{axes}`"))?;
        let total = args.grid.saturating_mul(args.grid);
        let bar = progress_bar(total as u64, "starts");
        let log = Watch::new(format!("{system} basin"), args.options.log_every);
        let map = basin(&study, (index(a)?, index(b)?), args.grid, &|done, _| {
            bar.set_position(done as u64);
            if done < total {
                log.log(&format!("{done}/{total} starts done"));
            }
        });
        bar.finish_and_clear();
        let map = match map {
            Err(StudyError::Interrupted(message)) => return Ok(stopped(&message)),
            map => map?,
        };
        map.write(&args.out, args.force)?;
        emit(&map.markdown())?;
        return Ok(Outcome::Success);
    }
    let total = study.spec().trials;
    let bar = progress_bar(total as u64, "trials");
    let label = match args.shard {
        Some(s) => format!("{system} shard {}/{}", s.index, s.count),
        None => system.to_string(),
    };
    let log = Watch::new(label, args.options.log_every);
    let options = RunOptions { shard: args.shard, resume: args.resume, force: args.force };
    let summary = files::run(&study, &args.out, options, &|done, todo| {
        bar.set_length(todo as u64);
        bar.set_position(done as u64);
        if done > 0 && done < todo {
            log.log(&format!("{done}/{todo} trials done"));
        }
    });
    bar.finish_and_clear();
    let summary = match summary {
        Err(StudyError::Interrupted(message)) => {
            return Ok(stopped(&format!("{message}: the same command with --resume runs them")));
        }
        summary => summary?,
    };
    emit(&summary.markdown())?;
    eprintln!("{}: {} trials written to {}", system, summary.trials, args.out.display());
    Ok(Outcome::Success)
}

/// A study or basin map that Ctrl-C or SIGTERM stopped: what was kept, on stderr (nothing on
/// stdout: there is no summary).
fn stopped(message: &str) -> Outcome {
    eprintln!("{message}");
    Outcome::NotConverged
}

/// Runs `sysid merge`.
pub fn merge(args: &MergeArgs) -> anyhow::Result<Outcome> {
    let Some(out) = &args.out else { return check(&args.shards) };
    let summary = files::merge(&args.shards, out, args.force)?;
    emit(&summary.markdown())?;
    eprintln!(
        "{} shard{} merged into {} ({} trials)",
        args.shards.len(),
        if args.shards.len() == 1 { "" } else { "s" },
        out.display(),
        summary.trials
    );
    Ok(Outcome::Success)
}

/// `sysid merge --check`: exit 0 when every shard of the study is complete, 1 when not.
fn check(dirs: &[PathBuf]) -> anyhow::Result<Outcome> {
    let (text, complete) = files::check(dirs)?;
    emit(&text)?;
    Ok(if complete { Outcome::Success } else { Outcome::NotConverged })
}
