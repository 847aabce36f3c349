//! The comparison report of the whole catalogue (`sysid report`), figures and data included.
//!
//! For every catalogue system: the methods compared (by default five) from the default start
//! (convergence), a Monte-Carlo study (accuracy against the Cramér–Rao bound, cost, success),
//! a basin map over the first two unknowns, and the fit with its prediction band. Everything
//! is written under `--out` (one directory per system, replaced on every run) with
//! `README.md` on top; every sentence of it is generated from the numbers next to it.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use sysid_core::{Estimate, Problem, Samples};
use sysid_montecarlo::files;
use sysid_montecarlo::multistart::Starts;
use sysid_montecarlo::{
    MultistartOptions, Scenario, Study, StudySpec, Summary, TrialRecord, basin,
};
use sysid_ode::System;
use sysid_registry::{Boxed, Registry, Settings};
use sysid_systems::{Case, Visit};

use crate::{
    Accuracy, Basin, BasinPanel, Cell, Convergence, Cost, CostBar, History, MethodMinima, Minima,
    Prediction, PredictionPanel, Spread, save,
};

/// What a report covers (the defaults are `sysid report`'s).
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// The report's directory: README.md and one directory per system. A report replaces
    /// the files an earlier report wrote there (listed in its `.sysid-report`) and no others.
    pub out: PathBuf,
    /// Catalogue systems (empty: all).
    pub systems: Vec<String>,
    /// The methods compared, comma-separated registry names.
    pub methods: String,
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
}

/// The methods a report compares by default.
pub const DEFAULT_METHODS: &str =
    "goodman,quasilinearization,gauss-newton-ls,levenberg-marquardt,multiple-shooting";

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            out: PathBuf::from("reports"),
            systems: Vec::new(),
            methods: DEFAULT_METHODS.into(),
            trials: 500,
            perturb: 0.3,
            grid: 25,
            basin_spread: 0.9,
            starts: 20,
            seed: 1,
            force: false,
        }
    }
}

impl ReportOptions {
    /// Checks the options, named as `sysid report` spells them (a study's own check would
    /// name the basin spread `--perturb`, and run only after the studies before it).
    pub fn validate(&self) -> anyhow::Result<()> {
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

/// The registry's method `name`, with the default settings.
fn method<S: System>(name: &str) -> anyhow::Result<Boxed<S>> {
    Ok(Registry::standard().build(name, &Settings::default())?)
}

/// The reference method: it decides success in the studies and draws the prediction.
const REFERENCE: &str = "goodman-halving";

/// Writes the report under `args.out` and returns the path of its README.md.
pub fn write_report(args: &ReportOptions, observer: &dyn Observer) -> anyhow::Result<PathBuf> {
    args.validate()?;
    let systems = if args.systems.is_empty() {
        sysid_systems::NAMES.iter().map(|s| s.to_string()).collect()
    } else {
        args.systems.clone()
    };
    for name in &systems {
        if !sysid_systems::NAMES.contains(&name.as_str()) {
            anyhow::bail!("unknown system `{name}` (systems: {})", sysid_systems::NAMES.join(", "));
        }
    }
    let methods = sysid_registry::parse_list(&args.methods)?;
    let manifest = Manifest::prepare(&args.out, &systems, args.force)?;
    let written = write_sections(args, &systems, &methods, observer);
    manifest.close()?;
    let path = written?;
    let seconds = manifest.started.elapsed().as_secs_f64();
    observer.note(&format!("report written to {} in {seconds:.0} s", path.display()));
    Ok(path)
}

fn write_sections(
    args: &ReportOptions,
    systems: &[String],
    methods: &[String],
    observer: &dyn Observer,
) -> anyhow::Result<PathBuf> {
    let started = Instant::now();
    let mut sections = Vec::new();
    for name in systems {
        let t = Instant::now();
        let report = SystemReport { args, methods, observer };
        let section = sysid_systems::visit(name, report).expect("a catalogue name")?;
        observer.note(&format!("{name}: done in {:.1} s", t.elapsed().as_secs_f64()));
        sections.push(section);
    }
    let readme = markdown(args, methods, &sections, started.elapsed().as_secs_f64());
    let path = args.out.join(README);
    write(&path, &readme)?;
    Ok(path)
}

/// The report's README, at the top of its directory.
const README: &str = "README.md";

/// `.sysid-report`: what reports wrote into their directory, a relative path a line. A report
/// removes and replaces these files and no others, so whatever else the directory holds is
/// never touched.
const MANIFEST: &str = ".sysid-report";

/// The files a report may write for one system, relative to the report's directory.
fn system_files(system: &str) -> Vec<String> {
    let figures = ["convergence", "minima", "prediction", "accuracy", "cost", "basin"];
    let mut paths: Vec<String> = figures
        .iter()
        .flat_map(|f| ["png", "svg"].map(|ext| format!("{system}/{f}.{ext}")))
        .collect();
    paths.extend(["convergence", "prediction", "data"].map(|f| format!("{system}/{f}.csv")));
    paths.push(format!("{system}/multistart.json"));
    for sub in ["study", "basin"] {
        paths.extend(files::OWNED.iter().map(|f| format!("{system}/{sub}/{f}")));
    }
    paths
}

/// The report directory's ledger of its own files, open while a report writes.
struct Manifest {
    out: PathBuf,
    /// What earlier reports wrote and this one does not replace.
    kept: std::collections::BTreeSet<String>,
    /// What this report may write.
    planned: Vec<String>,
    started: Instant,
}

impl Manifest {
    /// Checks that the report replaces only files a report wrote (or `force`), and removes
    /// those of the systems it is about to write, stale figures included.
    fn prepare(out: &Path, systems: &[String], force: bool) -> anyhow::Result<Self> {
        let path = out.join(MANIFEST);
        let earlier: std::collections::BTreeSet<String> = match std::fs::read_to_string(&path) {
            Ok(text) => text.lines().map(str::to_string).collect(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Default::default(),
            Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
        };
        let mut planned = vec![README.to_string()];
        planned.extend(systems.iter().flat_map(|s| system_files(s)));
        let foreign: Vec<&String> =
            planned.iter().filter(|f| out.join(f).exists() && !earlier.contains(*f)).collect();
        if !foreign.is_empty() && !force {
            let shown: Vec<&str> = foreign.iter().take(4).map(|f| f.as_str()).collect();
            let more = foreign.len().saturating_sub(shown.len());
            anyhow::bail!(
                "{} holds files that no report wrote at the report's paths ({}{}): choose \
                 another --out, or give --force to replace them",
                out.display(),
                shown.join(", "),
                if more > 0 { format!(" and {more} more") } else { String::new() }
            );
        }
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
        for f in &planned {
            match std::fs::remove_file(out.join(f)) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => {
                    return Err(e)
                        .with_context(|| format!("cannot replace {}", out.join(f).display()));
                }
            }
        }
        let kept = earlier.into_iter().filter(|f| !planned.contains(f)).collect();
        Ok(Self { out: out.into(), kept, planned, started: Instant::now() })
    }

    /// Records what the report wrote (also after a failure: what exists is the report's).
    fn close(&self) -> anyhow::Result<()> {
        let mut lines: Vec<&str> = self.kept.iter().map(String::as_str).collect();
        lines.extend(self.planned.iter().filter(|f| self.out.join(f).exists()).map(String::as_str));
        lines.sort_unstable();
        write(&self.out.join(MANIFEST), &(lines.join("\n") + "\n"))
    }
}

/// What the README says about one system.
struct Section {
    name: String,
    summary: String,
    unknowns: Vec<String>,
    truth: Vec<f64>,
    start: Vec<f64>,
    fits: Vec<(String, Result<Estimate, String>)>,
    multistart: Vec<(String, Result<Starts, String>)>,
    study: Result<Summary, String>,
    basin: Option<BasinNumbers>,
    figures: Vec<(String, String)>,
    seconds: f64,
}

struct BasinNumbers {
    axes: [String; 2],
    rates: Vec<(String, f64)>,
}

struct SystemReport<'a> {
    args: &'a ReportOptions,
    methods: &'a [String],
    observer: &'a dyn Observer,
}

impl Visit for SystemReport<'_> {
    type Output = anyhow::Result<Section>;

    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        let started = Instant::now();
        let args = self.args;
        let dir = args.out.join(case.name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let problem = case.problem(args.seed).with_context(|| format!("system {}", case.name))?;
        let mut figures = Vec::new();

        // Convergence from the default start.
        let mut fits = Vec::new();
        for m in self.methods {
            let fit = method::<S>(m)?.fit(&problem).map_err(|e| e.to_string());
            fits.push((m.clone(), fit));
        }
        write_convergence(&dir, &fits)?;
        let figure = Convergence {
            title: format!("{}: convergence from the default start", case.name),
            methods: fits
                .iter()
                .filter_map(|(m, f)| f.as_ref().ok().map(|e| history(m, e)))
                .collect(),
        };
        save(&figure, &dir.join("convergence"))?;
        figures.push((
            "convergence".into(),
            "Cost ε and step norm per iteration from the default start, same data.".into(),
        ));

        let multistart = self.multistart(case.name, &problem, &dir, &mut figures)?;

        // Fit and prediction, by the reference method.
        let fitted = method::<S>(REFERENCE)?.fit(&problem)?;
        if fitted.converged() {
            prediction(&case, &problem, &fitted, &dir)?;
            figures.push((
                "prediction".into(),
                format!(
                    "Data, the fit ({REFERENCE}) and its 95 % band from the linearised \
                     covariance, continued past the data by half their span."
                ),
            ));
        }

        // The study, and the basin map on its first trial's data.
        let truth = case.expected_values().unwrap_or_default();
        let (study, basin_numbers) = match Scenario::from_case(&case) {
            Ok(scenario) => {
                let (summary, numbers) = self.study(&case, scenario, &dir, &mut figures)?;
                (Ok(summary), Some(numbers))
            }
            Err(e) => (Err(e.to_string()), None),
        };

        Ok(Section {
            name: case.name.into(),
            summary: case.summary.into(),
            unknowns: problem.names(),
            truth,
            start: problem.guesses(),
            fits,
            multistart,
            study,
            basin: basin_numbers,
            figures,
            seconds: started.elapsed().as_secs_f64(),
        })
    }
}

impl SystemReport<'_> {
    /// Every method from `--starts` starts on the default data (written to
    /// `dir/multistart.json`, drawn as the minima figure); appends the figure's caption.
    fn multistart<S: System + Sync>(
        &self,
        system: &str,
        problem: &Problem<S>,
        dir: &Path,
        figures: &mut Vec<(String, String)>,
    ) -> anyhow::Result<Vec<(String, Result<Starts, String>)>> {
        let options =
            MultistartOptions { starts: self.args.starts, seed: self.args.seed, spread: 0.5 };
        let mut runs = Vec::new();
        for m in self.methods {
            let run = sysid_montecarlo::multistart(&*method::<S>(m)?, problem, &options);
            runs.push((m.clone(), run.map(|r| r.starts).map_err(|e| e.to_string())));
        }
        let json: Vec<serde_json::Value> = runs
            .iter()
            .map(|(m, run)| match run {
                Ok(s) => serde_json::json!({ "method": m, "starts": s }),
                Err(e) => serde_json::json!({ "method": m, "error": e }),
            })
            .collect();
        write(&dir.join("multistart.json"), &serde_json::to_string_pretty(&json)?)?;
        let figure = Minima {
            title: format!("{system}: minima from {} starts", options.starts),
            methods: runs
                .iter()
                .filter_map(|(m, run)| run.as_ref().ok().map(|s| (m, s)))
                .map(|(m, s)| MethodMinima {
                    method: m.clone(),
                    starts: s.count,
                    minima: s.minima.iter().map(|x| (x.cost, x.count)).collect(),
                })
                .collect(),
        };
        save(&figure, &dir.join("minima"))?;
        figures.push((
            "minima".into(),
            format!(
                "The distinct minima each method converged to from {} starts (the default \
                 start, then a Latin hypercube ±50 % around it); the dashed line is the least \
                 cost found.",
                options.starts
            ),
        ));
        Ok(runs)
    }

    /// The Monte-Carlo study of `case` (written under `dir/study`, drawn as accuracy and cost)
    /// and the basin map on its first trial's data; appends the figures' captions.
    fn study<S: System + Clone + Send + Sync + 'static>(
        &self,
        case: &Case<S>,
        scenario: Scenario<S>,
        dir: &Path,
        figures: &mut Vec<(String, String)>,
    ) -> anyhow::Result<(Summary, BasinNumbers)> {
        let args = self.args;
        let spec = StudySpec {
            system: case.name.to_string(),
            methods: self.methods.to_vec(),
            reference: REFERENCE.into(),
            trials: args.trials,
            noise: 1.0,
            perturb: args.perturb,
            seed: args.seed,
            fixed: Vec::new(),
            driver: Default::default(),
            settings: Default::default(),
        };
        let fits = self.methods.iter().map(|m| method::<S>(m)).collect::<anyhow::Result<_>>()?;
        let study = Study::new(spec, scenario, fits, method::<S>(REFERENCE)?)?;
        let summary = run_study(&study, &dir.join("study"), self.observer)?;
        draw_study(case, &summary, dir)?;
        figures.push((
            "accuracy".into(),
            format!(
                "Estimates over the successful trials of {} (box: quartiles, whiskers: \
                 2.5–97.5 %), the truth (dashed) and truth ± σ_CRB (grey).",
                summary.trials
            ),
        ));
        figures.push((
            "cost".into(),
            "Time per fit (median, 90th percentile) and success rate with its Wilson \
             95 % interval."
                .into(),
        ));
        let basin_spec =
            StudySpec { perturb: args.basin_spread, trials: 1, ..study.spec().clone() };
        let fits = self.methods.iter().map(|m| method::<S>(m)).collect::<anyhow::Result<_>>()?;
        let basin_study =
            Study::new(basin_spec, study.scenario().clone(), fits, method::<S>(REFERENCE)?)?;
        let numbers = draw_basin(case, &basin_study, args.grid, dir, self.observer)?;
        figures.push((
            "basin".into(),
            format!(
                "Starts on a {g} × {g} grid of {} and {} (the other unknowns at the \
                 truth), on the data of trial 0.",
                numbers.axes[0],
                numbers.axes[1],
                g = args.grid
            ),
        ));
        Ok((summary, numbers))
    }
}

fn history(method: &str, e: &Estimate) -> History {
    History {
        method: method.into(),
        // Multiple shooting evaluates ε only once its nodes match.
        costs: e
            .history
            .iter()
            .filter(|h| h.cost.is_finite())
            .map(|h| (h.iteration, h.cost))
            .collect(),
        steps: e.history.iter().filter_map(|h| h.step_norm.map(|s| (h.iteration, s))).collect(),
    }
}

fn write_convergence(
    dir: &Path,
    fits: &[(String, Result<Estimate, String>)],
) -> anyhow::Result<()> {
    let mut csv = String::from("method,iteration,cost,step_norm,gradient_norm,defect\n");
    // Empty where a method did not evaluate the quantity.
    let cell =
        |v: Option<f64>| v.filter(|v| v.is_finite()).map_or(String::new(), |v| format!("{v:e}"));
    for (m, fit) in fits {
        if let Ok(e) = fit {
            for h in &e.history {
                let (cost, step) = (cell(Some(h.cost)), cell(h.step_norm));
                let (gradient, defect) = (cell(Some(h.gradient_norm)), cell(h.defect));
                writeln!(csv, "{m},{},{cost},{step},{gradient},{defect}", h.iteration)?;
            }
        }
    }
    write(&dir.join("convergence.csv"), &csv)
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// The measured quantities, the fit and its band from the data's start to half a span past
/// their end.
fn prediction<S: System + Clone>(
    case: &Case<S>,
    problem: &Problem<S>,
    fitted: &Estimate,
    dir: &Path,
) -> anyhow::Result<()> {
    let (_, t_hi) = problem.span();
    let first = problem.sampled().times[0];
    // Data spread over two decades or more from a positive first time (robertson: 0.01 to
    // 100) are drawn on a log time axis from the first datum, continued half a decade;
    // otherwise linear from t0, continued half the span.
    let log_time =
        !problem.is_continuous() && first > 0.0 && problem.t0() >= 0.0 && t_hi >= 100.0 * first;
    let times: Vec<f64> = if log_time {
        let (a, b) = (first.log10(), t_hi.log10() + 0.5);
        (0..=400).map(|i| 10f64.powf(a + (b - a) * i as f64 / 400.0)).collect()
    } else {
        let t_lo = problem.span().0;
        let end = t_hi + 0.5 * (t_hi - t_lo);
        (0..=400).map(|i| t_lo + (end - t_lo) * i as f64 / 400.0).collect()
    };
    let t_lo = times[0];
    let observed = problem.observed(&fitted.values, fitted.band(), &times)?;
    let mut panels = Vec::new();
    let mut csv = String::from("t");
    for o in &observed {
        write!(csv, ",{n},{n}_lower,{n}_upper", n = o.name)?;
    }
    csv.push('\n');
    for (m, t) in times.iter().enumerate() {
        write!(csv, "{t}")?;
        for o in &observed {
            let y = o.values[m];
            match &o.half_width {
                Some(w) => write!(csv, ",{y},{},{}", y - w[m], y + w[m])?,
                None => write!(csv, ",{y},,")?,
            }
        }
        csv.push('\n');
    }
    write(&dir.join("prediction.csv"), &csv)?;
    let mut data_csv = String::from("series,t,value\n");
    for (series, o) in problem.data().series.iter().zip(&observed) {
        let data: Vec<(f64, f64)> = match &series.samples {
            Samples::Points { times, values } => {
                times.iter().copied().zip(values.iter().copied()).collect()
            }
            Samples::Function(f) => {
                times.iter().filter(|&&t| t >= t_lo && t <= t_hi).map(|&t| (t, f(t))).collect()
            }
        };
        for (t, v) in &data {
            writeln!(data_csv, "{},{t},{v}", series.name)?;
        }
        panels.push(PredictionPanel {
            name: o.name.clone(),
            data,
            curve: times
                .iter()
                .enumerate()
                .map(|(m, &t)| (t, o.values[m], o.half_width.as_ref().map(|w| w[m])))
                .collect(),
        });
    }
    write(&dir.join("data.csv"), &data_csv)?;
    let figure = Prediction {
        title: format!("{}: fit and prediction", case.name),
        time_label: match log_time {
            true => format!("t ({}, log scale)", case.time_unit),
            false => format!("t ({})", case.time_unit),
        },
        data_end: t_hi,
        log_time,
        panels,
    };
    save(&figure, &dir.join("prediction"))?;
    Ok(())
}

fn run_study<S: System + Clone + Send + Sync>(
    study: &Study<S>,
    dir: &Path,
    observer: &dyn Observer,
) -> anyhow::Result<Summary> {
    observer.begin(&format!("{} trials", study.spec().system), study.spec().trials as u64);
    let summary = files::run(
        study,
        dir,
        files::RunOptions { force: true, ..Default::default() },
        &|done, todo| observer.advance(done as u64, todo as u64),
    );
    observer.end();
    let summary = summary?;
    Ok(summary)
}

fn draw_study<S: System>(case: &Case<S>, summary: &Summary, dir: &Path) -> anyhow::Result<()> {
    let header = files::read_header(&dir.join("study").join("study.json"))?;
    let records = files::read_complete(&dir.join("study"), &header)?;
    let methods: Vec<String> = summary.spec.methods.clone();
    let successes = |m: &str| -> Vec<&TrialRecord> {
        records.iter().filter(|r| r.method == m && r.success == Some(true)).collect()
    };
    let unknowns = summary
        .unknowns
        .iter()
        .enumerate()
        .map(|(k, name)| Spread {
            name: name.clone(),
            truth: summary.truth[k],
            crb_sd: summary.crb_sd.get(k).copied().filter(|v| v.is_finite()),
            estimates: methods
                .iter()
                .map(|m| successes(m).iter().map(|r| r.values[k]).collect())
                .collect(),
        })
        .collect();
    let figure = Accuracy {
        title: format!(
            "{}: estimates over {} trials (noise 1σ, starts ±{:.0} %)",
            case.name,
            summary.trials,
            100.0 * summary.spec.perturb
        ),
        methods: methods.clone(),
        unknowns,
    };
    save(&figure, &dir.join("accuracy"))?;
    let bars = summary
        .methods
        .iter()
        .filter(|m| methods.contains(&m.method))
        .map(|m| CostBar {
            method: m.method.clone(),
            median_ms: m.time_ms.median.unwrap_or(f64::NAN),
            p90_ms: m.time_ms.p90.unwrap_or(f64::NAN),
            success: m.success_rate,
            interval: m.success_interval,
        })
        .collect();
    let figure = Cost { title: format!("{}: cost and success", case.name), methods: bars };
    save(&figure, &dir.join("cost"))?;
    Ok(())
}

fn draw_basin<S: System + Clone + Send + Sync>(
    case: &Case<S>,
    study: &Study<S>,
    grid: usize,
    dir: &Path,
    observer: &dyn Observer,
) -> anyhow::Result<BasinNumbers> {
    let total = (grid * grid) as u64;
    observer.begin(&format!("{} basin starts", case.name), total);
    let map = basin(study, (0, 1), grid, &|done, _| observer.advance(done as u64, total));
    observer.end();
    let map = map?;
    map.write(&dir.join("basin"), true)?;
    let truth = study.scenario().truth();
    let panels = map
        .maps
        .iter()
        .map(|m| BasinPanel {
            method: m.method.clone(),
            cells: (0..map.y.len())
                .map(|j| {
                    (0..map.x.len())
                        .map(|i| match (m.success[j][i], m.outcome[j][i].as_str()) {
                            (true, _) => Cell::Success(m.iterations[j][i]),
                            (false, "other_minimum") => Cell::OtherMinimum,
                            _ => Cell::Failure,
                        })
                        .collect()
                })
                .collect(),
        })
        .collect();
    let figure = Basin {
        title: format!("{}: basins of convergence", case.name),
        axes: map.axes.clone(),
        x: map.x.clone(),
        y: map.y.clone(),
        truth: (truth[0], truth[1]),
        panels,
    };
    save(&figure, &dir.join("basin"))?;
    Ok(BasinNumbers {
        axes: map.axes.clone(),
        rates: map.maps.iter().map(|m| (m.method.clone(), m.success_rate)).collect(),
    })
}

/// A number in four significant digits.
fn num(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-3..1e5).contains(&a) {
        let d = if a == 0.0 { 0 } else { (3 - a.log10().floor() as i32).max(0) as usize };
        format!("{v:.d$}")
    } else {
        format!("{v:.3e}")
    }
}

fn percent(v: f64) -> String {
    format!("{:.1} %", 100.0 * v)
}

fn markdown(
    args: &ReportOptions,
    methods: &[String],
    sections: &[Section],
    seconds: f64,
) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# sysid comparison report\n\n\
         Generated by `cargo run --release -- report --out reports` ({:.0} s on this machine). \
         Every number and figure below comes from that one command; the data behind each \
         figure are next to it (CSV and JSON), and nothing here is edited by hand.\n\n\
         Methods compared: {}. Each system's section shows\n\n\
         * **convergence** from the catalogue's default start on the default data (seed {}): \
         the cost ε = Σ w r² and the step norm per iteration;\n\
         * **multistart**: every method from {} starts on the same data, and the distinct \
         minima they reach;\n\
         * **accuracy** over a Monte-Carlo study of {} trials: each trial draws new noise \
         (1σ of the system) and a new start (each unknown at truth·(1 + ρu), u uniform on \
         [−1, 1], ρ = {}); a method succeeds when it converges to the cost of a reference fit \
         ({REFERENCE}) started from the truth on the same data, within 1e-6 relative. Estimates \
         of successful trials against the Cramér–Rao bound (σ_CRB from the Fisher information \
         at the truth); efficiency = σ_CRB² / observed variance;\n\
         * **basins**: a {g} × {g} grid of starts over the first two unknowns from \
         truth·(1 − {s}) to truth·(1 + {s}) (log-spaced for log-scale unknowns), the others at \
         the truth;\n\
         * **fit and prediction**: the data, the fitted model and its 95 % band from the \
         linearised covariance, continued past the data;\n\
         * **cost**: time per fit and success rate.\n",
        seconds,
        methods.join(", "),
        args.seed,
        args.starts,
        args.trials,
        args.perturb,
        g = args.grid,
        s = args.basin_spread,
    );
    // The overview.
    let _ = writeln!(md, "## Overview\n");
    let mut head = String::from("| system |");
    let mut rule = String::from("|---|");
    for m in methods {
        let _ = write!(head, " {m}: success | basin | median ms |");
        rule += "---|---|---|";
    }
    let _ = writeln!(md, "{head}\n{rule}");
    for s in sections {
        let mut row = format!("| [{}](#{}) |", s.name, s.name);
        for m in methods {
            let (rate, ms) = match &s.study {
                Ok(summary) => summary
                    .methods
                    .iter()
                    .find(|x| &x.method == m)
                    .map_or(("—".into(), "—".into()), |x| {
                        (percent(x.success_rate), x.time_ms.median.map_or("—".into(), num))
                    }),
                Err(_) => ("—".into(), "—".into()),
            };
            let basin = s
                .basin
                .as_ref()
                .and_then(|b| b.rates.iter().find(|(n, _)| n == m))
                .map_or("—".into(), |(_, r)| percent(*r));
            let _ = write!(row, " {rate} | {basin} | {ms} |");
        }
        let _ = writeln!(md, "{row}");
    }
    let _ = writeln!(
        md,
        "\nSuccess: share of the {} study trials that reach the reference minimum; basin: \
         share of the grid of starts that do; median ms: time per fit in the study, on one \
         core. A dash: no study (see the system's section).\n",
        args.trials
    );
    md += &crate::bench::section();
    for s in sections {
        md += &system_markdown(s);
    }
    md
}

fn system_markdown(s: &Section) -> String {
    let mut md = format!("\n## {}\n\n{}\n\n", s.name, s.summary);
    let _ = writeln!(md, "| unknown | truth | default start |\n|---|---|---|");
    for (k, name) in s.unknowns.iter().enumerate() {
        let truth = s.truth.get(k).map_or("—".into(), |v| num(*v));
        let _ = writeln!(md, "| {name} | {truth} | {} |", num(s.start[k]));
    }
    // From the default start.
    let _ = writeln!(md, "\n### From the default start\n");
    let _ =
        writeln!(md, "| method | converged | iterations | ε | time ms |\n|---|---|---|---|---|");
    for (m, fit) in &s.fits {
        match fit {
            Ok(e) => {
                let _ = writeln!(
                    md,
                    "| {m} | {} | {} | {} | {:.2} |",
                    if e.converged() {
                        "yes".to_string()
                    } else {
                        format!("no: {}", e.termination)
                    },
                    e.iterations,
                    num(e.cost),
                    e.elapsed.as_secs_f64() * 1e3
                );
            }
            Err(message) => {
                let _ = writeln!(md, "| {m} | error: {message} | | | |");
            }
        }
    }
    md += &default_start_paragraph(s);
    md += &multistart_table(s);
    for (file, caption) in &s.figures {
        let _ = writeln!(md, "\n![{file}]({}/{file}.png)\n\n*{caption}*", s.name);
    }
    match &s.study {
        Ok(summary) => {
            let _ = writeln!(md, "\n### Study\n");
            md += &study_paragraph(summary);
            let _ = writeln!(
                md,
                "\nThe full tables: [{n}/study/summary.md]({n}/study/summary.md); every trial: \
                 `{n}/study/trials.jsonl`.",
                n = s.name
            );
            md += &table_of(summary);
        }
        Err(why) => {
            let _ = writeln!(md, "\nNo Monte-Carlo study for this system: {why}.");
        }
    }
    if let Some(b) = &s.basin {
        let rates: Vec<String> =
            b.rates.iter().map(|(m, r)| format!("{m} {}", percent(*r))).collect();
        let _ = writeln!(
            md,
            "\n**Basins.** Over the grid of starts in {} and {}, the share that reaches the \
             reference minimum: {}. The map: `{}/basin/basin.json`.",
            b.axes[0],
            b.axes[1],
            rates.join(", "),
            s.name
        );
    }
    let _ = writeln!(md, "\n*This section took {:.1} s to compute.*", s.seconds);
    md
}

fn multistart_table(s: &Section) -> String {
    let Some(count) = s.multistart.iter().find_map(|(_, r)| r.as_ref().ok().map(|x| x.count))
    else {
        return String::new();
    };
    let mut md = format!(
        "\n### Multistart\n\nEach method from {count} starts on the same data: the default \
         start, then a Latin hypercube ±50 % around it (`--starts {count}`). Reached best: \
         starts whose fit converged to the least cost that method found (within 1e-6 \
         relative).\n\n| method | converged | reached best | distinct minima | best ε | wall ms |\n\
         |---|---|---|---|---|---|\n"
    );
    for (m, run) in &s.multistart {
        match run {
            Ok(x) => {
                let best = x.minima.first().map_or("—".into(), |b| num(b.cost));
                let _ = writeln!(
                    md,
                    "| {m} | {} | {} | {} | {best} | {:.1} |",
                    x.converged,
                    x.reached_best,
                    x.minima.len(),
                    x.elapsed_ms
                );
            }
            Err(e) => {
                let _ = writeln!(md, "| {m} | error: {e} | | | | |");
            }
        }
    }
    md
}

fn default_start_paragraph(s: &Section) -> String {
    let converged: Vec<&Estimate> =
        s.fits.iter().filter_map(|(_, f)| f.as_ref().ok()).filter(|e| e.converged()).collect();
    let failed: Vec<String> = s
        .fits
        .iter()
        .filter_map(|(m, f)| match f {
            Ok(e) if e.converged() => None,
            Ok(e) => Some(format!("{m} does not converge ({})", e.termination)),
            Err(message) => Some(format!("{m} stops with an error ({message})")),
        })
        .collect();
    let mut p = String::new();
    if let Some(best) = converged.iter().map(|e| e.cost).reduce(f64::min) {
        let same: Vec<&str> = converged
            .iter()
            .filter(|e| (e.cost - best).abs() <= 1e-6 * best.abs() + 1e-12)
            .map(|e| e.method.as_str())
            .collect();
        let _ = write!(
            p,
            "\nFrom the default start, {} reach{} the lowest cost found, ε = {}",
            same.join(", "),
            if same.len() == 1 { "es" } else { "" },
            num(best)
        );
        let fewest = converged.iter().min_by_key(|e| e.iterations).expect("one converged");
        let _ = write!(p, "; the fewest iterations: {} ({}).", fewest.method, fewest.iterations);
        let elsewhere: Vec<String> = converged
            .iter()
            .filter(|e| (e.cost - best).abs() > 1e-6 * best.abs() + 1e-12)
            .map(|e| format!("{} (ε = {})", e.method, num(e.cost)))
            .collect();
        if !elsewhere.is_empty() {
            let _ = write!(p, " Converged to a higher minimum: {}.", elsewhere.join(", "));
        }
    }
    if !failed.is_empty() {
        let _ = write!(p, " {}.", failed.join("; "));
    }
    p.push('\n');
    p
}

fn study_paragraph(summary: &Summary) -> String {
    let methods: Vec<_> =
        summary.methods.iter().filter(|m| summary.spec.methods.contains(&m.method)).collect();
    let mut p = format!(
        "Over {} trials (noise 1σ, starts within ±{:.0} %), the methods reach the reference \
         minimum in ",
        summary.trials,
        100.0 * summary.spec.perturb
    );
    let rates: Vec<String> = methods
        .iter()
        .map(|m| {
            let failures: Vec<String> = m
                .outcomes
                .iter()
                .filter(|c| c.outcome != "success")
                .map(|c| format!("{} {}", c.outcome.replace('_', " "), c.count))
                .collect();
            if failures.is_empty() {
                format!("{} of the trials ({})", percent(m.success_rate), m.method)
            } else {
                format!(
                    "{} ({}; failures: {})",
                    percent(m.success_rate),
                    m.method,
                    failures.join(", ")
                )
            }
        })
        .collect();
    p += &rates.join(", ");
    p += ".";
    // Accuracy: efficiency and coverage over methods and unknowns.
    let eff: Vec<f64> =
        methods.iter().flat_map(|m| m.accuracy.iter().filter_map(|a| a.efficiency)).collect();
    let cov: Vec<f64> =
        methods.iter().flat_map(|m| m.accuracy.iter().filter_map(|a| a.coverage)).collect();
    if let (Some(lo), Some(hi)) =
        (eff.iter().copied().reduce(f64::min), eff.iter().copied().reduce(f64::max))
    {
        let _ = write!(
            p,
            " On the successful trials the efficiency (σ_CRB² / variance; 1 = the Cramér–Rao \
             bound) lies between {} and {} over methods and unknowns",
            num(lo),
            num(hi)
        );
        if let (Some(c_lo), Some(c_hi)) =
            (cov.iter().copied().reduce(f64::min), cov.iter().copied().reduce(f64::max))
        {
            let _ = write!(
                p,
                ", and each fit's own 95 % interval (Student's t, N − k degrees of freedom) covers the truth in {} to {} of them",
                percent(c_lo),
                percent(c_hi)
            );
        }
        p += ".";
    }
    // Same minimum, same estimates?
    let sds: Vec<Vec<Option<f64>>> =
        methods.iter().map(|m| m.accuracy.iter().map(|a| a.sd).collect()).collect();
    let identical = methods.iter().all(|m| m.successes == methods[0].successes)
        && sds.iter().all(|s| {
            s.iter().zip(&sds[0]).all(|(a, b)| match (a, b) {
                (Some(a), Some(b)) => (a - b).abs() <= 1e-6 * b.abs(),
                _ => a.is_none() && b.is_none(),
            })
        });
    if identical && methods.len() > 1 {
        p += " All methods succeed on the same trials and give the same estimates there (they \
              reach the same minimum), so their accuracy is the data's, not the method's.";
    }
    // Cost.
    let times: Vec<(&str, f64)> =
        methods.iter().filter_map(|m| m.time_ms.median.map(|t| (m.method.as_str(), t))).collect();
    if let (Some(fast), Some(slow)) = (
        times.iter().min_by(|a, b| a.1.total_cmp(&b.1)),
        times.iter().max_by(|a, b| a.1.total_cmp(&b.1)),
    ) && fast.0 != slow.0
    {
        let _ = write!(
            p,
            " The fastest fit is {} (median {} ms); the slowest {} ({} ms, {:.1}× longer).",
            fast.0,
            num(fast.1),
            slow.0,
            num(slow.1),
            slow.1 / fast.1
        );
    }
    p.push('\n');
    p
}

/// The study's per-method table and the accuracy of the first method per unknown.
fn table_of(summary: &Summary) -> String {
    let mut md = String::from(
        "\n| method | success | 95 % interval | iterations median / 90 % | ms median / 90 % |\n\
         |---|---|---|---|---|\n",
    );
    let opt = |v: Option<f64>| v.map_or("—".into(), num);
    for m in &summary.methods {
        let _ = writeln!(
            md,
            "| {} | {}/{} | {}–{} | {} / {} | {} / {} |",
            m.method,
            m.successes,
            m.trials,
            percent(m.success_interval[0]),
            percent(m.success_interval[1]),
            opt(m.iterations.median),
            opt(m.iterations.p90),
            opt(m.time_ms.median),
            opt(m.time_ms.p90)
        );
    }
    let _ = writeln!(
        md,
        "\n| method | unknown | bias | sd | σ_CRB | efficiency | coverage |\n|---|---|---|---|---|---|---|"
    );
    for m in summary.methods.iter().filter(|m| summary.spec.methods.contains(&m.method)) {
        for a in &m.accuracy {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} |",
                m.method,
                a.name,
                opt(a.bias),
                opt(a.sd),
                num(a.crb_sd),
                opt(a.efficiency),
                a.coverage.map_or("—".into(), percent)
            );
        }
    }
    md
}
