//! The PEtab section: every problem of a directory of PEtab problems (tests/data/petab)
//! imported, its NLL at the nominal parameters beside the stored reference
//! (`references.tsv`), and fits from nominal by the default method and by
//! Levenberg–Marquardt: the NLL they end at, their iterations and time, certified or not.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use serde_json::json;
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
    iterations: usize,
    seconds: f64,
    certified: bool,
    termination: String,
}

/// One problem: what importing it and fitting it gave.
struct Row {
    problem: String,
    reference: Option<f64>,
    outcome: Result<Numbers, String>,
}

struct Numbers {
    /// The caption of its profiles figure, where they were traced.
    profiles: Option<String>,
    states: usize,
    unknowns: usize,
    experiments: usize,
    import_ms: f64,
    nominal: f64,
    fits: Vec<Fit>,
}

/// The reference NLLs of `references.tsv` in `dir`: problem → NLL.
fn references(dir: &Path) -> Vec<(String, f64)> {
    let Ok(text) = std::fs::read_to_string(dir.join("references.tsv")) else {
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

/// Imports, evaluates and fits one problem; traces its profiles (into `out`) where the
/// Levenberg–Marquardt fit certifies and it has at most [`PROFILED_UNKNOWNS`] free unknowns.
fn numbers(yaml: &Path, out: &Path, observer: &dyn Observer) -> Result<Numbers, String> {
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
            profiles = crate::profiles::write_profiles(&name, &problem, &fit, out, m)
                .map_err(|e| format!("profiles: {e}"))?;
            observer.note(&format!(
                "{}: profiles in {:.1} s",
                yaml.display(),
                t.elapsed().as_secs_f64()
            ));
        }
    }
    Ok(Numbers {
        profiles,
        states: problem.experiments()[0].system().signature().n_states(),
        unknowns: problem.names().len(),
        experiments: problem.experiments().len(),
        import_ms,
        nominal,
        fits,
    })
}

/// The problems of `dir` (a folder each, with its YAML of the same name), their numbers
/// written to `out/petab/petab.json`; the section's Markdown.
pub(crate) fn section(dir: &Path, out: &Path, observer: &dyn Observer) -> anyhow::Result<String> {
    let references = references(dir);
    let mut rows = Vec::new();
    for name in problems(dir) {
        let yaml = dir.join(&name).join(format!("{name}.yaml"));
        let outcome = numbers(&yaml, &out.join("petab").join(&name), observer);
        let reference = references.iter().find(|r| r.0 == name).map(|r| r.1);
        rows.push(Row { problem: name, reference, outcome });
    }
    let json: Vec<serde_json::Value> = rows.iter().map(row_json).collect();
    std::fs::create_dir_all(out.join("petab"))?;
    crate::manifest::write(
        &out.join("petab/petab.json"),
        &serde_json::to_string_pretty(&json).expect("JSON"),
    )?;
    Ok(markdown(dir, &rows))
}

fn row_json(r: &Row) -> serde_json::Value {
    match &r.outcome {
        Ok(n) => json!({
            "problem": r.problem,
            "reference_nll": r.reference,
            "nll_at_nominal": n.nominal,
            "states": n.states,
            "unknowns": n.unknowns,
            "experiments": n.experiments,
            "import_ms": n.import_ms,
            "fits": n.fits.iter().map(|f| json!({
                "method": f.method,
                "nll": f.nll,
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

fn markdown(dir: &Path, rows: &[Row]) -> String {
    let [default, lm] = methods();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## PEtab problems\n\n\
         Every problem of `{}` (Benchmark-Models-PEtab, BSD-3), imported with `--petab`: the \
         negative log-likelihood at the parameter table's nominal values beside AMICI's stored \
         reference (which AMICI checks itself against to 1e-3), and a fit from nominal by the \
         default method ({default}) and by {lm}, each with the NLL it ends at, its iterations, \
         its time on one core and whether its first-order certificate holds (✓) or not (✗, with \
         the reason in `petab/petab.json`). Import: reading the files and building the \
         problem, the JIT included.\n",
        dir.display()
    );
    let _ = writeln!(
        md,
        "| problem | states | unknowns | experiments | import ms | reference NLL | NLL at nominal | {default}: NLL | it | s | | {lm}: NLL | it | s | |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        match &r.outcome {
            Ok(n) => {
                let mut line = format!(
                    "| {} | {} | {} | {} | {:.1} | {} | {} |",
                    r.problem,
                    n.states,
                    n.unknowns,
                    n.experiments,
                    n.import_ms,
                    number(r.reference),
                    number(Some(n.nominal))
                );
                for f in &n.fits {
                    let _ = write!(
                        line,
                        " {} | {} | {:.2} | {} |",
                        number(f.nll),
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
                    "| {} | | | | | {} | refused: {} | | | | | | | | |",
                    r.problem,
                    number(r.reference),
                    e.rsplit(": ").next().unwrap_or(e)
                );
            }
        }
    }
    md.push('\n');
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
         {PROFILED_UNKNOWNS} free unknowns.\n"
    );
    let _ = writeln!(
        md,
        "Crauste: the stored reference is 1.24e-3 above sysid's value, which agrees to 1e-8 \
         with the NLL of the collection's own simulated observables at nominal \
         (docs/petab.md). A fit that is not certified keeps its best point: its NLL is never \
         above the NLL at nominal.\n"
    );
    md
}
