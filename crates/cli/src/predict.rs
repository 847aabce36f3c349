//! `sysid predict`: fit, then the fitted trajectory forward with a 95 % band.

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;
use sysid_core::format::shortest;

use crate::Outcome;
use crate::options::{IntegratorArgs, MethodArg, MethodArgs, SourceArgs};
use crate::output::{not_an_input, spaced, write_output};
use crate::problem::{fit, problem, watching};

/// Arguments of `sysid predict`.
#[derive(Args, Debug)]
pub struct PredictArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// Predict up to this time.
    #[arg(long, value_name = "T", value_parser = crate::options::number, allow_hyphen_values = true)]
    until: f64,
    /// Spacing of the predicted times (default: 200 intervals from t0 to T).
    #[arg(long, value_name = "H", value_parser = crate::options::number, allow_hyphen_values = true)]
    step: Option<f64>,
    #[command(flatten)]
    method: MethodArg,
    #[command(flatten)]
    options: MethodArgs,
    /// Only this experiment (default: all; with several, a first column names each row's
    /// experiment).
    #[arg(long, value_name = "NAME")]
    experiment: Option<String>,
    /// Write to this file instead of standard output: whole, through a temporary file beside
    /// it and a rename; through a symbolic link to its target; into a device or a FIFO.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// Runs `sysid predict`.
pub fn run(args: &PredictArgs) -> anyhow::Result<Outcome> {
    if !args.until.is_finite() {
        bail!("--until must be a finite time");
    }
    args.options.validate()?;
    args.integrator.validate()?;
    args.method.check()?;
    let (problem, context) = problem(&args.source, &args.integrator, &args.options)?;
    if let Some(out) = &args.out {
        not_an_input(out, &context.inputs, "--out")?;
    }
    let experiments: Vec<usize> = match &args.experiment {
        None => (0..problem.experiments().len()).collect(),
        Some(name) => match problem.experiments().iter().position(|e| e.answers_to(name)) {
            Some(i) => vec![i],
            None => {
                let names: Vec<&str> = problem.experiments().iter().map(|e| e.name()).collect();
                bail!(
                    "--experiment {name}: no such experiment (experiments: {})",
                    names.join(", ")
                );
            }
        },
    };
    // Each experiment's output times, checked before the fit: bad input is refused before
    // any work (`--step 0` was refused only after the whole fit, below its report).
    let mut times_of = Vec::with_capacity(experiments.len());
    for &i in &experiments {
        let (t0, name) = (problem.experiments()[i].t0(), problem.experiments()[i].name());
        if args.until <= t0 {
            bail!("--until {} must lie after t0 = {t0} (experiment `{name}`)", args.until);
        }
        let step = args.step.unwrap_or((args.until - t0) / 200.0);
        if !(step > 0.0 && step.is_finite()) {
            match args.step {
                Some(_) => bail!("--step must be positive, got {step}"),
                // The default step, a 200th of the span, is no number (the span overflows)
                // or no step (it underflows): the span is what to change.
                None => bail!(
                    "--until {} and t0 = {} (experiment `{name}`) are too {} for 200 steps between them: give --step, or another --until",
                    shortest(args.until),
                    shortest(t0),
                    if step > 0.0 { "far apart" } else { "close together" }
                ),
            }
        }
        let what = match args.step {
            Some(_) => format!("--step {step:e} from t0 = {t0} to --until {}", args.until),
            None => format!(
                "the default step {step:e} (a 200th of t0 = {t0} to --until {})",
                args.until
            ),
        };
        let mut times = spaced(t0, args.until, step, &what)?;
        if times.last().is_some_and(|&t| t < args.until) {
            times.push(args.until);
        }
        times_of.push(times);
    }
    let watch = context.watch(&args.method.method, args.options.log_every);
    let estimate =
        watching(&watch, || fit(&problem, &args.method.method, &args.options.settings()))
            .map_err(|e| context.blame(e))?;
    if !estimate.converged() {
        eprintln!(
            "{}: {} did not converge (converged: {}; {}): no prediction written",
            context.name,
            estimate.method,
            estimate.verdict(),
            estimate.termination
        );
        return Ok(Outcome::NotConverged);
    }
    // The band: Student's t for the fit's N − k_free degrees of freedom, as the intervals'.
    let band = estimate.band();
    if band.is_none() {
        eprintln!(
            "{}: no covariance (no more data than unknowns, or a singular normal matrix): the band columns are empty",
            context.name
        );
    }
    let several = experiments.len() > 1;
    let mut text = String::new();
    for (i, times) in experiments.into_iter().zip(times_of) {
        let e = &problem.experiments()[i];
        let states = problem.trajectory(i, &estimate.values, band, &times).map_err(|error| {
            let experiment = match several {
                true => format!(" (experiment `{}`)", e.name()),
                false => String::new(),
            };
            context.blame(anyhow::anyhow!(
                "the fitted model cannot be integrated to --until {}{experiment}: {error}",
                shortest(args.until)
            ))
        })?;
        if text.is_empty() {
            text += if several { "experiment,t" } else { "t" };
            for s in &states {
                text += &format!(",{n},{n}_lower,{n}_upper", n = s.name);
            }
            text += "\n";
        }
        for (m, t) in times.iter().enumerate() {
            if several {
                text += &format!("{},", e.name());
            }
            text += &shortest(*t);
            for s in &states {
                let y = s.values[m];
                let y_text = shortest(y);
                match &s.half_width {
                    Some(w) => {
                        text += &format!(",{y_text},{},{}", shortest(y - w[m]), shortest(y + w[m]));
                    }
                    None => text += &format!(",{y_text},,"),
                }
            }
            text += "\n";
        }
    }
    write_output(args.out.as_deref(), &text)?;
    Ok(Outcome::Success)
}
