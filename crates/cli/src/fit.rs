//! `sysid fit`.

use clap::Args;
use sysid_core::Estimate;

use crate::Outcome;
use crate::options::{Format, IntegratorArgs, MethodArg, MethodArgs, SourceArgs, StartsArgs};
use crate::output::emit;
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
}

/// Runs `sysid fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.integrator.validate()?;
    args.starts.options()?;
    sysid_registry::parse_list(&args.method.method)?;
    let (problem, context) = problem(&args.source, &args.integrator, &args.options)?;
    let settings = args.options.settings();
    let (estimate, starts) =
        fit_from_starts(&problem, &args.method.method, &settings, &args.starts)?;
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
