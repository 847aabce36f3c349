//! `sysid compare`: every chosen method on the same data from the same start.

use clap::Args;
use sysid_core::format::significant;
use sysid_core::{
    Estimate,
    format::{Compared, compact, compact_header, comparison},
};
use sysid_montecarlo::multistart::Starts;
use sysid_registry::ENTRIES;

use crate::Outcome;
use crate::options::{Format, IntegratorArgs, MethodArgs, SourceArgs, StartsArgs};
use crate::output::emit;
use crate::problem::{
    AnyProblem, Context, best_of_starts, method, no_source, problem, watching, with_starts,
};

/// Arguments of `sysid compare`.
#[derive(Args, Debug)]
pub struct CompareArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// Every catalogue system, one after the other.
    #[arg(long, conflicts_with_all = ["system", "model", "data"])]
    all: bool,
    /// Comma-separated methods (default: all of them).
    #[arg(long, value_name = "A,B,C")]
    methods: Option<String>,
    /// Per system, a table with each method's estimates next to the truth or reference
    /// answer, its termination and its multistart, instead of one line per method (one
    /// system) or the matrix of systems and methods (several).
    #[arg(long)]
    verbose: bool,
    /// Output format: tables, or a JSON list of fit objects (one per method, converged or
    /// not).
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    #[command(flatten)]
    options: MethodArgs,
    #[command(flatten)]
    starts: StartsArgs,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// One method's outcome on one system.
pub struct Row {
    method: String,
    result: Result<(Estimate, Option<Starts>), String>,
}

/// Runs `sysid compare`.
pub fn run(args: &CompareArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.integrator.validate()?;
    args.starts.options()?;
    args.starts.check_start(&args.options.start)?;
    let methods = match &args.methods {
        Some(list) => sysid_registry::parse_list(list)?,
        None => ENTRIES.iter().map(|e| e.name.to_string()).collect(),
    };
    let sources: Vec<SourceArgs> = match (args.all, &args.source) {
        (true, _) => sysid_systems::NAMES
            .iter()
            .map(|n| SourceArgs { system: Some(n.to_string()), ..args.source.clone() })
            .collect(),
        (false, SourceArgs { system: None, model: None, petab: None, .. }) => {
            return Err(no_source());
        }
        (false, source) => vec![source.clone()],
    };
    let starts = args.starts.options()?;
    // Each start of --starts has a start's budget; without, one fit's.
    let settings = args.options.settings_for(starts.as_ref());
    let methods = crate::problem::as_run(&methods, &settings)?;
    let mut json = Vec::new();
    let mut tables = Vec::new();
    let mut summaries = Vec::new();
    for source in &sources {
        let (problem, context) = problem(source, &args.integrator, &args.options)?;
        let mut rows = Vec::with_capacity(methods.len());
        for name in &methods {
            // Stopped (Ctrl-C): the methods not yet begun are listed, not run.
            if sysid_core::observer::stop_requested() {
                let result = Err("not begun: the run was stopped".to_string());
                rows.push(Row { method: name.clone(), result });
                continue;
            }
            let m = method(name, &settings)?;
            let watch = context.watch(name, args.options.log_every);
            let result = match &starts {
                Some(options) => best_of_starts(&problem, &*m, options, &watch)
                    .map(|(e, s)| (e, Some(s)))
                    .map_err(|e| e.to_string()),
                None => watching(&watch, || m.fit(&problem))
                    .map(|e| (e, None))
                    .map_err(|e| e.to_string()),
            };
            rows.push(Row { method: name.clone(), result });
        }
        json.extend(rows.iter().map(|row| match &row.result {
            Ok((e, starts)) => with_starts(e.record(&context.name), starts.as_ref()),
            Err(message) => serde_json::json!({
                "system": context.name, "method": row.method, "converged": false, "error": message,
            }),
        }));
        tables.push(text(&problem, &context, &rows, args.verbose));
        summaries.push(Summary { system: context.name, rows });
        if sysid_core::observer::stop_requested() {
            if summaries.len() < sources.len() {
                eprintln!(
                    "stopped: {} of the {} systems compared, the rest not begun",
                    summaries.len(),
                    sources.len()
                );
            }
            break;
        }
    }
    match args.format {
        Format::Json => emit(&format!("{}\n", serde_json::to_string_pretty(&json)?))?,
        Format::Table if args.verbose => emit(&tables.join("\n"))?,
        Format::Table if summaries.len() > 1 => emit(&matrix(&methods, &summaries))?,
        Format::Table => {
            let name = summaries.first().map_or("", |s| s.system.as_str());
            emit(&(compact_header(name) + &tables.concat()))?
        }
    }
    Ok(Outcome::Success)
}

/// One system's outcomes.
struct Summary {
    system: String,
    rows: Vec<Row>,
}

/// Two costs of converged fits within this relative distance are the same minimum.
const SAME_MINIMUM: f64 = 1e-6;

/// Several systems at a glance: a row per method, a column per system (numbered, named
/// below with the least cost and how many methods reached it), each cell ✓ and the
/// iterations of a converged fit, ✗ and the iterations of one that did not converge, ! for a
/// method that refused the problem or was not begun (Ctrl-C); then every fit that did not
/// converge, with why.
fn matrix(methods: &[String], systems: &[Summary]) -> String {
    let width = sysid_core::format::column_width(methods.iter().map(String::as_str), 6);
    let mut out = format!(
        "{} methods on {} systems, each from the system's default start.\n✓ n: converged (the \
         certificate holds) after n iterations; ✗ n: did not; !: refused the problem (or not \
         begun: the run was stopped).\n\
         `--verbose` prints every fit in full, `--format json` as JSON.\n\n{:width$}",
        methods.len(),
        systems.len(),
        "",
    );
    for j in 1..=systems.len() {
        out += &format!(" {j:>5}");
    }
    out.push('\n');
    for (i, method) in methods.iter().enumerate() {
        out += &format!("{method:width$}");
        for s in systems {
            let cell = match &s.rows[i].result {
                Ok((e, _)) => {
                    format!("{} {}", if e.converged() { '✓' } else { '✗' }, e.iterations)
                }
                Err(_) => "!".into(),
            };
            out += &format!(" {cell:>5}");
        }
        out.push('\n');
    }
    out.push('\n');
    let name_width = sysid_core::format::column_width(systems.iter().map(|s| s.system.as_str()), 0);
    let mut failures = Vec::new();
    for (j, s) in systems.iter().enumerate() {
        let fits: Vec<&Estimate> =
            s.rows.iter().filter_map(|r| r.result.as_ref().ok()).map(|r| &r.0).collect();
        let elapsed: f64 = fits.iter().map(|e| e.elapsed.as_secs_f64()).sum();
        let converged: Vec<&&Estimate> = fits.iter().filter(|e| e.converged()).collect();
        let best = converged.iter().min_by(|a, b| a.cost.total_cmp(&b.cost));
        let least = best.map_or(f64::INFINITY, |e| e.cost);
        // Where the model passes through the data, ε is the integration's noise: every
        // exact fit is the minimum.
        let exact = best.is_some_and(|e| e.certificate.exact_fit);
        let reached = converged
            .iter()
            .filter(|e| match exact {
                true => e.certificate.exact_fit,
                false => e.cost - least <= SAME_MINIMUM * least.abs(),
            })
            .count();
        let minimum = match (least.is_finite(), exact) {
            (false, _) => "no method converged".into(),
            (true, true) => format!("an exact fit (reached by {reached})"),
            (true, false) => format!("least ε {} (reached by {reached})", significant(least, 10)),
        };
        out += &format!("{:>3} {:name_width$}  {minimum}, {:.2} s\n", j + 1, s.system, elapsed);
        for row in &s.rows {
            match &row.result {
                Ok((e, _)) if !e.converged() => failures.push(format!(
                    "  {} on {}: {} after {} iteration{} (ε {})",
                    row.method,
                    s.system,
                    e.termination.code(),
                    e.iterations,
                    if e.iterations == 1 { "" } else { "s" },
                    significant(e.cost, 10)
                )),
                Ok(_) => {}
                Err(message) => {
                    failures.push(format!("  {} on {}: {message}", row.method, s.system))
                }
            }
        }
    }
    if !failures.is_empty() {
        out += &format!("\nNot converged ({}):\n{}\n", failures.len(), failures.join("\n"));
    }
    out
}

/// One system's rows as text: a table per system (`verbose`) or a line per method.
fn text(problem: &AnyProblem, context: &Context, rows: &[Row], verbose: bool) -> String {
    let compared: Vec<Compared<'_>> = rows
        .iter()
        .map(|row| Compared {
            method: &row.method,
            fit: row.result.as_ref().map(|r| &r.0).map_err(String::as_str),
            note: row.result.as_ref().ok().and_then(|r| r.1.as_ref()).map(|s| match verbose {
                true => s.to_string(),
                false => format!("best of {} starts ({} reached it)", s.count, s.reached_best),
            }),
        })
        .collect();
    match verbose {
        true => format!(
            "{}: {}\n{}",
            context.name,
            context.summary,
            comparison(&problem.names(), context.expected.as_ref(), &compared)
        ),
        false => compact(&context.name, &compared),
    }
}
