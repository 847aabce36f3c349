//! `sysid simulate`: a catalogue system's data, or a model's trajectory, as CSV.

use std::path::{Path, PathBuf};

use anyhow::bail;
use clap::Args;
use sysid_core::{Data, Record};

use crate::Outcome;
use crate::options::{IntegratorArgs, SourceArgs, once_each, parse_fix};
use crate::output::{intervals, not_an_input, parse_times, writable, write_output};
use crate::problem::{case, no_source};

/// Arguments of `sysid simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// A catalogue system: its data, with the seeded noise. A model file: its trajectory
    /// (states, then outputs) at --times, inputs from the data file.
    #[command(flatten)]
    source: SourceArgs,
    /// Output times a:b:step, e.g. 0:10:0.1 (model files).
    #[arg(long, value_name = "A:B:STEP", allow_hyphen_values = true)]
    times: Option<String>,
    /// Set an unknown (or known) value, e.g. --set k1=0.8; unknowns are at their guesses
    /// otherwise. Repeat for several.
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = parse_fix, allow_hyphen_values = true)]
    set: Vec<(String, f64)>,
    /// Only this experiment of a model file with [[experiments]] (default: all, a first
    /// column naming each row's experiment).
    #[arg(long, value_name = "NAME")]
    experiment: Option<String>,
    /// Sample spacing for a catalogue record given as a function (continuous systems).
    #[arg(long, default_value_t = 0.001, value_name = "DT", value_parser = crate::options::number, allow_hyphen_values = true)]
    step: f64,
    /// Write to this file instead of standard output: whole, through a temporary file beside
    /// it and a rename; through a symbolic link to its target; into a device or a FIFO.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// Runs `sysid simulate`.
pub fn run(args: &SimulateArgs) -> anyhow::Result<Outcome> {
    if let Some(out) = &args.out {
        writable(out, "--out")?;
    }
    if !(args.step > 0.0 && args.step.is_finite()) {
        bail!("--step must be a finite positive number, got {}", args.step);
    }
    args.integrator.validate()?;
    let text = match (&args.source.system, args.source.file()) {
        (Some(name), _) => {
            // A catalogue system's data are its own: options of model files are refused,
            // not ignored.
            for (given, option) in [
                (args.times.is_some(), "--times"),
                (!args.set.is_empty(), "--set"),
                (args.experiment.is_some(), "--experiment"),
            ] {
                if given {
                    bail!(
                        "{option} is for a model file's trajectory: `--system {name}` writes the system's data as the catalogue has them"
                    );
                }
            }
            let mut case = case(name)?;
            case.integrator = args.integrator.apply_to(case.integrator)?;
            let data = case.data(args.source.seed)?;
            data_csv(&data, args.step)?
        }
        (None, Some(path)) => model_csv(path, args)?,
        (None, None) => return Err(no_source()),
    };
    write_output(args.out.as_deref(), &text)?;
    Ok(Outcome::Success)
}

/// A model file's trajectory at `--times`, with `--set` values.
fn model_csv(path: &Path, args: &SimulateArgs) -> anyhow::Result<String> {
    let Some(times) = &args.times else {
        bail!("a model's trajectory needs its times: add --times A:B:STEP, e.g. --times 0:10:0.1");
    };
    let times = parse_times(times)?;
    once_each(&args.set, "--set")?;
    let mut model = args.source.load(path)?;
    model.file.integrator = args.integrator.apply_to(model.file.integrator)?;
    if let Some(out) = &args.out {
        let inputs: Vec<PathBuf> =
            model.inputs().into_iter().chain(args.source.data.clone()).collect();
        not_an_input(out, &inputs, "--out")?;
    }
    Ok(model.simulate(
        &args.set,
        args.source.data.as_deref(),
        &times,
        args.experiment.as_deref(),
    )?)
}

/// The data as CSV, a record given as a function sampled every `step` (rounded to divide
/// the record evenly).
fn data_csv(data: &Data, step: f64) -> anyhow::Result<String> {
    let n = match data.record {
        Record::Continuous { t_lo, t_hi } => {
            let what = format!("--step {step:e} over the record [{t_lo}, {t_hi}]");
            intervals(((t_hi - t_lo) / step).round(), &what)?
        }
        Record::Discrete => 0,
    };
    Ok(sysid_model::simulate::data_csv(data, n))
}
