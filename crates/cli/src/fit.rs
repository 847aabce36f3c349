//! `sysid fit`.

use clap::Args;
use sysid_core::Estimate;

use crate::Outcome;
use crate::options::{Format, IntegratorArgs, MethodArg, MethodArgs, SourceArgs, StartsArgs};
use crate::output::{Trace, emit, figure_writable};
use crate::problem::{Context, fit_from_starts, problem, with_starts};

/// Arguments of `sysid fit`.
#[derive(Args, Debug)]
pub struct FitArgs {
    #[command(flatten)]
    source: SourceArgs,
    #[command(flatten)]
    method: MethodArg,
    /// Output format: a readable table, or the JSON object of docs/json.md (printed
    /// for every run past input checking, converged or not).
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    #[command(flatten)]
    options: MethodArgs,
    #[command(flatten)]
    starts: StartsArgs,
    #[command(flatten)]
    integrator: IntegratorArgs,
    /// With --starts: draw the waterfall (every start's final objective, sorted) to
    /// STEM.png and STEM.svg.
    #[arg(long, value_name = "STEM")]
    waterfall: Option<std::path::PathBuf>,
    /// Write the fit's every iterate and every trial step to FILE as it runs, one JSON
    /// object a line (docs/json.md, "sysid fit --trace FILE"): for the trust-region methods
    /// each trial's model, radius, λ, predicted and actual decrease, and whether it was
    /// taken. One fit: not with --starts (fit a start alone from its start values instead).
    #[arg(long, value_name = "FILE")]
    trace: Option<std::path::PathBuf>,
}

/// Runs `sysid fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.integrator.validate()?;
    args.starts.options()?;
    args.starts.check_start(&args.options.start)?;
    args.method.check()?;
    let (problem, context) = problem(&args.source, &args.integrator, &args.options)?;
    // Where the figure goes is checked before the work, not after it.
    if let Some(stem) = &args.waterfall {
        if args.starts.starts.is_none() {
            anyhow::bail!("--waterfall needs --starts N");
        }
        figure_writable(stem, &context.inputs, "--waterfall")?;
    }
    let watch = context.watch(&args.method.method, args.options.log_every);
    if let Some(path) = &args.trace {
        if args.starts.starts.is_some() {
            anyhow::bail!(
                "--trace follows one fit, and the starts of --starts run side by side: trace a \
                 start alone, fitted from its start values (--start NAME=VALUE for each unknown; \
                 the JSON's waterfall lists them)"
            );
        }
        watch.set_trace(Trace::create(path, &context.inputs)?)?;
    }
    let (estimate, starts) =
        fit_from_starts(&problem, &args.method.method, &args.options, &args.starts, &watch)
            .map_err(|e| context.blame(e))?;
    match args.format {
        Format::Json => {
            let record = with_starts(estimate.record(&context.name), starts.as_ref());
            emit(&format!("{}\n", serde_json::to_string_pretty(&record)?))?
        }
        Format::Table => {
            let mut text = table(&context, &estimate);
            if let Some(s) = &starts {
                text += &format!("\n  starts       {}\n", s);
            }
            emit(&text)?
        }
    }
    // The results are out before the trace is closed and the figure drawn: a file that
    // cannot be written loses nothing.
    if let Some(trace) = watch.trace() {
        trace.finish()?;
        eprintln!("wrote {}", trace.path().display());
    }
    if let (Some(stem), Some(s)) = (&args.waterfall, &starts) {
        let subject = std::path::Path::new(&context.name)
            .file_name()
            .map_or(context.name.clone(), |n| n.to_string_lossy().into_owned());
        let objectives =
            s.waterfall.iter().filter_map(|o| o.objective.map(|v| (v, o.converged))).collect();
        let figure =
            sysid_report::Waterfall::of_starts(&subject, s.count, &estimate.method, objectives);
        let [png, svg] = sysid_report::save(&figure, stem)?;
        eprintln!("wrote {} and {}", png.display(), svg.display());
    }
    Ok(if estimate.converged() { Outcome::Success } else { Outcome::NotConverged })
}

/// The readable report: the problem and the method, then the estimates next to the
/// reference or truth, and the run.
fn table(context: &Context, e: &Estimate) -> String {
    let describe = sysid_registry::entry(&e.method).map_or("", |m| m.description);
    format!(
        "{}: {}\nmethod {}: {describe}\n\n{}",
        context.name,
        context.summary,
        e.method,
        e.table(context.expected.as_ref())
    )
}
