//! Running the catalogue for the report: for every system, the methods from the default
//! start, a multistart, a Monte-Carlo study, a basin map and the fit with its prediction band,
//! each written as data (CSV, JSON) and drawn as figures; then the README.

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
use sysid_registry::{Boxed, Registry, Role};
use sysid_systems::{Case, Visit};

use crate::accuracy::{Accuracy, Spread};
use crate::basin::{Basin, BasinPanel, Cell};
use crate::chart::save;
use crate::convergence::{Convergence, History};
use crate::cost::{Cost, CostBar};
use crate::manifest::{Manifest, README, write};
use crate::markdown::{BasinNumbers, Section, markdown};
use crate::minima::{MethodMinima, Minima};
use crate::options::{Observer, ReportOptions};
use crate::prediction::{Prediction, PredictionPanel};
use crate::profiles::write_profiles;

/// The registry's method `name`, with the catalogue sections' settings.
fn method<S: System>(name: &str, args: &ReportOptions) -> anyhow::Result<Boxed<S>> {
    Ok(Registry::standard().build(name, &args.settings())?)
}

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
    let methods = &args.methods;
    let petab = args.petab.as_deref().map(crate::petab::problems).unwrap_or_default();
    let manifest = Manifest::prepare(&args.out, &systems, &petab, args.force)?;
    let written = write_sections(args, &systems, methods, observer);
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
        // As `AnySystem`, so that the report's methods, studies and figures are compiled once
        // rather than once per catalogue system (the crate built in half the time).
        let case = sysid_registry::any::case(name).expect("a catalogue name");
        let section = report.visit(case)?;
        observer.note(&format!("{name}: done in {:.1} s", t.elapsed().as_secs_f64()));
        sections.push(section);
        stop_here(&format!("at system {} of {} ({name})", sections.len(), systems.len()))?;
    }
    let petab = match &args.petab {
        Some(dir) => {
            let t = Instant::now();
            let multistart = sysid_montecarlo::MultistartOptions {
                starts: args.petab_starts,
                seed: args.seed,
                sampling: sysid_montecarlo::Sampling::Uniform,
                guess: false,
                budget: Some(std::time::Duration::from_secs_f64(args.petab_budget)),
                ..Default::default()
            };
            let starts =
                crate::petab::Starting { options: &multistart, seconds: args.petab_start_seconds };
            let md = crate::petab::section(dir, &args.out, &starts, &args.settings(), observer)?;
            observer.note(&format!("PEtab problems: done in {:.1} s", t.elapsed().as_secs_f64()));
            stop_here("in the PEtab problems")?;
            md
        }
        None => String::new(),
    };
    let readme = markdown(args, methods, &sections, started.elapsed().as_secs_f64()) + &petab;
    let path = args.out.join(README);
    write(&path, &readme)?;
    Ok(path)
}

/// An error where the caller stopped the run ([`sysid_core::observer::stop_when`]; Ctrl-C in
/// the command line): what the sections wrote stays, README.md is not written.
fn stop_here(when: &str) -> anyhow::Result<()> {
    if sysid_core::observer::stop_requested() {
        anyhow::bail!(
            "stopped {when}: README.md is not written (the figures and data written so far stay)"
        );
    }
    Ok(())
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
            let fit = method::<S>(m, args)?.fit(&problem).map_err(|e| e.to_string());
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
        let fitted = method::<S>(Role::Reference.method(), args)?.fit(&problem)?;
        if fitted.converged() {
            prediction(&case, &problem, &fitted, &dir)?;
            figures.push((
                "prediction".into(),
                format!(
                    "Data, the fit ({}) and its 95 % band from the linearised covariance, \
                     continued past the data by half their span.",
                    Role::Reference.method()
                ),
            ));
        }

        // Profile likelihoods around the reference fit.
        if fitted.converged() {
            self.profiles(case.name, &problem, &fitted, &dir, &mut figures)?;
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
        // The report's figures were drawn from Latin-hypercube starts (the sampling before the
        // field's uniform one became the default); they stay comparable run to run.
        let options = MultistartOptions {
            starts: self.args.starts,
            seed: self.args.seed,
            sampling: sysid_montecarlo::Sampling::LatinHypercube,
            ..Default::default()
        };
        let mut runs = Vec::new();
        for m in self.methods {
            let run = sysid_montecarlo::multistart(&*method::<S>(m, self.args)?, problem, &options);
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

    /// The profile likelihood of every unknown around the reference method's fit `optimum`,
    /// re-optimised by that method (written to `dir/profiles.json`, drawn as the profiles
    /// figure); appends the figure's caption. A profile that finds a lower point than the
    /// fit says so in the caption instead of being drawn from the wrong optimum.
    fn profiles<S: System + Sync>(
        &self,
        system: &str,
        problem: &Problem<S>,
        optimum: &Estimate,
        dir: &Path,
        figures: &mut Vec<(String, String)>,
    ) -> anyhow::Result<()> {
        let reference = Role::Reference.method();
        if let Some(caption) =
            write_profiles(system, problem, optimum, dir, reference, &self.args.settings())?
        {
            figures.push(("profiles".into(), caption));
        }
        Ok(())
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
            reference: Role::Reference.method().into(),
            trials: args.trials,
            noise: 1.0,
            perturb: args.perturb,
            seed: args.seed,
            fixed: Vec::new(),
            driver: args.settings().driver,
            settings: Default::default(),
        };
        let fits =
            self.methods.iter().map(|m| method::<S>(m, args)).collect::<anyhow::Result<_>>()?;
        let study = Study::new(spec, scenario, fits, method::<S>(Role::Reference.method(), args)?)?;
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
        let fits =
            self.methods.iter().map(|m| method::<S>(m, args)).collect::<anyhow::Result<_>>()?;
        let basin_study = Study::new(
            basin_spec,
            study.scenario().clone(),
            fits,
            method::<S>(Role::Reference.method(), args)?,
        )?;
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
    let estimates: Vec<&Estimate> = fits.iter().filter_map(|(_, f)| f.as_ref().ok()).collect();
    // A column for every diagnostic a method attached (multiple shooting's defect, ...).
    let mut diagnostics: Vec<&str> = Vec::new();
    for (name, _) in estimates.iter().flat_map(|e| &e.history).flat_map(|h| h.diagnostics.iter()) {
        if !diagnostics.contains(&name) {
            diagnostics.push(name);
        }
    }
    let mut csv = String::from("method,iteration,cost,step_norm,gradient_norm");
    for name in &diagnostics {
        write!(csv, ",{name}")?;
    }
    csv.push('\n');
    // Empty where a method did not evaluate the quantity.
    let cell =
        |v: Option<f64>| v.filter(|v| v.is_finite()).map_or(String::new(), |v| format!("{v:e}"));
    for e in estimates {
        for h in &e.history {
            let (cost, step) = (cell(Some(h.cost)), cell(h.step_norm));
            write!(
                csv,
                "{},{},{cost},{step},{}",
                e.method,
                h.iteration,
                cell(Some(h.gradient_norm))
            )?;
            for name in &diagnostics {
                write!(csv, ",{}", cell(h.diagnostic(name)))?;
            }
            csv.push('\n');
        }
    }
    write(&dir.join("convergence.csv"), &csv)
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
