//! The PEtab section: every problem of a directory of PEtab problems (tests/data/petab)
//! imported, its NLL at the nominal parameters beside the stored reference
//! (`references.tsv`), fits from nominal by the default method and by
//! Levenberg–Marquardt (the NLL they end at, their iterations and time, certified or not),
//! and a multistart of the default method as the field runs one (starts drawn uniformly on
//! each unknown's scale within its bounds, or from its initialization prior): the best
//! objective beside the best known one (`best_known.tsv`), how many starts reached it, the
//! time per start, and the waterfall figure.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use serde_json::json;
use sysid_montecarlo::MultistartOptions;
use sysid_ode::System as _;
use sysid_registry::{Registry, Role, Settings};

use crate::options::Observer;

/// The methods the section fits with: the command line's default, and the one that does
/// best on these problems.
fn methods() -> [&'static str; 2] {
    [Role::Default.method(), "levenberg-marquardt"]
}

/// One fit from nominal.
struct Fit {
    method: String,
    nll: Option<f64>,
    /// The priors' negative log-density at the fit's point (None without priors): the fit
    /// minimises `nll + prior`.
    prior: Option<f64>,
    iterations: usize,
    seconds: f64,
    certified: bool,
    termination: String,
}

/// One problem: what importing it and fitting it gave.
struct Row {
    problem: String,
    reference: Option<f64>,
    /// The least objective known (`best_known.tsv`).
    best_known: Option<f64>,
    outcome: Result<Numbers, String>,
}

struct Numbers {
    /// The caption of its profiles figure, where they were traced.
    profiles: Option<String>,
    /// The multistart, where one was asked for.
    starts: Option<Starts>,
    states: usize,
    unknowns: usize,
    experiments: usize,
    import_ms: f64,
    nominal: f64,
    /// The priors' negative log-density at nominal (None without priors).
    nominal_prior: Option<f64>,
    fits: Vec<Fit>,
}

impl Numbers {
    /// The objective at nominal: the NLL plus the priors' term.
    fn nominal_objective(&self) -> f64 {
        self.nominal + self.nominal_prior.unwrap_or(0.0)
    }
}

impl Fit {
    /// The objective the fit ends at: the NLL plus the priors' term.
    fn objective(&self) -> Option<f64> {
        self.nll.map(|n| n + self.prior.unwrap_or(0.0))
    }
}

/// A multistart of the default method on one problem.
struct Starts {
    /// The starts fitted.
    count: usize,
    /// The starts drawn and left out because the time budget ran out.
    not_started: usize,
    /// The least objective (NLL plus the priors' term) any start ended at.
    best: Option<f64>,
    converged: usize,
    /// Converged starts whose objective is within [`REACHED`] of the best known one (of
    /// the best found, where none is known or the best found is lower).
    reached: usize,
    /// The median wall time of one start (the starts run two at a time on two cores).
    median_seconds: f64,
    seconds: f64,
    converged_per_minute: f64,
}

/// How the section's multistarts run: the options, and the wall-clock limit of one start.
pub(crate) struct Starting<'a> {
    pub(crate) options: &'a MultistartOptions,
    pub(crate) seconds: Option<f64>,
}

/// The field's tolerance for a start that found the optimum (pyPESTO, Fröhlich & Sorger
/// 2022): within 0.1 of the best objective.
const REACHED: f64 = sysid_montecarlo::REACHED;

/// The values of a `problem<TAB>value…` table in `dir`: problem → value.
fn table(dir: &Path, file: &str) -> Vec<(String, f64)> {
    let Ok(text) = std::fs::read_to_string(dir.join(file)) else {
        return Vec::new();
    };
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let mut cells = l.split('\t');
            let name = cells.next()?.trim().to_string();
            let nll = cells.next()?.trim().parse().ok()?;
            Some((name, nll))
        })
        .collect()
}

/// The most free unknowns a problem's profiles are traced for (each profile point is a fit
/// of the others; beyond this the section would take hours).
const PROFILED_UNKNOWNS: usize = 15;

/// The problems of a directory of PEtab problems: its folders, sorted.
pub(crate) fn problems(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .filter(|e| e.path().is_dir())
                .map(|e| e.file_name().to_string_lossy().to_string())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

/// A problem folder's PEtab YAML: `<name>.yaml`, else `problem.yaml` (as some problems of
/// the collection name it), else the folder's only `.yaml` file; `<name>.yaml` when none is
/// found, so that the import names the file it looked for.
pub(crate) fn problem_yaml(dir: &Path, name: &str) -> std::path::PathBuf {
    let folder = dir.join(name);
    let own = folder.join(format!("{name}.yaml"));
    if own.is_file() {
        return own;
    }
    if folder.join("problem.yaml").is_file() {
        return folder.join("problem.yaml");
    }
    let yamls: Vec<std::path::PathBuf> = std::fs::read_dir(&folder)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "yaml" || e == "yml"))
                .collect()
        })
        .unwrap_or_default();
    match yamls.as_slice() {
        [only] => only.clone(),
        _ => own,
    }
}

/// Imports, evaluates and fits one problem; traces its profiles (into `out`) where the
/// Levenberg–Marquardt fit certifies and it has at most [`PROFILED_UNKNOWNS`] free unknowns.
fn numbers(
    yaml: &Path,
    out: &Path,
    multistart: &Starting<'_>,
    profile_settings: &Settings,
    best_known: Option<f64>,
    observer: &dyn Observer,
) -> Result<Numbers, String> {
    let started = Instant::now();
    let imported = sysid_petab::import(yaml).map_err(|e| e.to_string())?;
    let problem = imported.model.problem(None).map_err(|e| e.to_string())?;
    let import_ms = started.elapsed().as_secs_f64() * 1e3;
    let z = problem.unknowns().coordinates(&problem.guesses());
    // Where the sensitivities cannot be integrated at nominal (a switch on a state), the
    // model alone may be: its NLL, and the fits say why they cannot start.
    let nominal = match problem.linearize(&z) {
        Ok(lin) => problem.nll(&lin),
        Err(_) => problem.nll_at(&z).map_err(|e| e.to_string())?,
    };
    let nominal = nominal.ok_or("no likelihood")?;
    let nominal_prior = problem.prior_nll_at(&z);
    let mut fits = Vec::new();
    let mut profiles = None;
    for m in methods() {
        let method =
            Registry::standard().build(m, &Settings::default()).map_err(|e| e.to_string())?;
        let t = Instant::now();
        let fit = method.fit(&problem).map_err(|e| e.to_string())?;
        let seconds = t.elapsed().as_secs_f64();
        fits.push(Fit {
            method: m.to_string(),
            nll: fit.nll,
            prior: fit.prior,
            iterations: fit.iterations,
            seconds,
            certified: fit.converged(),
            termination: fit.termination.to_string(),
        });
        observer.note(&format!("{}: {m} in {seconds:.1} s", yaml.display()));
        if m == "levenberg-marquardt"
            && fit.converged()
            && problem.names().len() <= PROFILED_UNKNOWNS
        {
            let t = Instant::now();
            std::fs::create_dir_all(out).map_err(|e| e.to_string())?;
            let name = yaml.file_stem().map_or(String::new(), |s| s.to_string_lossy().to_string());
            profiles =
                crate::profiles::write_profiles(&name, &problem, &fit, out, m, profile_settings)
                    .map_err(|e| format!("profiles: {e}"))?;
            observer.note(&format!(
                "{}: profiles in {:.1} s",
                yaml.display(),
                t.elapsed().as_secs_f64()
            ));
        }
    }
    let starts = match multistart.options.starts {
        0 => None,
        _ => Some(starts(&problem, yaml, out, multistart, best_known, observer)?),
    };
    Ok(Numbers {
        profiles,
        starts,
        states: problem.experiments()[0].system().signature().n_states(),
        unknowns: problem.names().len(),
        experiments: problem.experiments().len(),
        import_ms,
        nominal,
        nominal_prior,
        fits,
    })
}

/// The least of the starts' objectives (`(objective, converged)` each), and how many
/// converged within [`REACHED`] of the best known objective, or of the best found where that
/// is lower or none is known.
fn reached(objectives: &[(f64, bool)], best_known: Option<f64>) -> (Option<f64>, usize) {
    let best = objectives.iter().map(|o| o.0).filter(|v| v.is_finite()).min_by(f64::total_cmp);
    let target = match (best, best_known) {
        (Some(b), Some(k)) => b.min(k),
        (b, k) => b.or(k).unwrap_or(f64::NAN),
    };
    (best, objectives.iter().filter(|o| o.1 && o.0 <= target + REACHED).count())
}

/// The default method's multistart on `problem`, its waterfall drawn into `out`.
fn starts<S: sysid_ode::System + Sync>(
    problem: &sysid_core::Problem<S>,
    yaml: &Path,
    out: &Path,
    starting: &Starting<'_>,
    best_known: Option<f64>,
    observer: &dyn Observer,
) -> Result<Starts, String> {
    let name = Role::Default.method();
    let options = starting.options;
    let mut settings = Settings::default();
    settings.driver.max_iterations = sysid_core::START_MAX_ITERATIONS;
    settings.driver.max_seconds = starting.seconds;
    let method = Registry::standard().build(name, &settings).map_err(|e| e.to_string())?;
    let run = sysid_montecarlo::multistart(method.as_ref(), problem, options)
        .map_err(|e| e.to_string())?;
    let s = &run.starts;
    let objectives: Vec<(f64, bool)> =
        s.waterfall.iter().filter_map(|o| o.objective.map(|v| (v, o.converged))).collect();
    let (best, reached) = reached(&objectives, best_known);
    let mut times: Vec<f64> = s.waterfall.iter().map(|o| o.elapsed_ms / 1e3).collect();
    times.sort_by(f64::total_cmp);
    let median_seconds = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    std::fs::create_dir_all(out).map_err(|e| e.to_string())?;
    let problem_name = yaml.file_stem().map_or(String::new(), |s| s.to_string_lossy().to_string());
    let figure = crate::Waterfall::of_starts(&problem_name, s.count, name, objectives);
    crate::save(&figure, &out.join("waterfall")).map_err(|e| format!("waterfall: {e}"))?;
    observer.note(&format!(
        "{}: {} starts ({} left out by the time budget) in {:.1} s, {} converged, {reached} reached the best",
        yaml.display(),
        s.count,
        s.not_started,
        s.elapsed_ms / 1e3,
        s.converged
    ));
    Ok(Starts {
        count: s.count,
        not_started: s.not_started,
        best,
        converged: s.converged,
        reached,
        median_seconds,
        seconds: s.elapsed_ms / 1e3,
        converged_per_minute: s.converged_per_minute,
    })
}

/// The problems of `dir` (a folder each, with its YAML of the same name), their numbers
/// written to `out/petab/petab.json`; the section's Markdown.
pub(crate) fn section(
    dir: &Path,
    out: &Path,
    multistart: &Starting<'_>,
    profile_settings: &Settings,
    observer: &dyn Observer,
) -> anyhow::Result<String> {
    let references = table(dir, "references.tsv");
    let known = table(dir, "best_known.tsv");
    let mut rows = Vec::new();
    for name in problems(dir) {
        let yaml = problem_yaml(dir, &name);
        let best_known = known.iter().find(|r| r.0 == name).map(|r| r.1);
        let outcome = numbers(
            &yaml,
            &out.join("petab").join(&name),
            multistart,
            profile_settings,
            best_known,
            observer,
        );
        let reference = references.iter().find(|r| r.0 == name).map(|r| r.1);
        rows.push(Row { problem: name, reference, best_known, outcome });
    }
    let json: Vec<serde_json::Value> = rows.iter().map(row_json).collect();
    std::fs::create_dir_all(out.join("petab"))?;
    crate::manifest::write(
        &out.join("petab/petab.json"),
        &serde_json::to_string_pretty(&json).expect("JSON"),
    )?;
    Ok(markdown(dir, &rows, multistart, profile_settings))
}

fn row_json(r: &Row) -> serde_json::Value {
    match &r.outcome {
        Ok(n) => json!({
            "problem": r.problem,
            "reference_nll": r.reference,
            "nll_at_nominal": n.nominal,
            "prior_at_nominal": n.nominal_prior,
            "objective_at_nominal": n.nominal_objective(),
            "states": n.states,
            "unknowns": n.unknowns,
            "experiments": n.experiments,
            "import_ms": n.import_ms,
            "best_known": r.best_known,
            "starts": n.starts.as_ref().map(|s| json!({
                "count": s.count,
                "not_started": s.not_started,
                "best": s.best,
                "converged": s.converged,
                "reached_best_known": s.reached,
                "median_seconds": s.median_seconds,
                "seconds": s.seconds,
                "converged_per_minute": s.converged_per_minute,
            })),
            "fits": n.fits.iter().map(|f| json!({
                "method": f.method,
                "nll": f.nll,
                "prior": f.prior,
                "objective": f.objective(),
                "iterations": f.iterations,
                "seconds": f.seconds,
                "converged": f.certified,
                "termination": f.termination,
            })).collect::<Vec<_>>(),
        }),
        Err(e) => json!({ "problem": r.problem, "reference_nll": r.reference, "refused": e }),
    }
}

fn number(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.6}"))
}

fn markdown(
    dir: &Path,
    rows: &[Row],
    multistart: &Starting<'_>,
    profile_settings: &Settings,
) -> String {
    let [default, lm] = methods();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## PEtab problems\n\n\
         Every problem of `{}` (Benchmark-Models-PEtab, BSD-3), imported with `--petab`: the \
         negative log-likelihood at the parameter table's nominal values beside AMICI's stored \
         reference (which AMICI checks itself against to 1e-3), and a fit from nominal by the \
         default method ({default}) and by {lm}, each with the objective it ends at, its \
         iterations, its wall-clock time (a problem's experiments are integrated in parallel \
         on {threads} threads) and whether its first-order certificate holds (✓) or \
         not (✗, with the reason in `petab/petab.json`). The objective is what the fits \
         minimise: the NLL plus the priors' negative log-density where the problem has priors \
         (what pyPESTO minimises), the NLL alone where it has none. Import: reading the files \
         and building the problem, the JIT included.\n",
        dir.display(),
        threads = rayon::current_num_threads(),
    );
    let _ = writeln!(
        md,
        "| problem | states | unknowns | experiments | import ms | reference NLL | NLL at nominal | objective at nominal | {default}: objective | it | s | | {lm}: objective | it | s | |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        match &r.outcome {
            Ok(n) => {
                let mut line = format!(
                    "| {} | {} | {} | {} | {:.1} | {} | {} | {} |",
                    r.problem,
                    n.states,
                    n.unknowns,
                    n.experiments,
                    n.import_ms,
                    number(r.reference),
                    number(Some(n.nominal)),
                    number(Some(n.nominal_objective()))
                );
                for f in &n.fits {
                    let _ = write!(
                        line,
                        " {} | {} | {:.2} | {} |",
                        number(f.objective()),
                        f.iterations,
                        f.seconds,
                        if f.certified { "✓" } else { "✗" }
                    );
                }
                let _ = writeln!(md, "{line}");
            }
            Err(e) => {
                let _ = writeln!(
                    md,
                    "| {} | | | | | {} | refused: {} | | | | | | | | | |",
                    r.problem,
                    number(r.reference),
                    e.rsplit(": ").next().unwrap_or(e)
                );
            }
        }
    }
    md.push('\n');
    md += &starts_markdown(rows, multistart);
    for r in rows {
        if let Ok(Numbers { profiles: Some(caption), .. }) = &r.outcome {
            let _ = writeln!(
                md,
                "### {0}: profile likelihoods\n\n![{0} profiles](petab/{0}/profiles.png)\n\n{caption}\n",
                r.problem
            );
        }
    }
    let _ = writeln!(
        md,
        "Profiles are traced where the {lm} fit certifies and the problem has at most \
         {PROFILED_UNKNOWNS} free unknowns, each point re-optimised with at most {} \
         iterations (the report's `--max-iterations`; each fit from nominal above may take {} \
         iterations, each start of a multistart {}).\n",
        profile_settings.driver.max_iterations,
        sysid_core::MAX_ITERATIONS,
        sysid_core::START_MAX_ITERATIONS
    );
    // Said of Crauste where the report has it.
    let crauste = match rows.iter().any(|r| r.problem.starts_with("Crauste_")) {
        true => {
            "Crauste: the stored reference is 1.24e-3 above sysid's value, which agrees to \
             1e-8 with the NLL of the collection's own simulated observables at nominal \
             (docs/petab.md). "
        }
        false => "",
    };
    let _ = writeln!(md, "{crauste}{}\n", kept_best(rows));
    md
}

/// How far above the objective at nominal a fit from nominal may end and still be said to
/// have kept its best point: the two are evaluated at the same point and tolerances, so
/// they differ by rounding alone.
const SAME_OBJECTIVE: f64 = 1e-9;

/// The sentence on whether every fit from nominal kept its best point, checked on the rows:
/// those that ended above the objective at nominal are named.
fn kept_best(rows: &[Row]) -> String {
    let above: Vec<String> = rows
        .iter()
        .filter_map(|r| r.outcome.as_ref().ok().map(|n| (r, n)))
        .flat_map(|(r, n)| {
            let start = n.nominal_objective();
            n.fits.iter().filter_map(move |f| {
                let end = f.objective()?;
                (end > start + SAME_OBJECTIVE * start.abs().max(1.0))
                    .then(|| format!("{} by {} ({end:.6} against {start:.6})", r.problem, f.method))
            })
        })
        .collect();
    match above.is_empty() {
        true => "A fit that is not certified keeps its best point: none of the fits above \
                 ends above the objective at nominal, its start."
            .into(),
        false => format!(
            "These fits ended above the objective at nominal, their start, which a fit that \
             keeps its best point cannot do: {}.",
            above.join("; ")
        ),
    }
}

/// The multistart table and the waterfall figures.
fn starts_markdown(rows: &[Row], starting: &Starting<'_>) -> String {
    let options = starting.options;
    let with: Vec<(&Row, &Starts)> = rows
        .iter()
        .filter_map(|r| match &r.outcome {
            Ok(Numbers { starts: Some(s), .. }) => Some((r, s)),
            _ => None,
        })
        .collect();
    if with.is_empty() {
        return String::new();
    }
    let budget = options.budget.map_or(String::new(), |b| {
        format!(
            " A problem's multistart begins no start after {:.0} s; the starts are taken in \
             order, so those fitted are the first ones, and `fitted` says how many.",
            b.as_secs_f64()
        )
    });
    let limit = starting.seconds.map_or(String::new(), |s| {
        format!(" A start stops after {s} s with its best point, not converged (`time_limit`).")
    });
    let default = Role::Default.method();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "### PEtab problems: up to {n} starts each\n\n\
         {default} from {n} starts drawn as the field draws them (uniform on each unknown's \
         scale within its bounds, or from its PEtab initialization prior; nominal not among \
         them), in parallel on {threads} threads. The objective is the NLL plus the priors' term \
         (what pyPESTO minimises). Best known: the least objective known for the problem, with \
         its source, in `best_known.tsv` beside the problems. Reached: converged starts within \
         {REACHED} of the best known value (or of the best found, where that is lower). Time \
         per start: the median wall time of one fit.{limit}{budget}\n",
        n = options.starts,
        threads = rayon::current_num_threads(),
    );
    let _ = writeln!(
        md,
        "| problem | best known | best found | fitted | converged | reached | time per start (s) | total (s) | converged per minute |\n\
         |---|---|---|---|---|---|---|---|---|"
    );
    for (r, s) in &with {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {:.2} | {:.1} | {:.1} |",
            r.problem,
            number(r.best_known),
            number(s.best),
            s.count,
            s.converged,
            s.reached,
            s.median_seconds,
            s.seconds,
            s.converged_per_minute
        );
    }
    md.push('\n');
    for (r, _) in &with {
        let _ = writeln!(md, "![{0} waterfall](petab/{0}/waterfall.png)\n", r.problem);
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_start_reaches_the_best_known_value_only_converged_and_within_the_tolerance() {
        let starts = [(10.05, true), (10.2, true), (10.01, false), (12.0, true), (f64::NAN, false)];
        // Known 10.0: 10.05 reached; 10.2 is 0.2 above; 10.01 did not converge.
        assert_eq!(reached(&starts, Some(10.0)), (Some(10.01), 1));
        // The best found is lower than the known value: it is the yardstick.
        assert_eq!(reached(&starts, Some(11.0)), (Some(10.01), 1));
        assert_eq!(reached(&starts, None), (Some(10.01), 1));
        // Nothing within 0.1 of a lower known value.
        assert_eq!(reached(&starts, Some(9.0)), (Some(10.01), 0));
        assert_eq!(reached(&[], Some(9.0)), (None, 0));
    }

    fn row(
        problem: &str,
        nominal: f64,
        nominal_prior: Option<f64>,
        ends: &[(f64, Option<f64>)],
    ) -> Row {
        let fits = ends
            .iter()
            .map(|&(nll, prior)| Fit {
                method: "m".into(),
                nll: Some(nll),
                prior,
                iterations: 1,
                seconds: 0.0,
                certified: false,
                termination: String::new(),
            })
            .collect();
        let numbers = Numbers {
            profiles: None,
            starts: None,
            states: 1,
            unknowns: 1,
            experiments: 1,
            import_ms: 0.0,
            nominal,
            nominal_prior,
            fits,
        };
        Row { problem: problem.into(), reference: None, best_known: None, outcome: Ok(numbers) }
    }

    #[test]
    fn a_fit_is_judged_against_the_objective_at_nominal_priors_included() {
        // Raimundez's case: the NLL rose (550.04 → 551.80) while the priors' term fell
        // (72.97 → 64.93): the objective fell, so the fit kept its best point.
        let priors = row("P", 550.04, Some(72.97), &[(551.80, Some(64.93))]);
        assert!(kept_best(&[priors]).starts_with("A fit that is not certified keeps"));
        // Without priors, an NLL above nominal is named, with its method and both values.
        let above = row("Q", 10.0, None, &[(9.0, None), (10.5, None)]);
        let said = kept_best(&[above]);
        assert!(said.contains("Q by m (10.500000 against 10.000000)"), "{said}");
        // Rounding is not a rise.
        let same = row("R", -1e4, None, &[(-1e4 + 1e-8, None)]);
        assert!(kept_best(&[same]).starts_with("A fit that is not certified keeps"));
    }
}
