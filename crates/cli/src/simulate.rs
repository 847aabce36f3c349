//! `sysid simulate`: a catalogue system's data, or a model's trajectory, as CSV.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow, bail};
use clap::Args;
use sysid_core::{Data, Record, Samples};
use sysid_model::Model;
use sysid_ode::{Inputs, Ivp, System};
use sysid_systems::{Case, Visit};

use crate::Outcome;

/// Arguments of `sysid simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// A catalogue system: write its data (with the seeded noise).
    #[arg(long, value_name = "NAME", required_unless_present = "model", conflicts_with = "model")]
    system: Option<String>,
    /// A model file: write its trajectory (states, then outputs) at --times.
    #[arg(long, value_name = "FILE", requires = "times")]
    model: Option<PathBuf>,
    /// Output times a:b:step, e.g. 0:10:0.1 (model files).
    #[arg(long, value_name = "A:B:STEP", allow_hyphen_values = true)]
    times: Option<String>,
    /// Set an unknown (or known) value, e.g. --set k1=0.8; unknowns are at their guesses
    /// otherwise. Repeat for several.
    #[arg(long = "set", value_name = "NAME=VALUE", allow_hyphen_values = true)]
    set: Vec<String>,
    /// The data file whose input columns drive the model (default: the model's data file).
    #[arg(long, value_name = "CSV", requires = "model", conflicts_with = "system")]
    data: Option<PathBuf>,
    /// Seed of the synthetic noise (catalogue systems): the same seed gives the same data.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    seed: u64,
    /// Sample spacing for a catalogue record given as a function (continuous systems).
    #[arg(long, default_value_t = 0.001, value_name = "DT", allow_negative_numbers = true)]
    step: f64,
    /// Write to this file instead of standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// Runs `sysid simulate`.
pub fn run(args: &SimulateArgs) -> anyhow::Result<Outcome> {
    let text = match (&args.system, &args.model) {
        (Some(name), _) => {
            if !(args.step > 0.0 && args.step.is_finite()) {
                bail!("--step must be positive, got {}", args.step);
            }
            let data =
                sysid_systems::visit(name, DataOf { seed: args.seed }).ok_or_else(|| {
                    anyhow!(
                        "unknown system `{name}` (systems: {})",
                        sysid_systems::NAMES.join(", ")
                    )
                })??;
            data_csv(&data, args.step)?
        }
        (None, Some(path)) => model_csv(path, args)?,
        (None, None) => bail!("give --system NAME or --model FILE"),
    };
    write_output(args.out.as_deref(), &text)?;
    Ok(Outcome::Success)
}

/// Writes to a file (through a temporary, so a failure leaves no partial file) or stdout.
pub fn write_output(out: Option<&Path>, text: &str) -> anyhow::Result<()> {
    match out {
        // Through a temporary file of our own beside it (never a user's `out.partial`),
        // renamed: the file is old or new, never half; errors name the user's path.
        Some(path) => sysid_montecarlo::files::write_atomically(path, text)?,
        None => crate::emit(text)?,
    }
    Ok(())
}

/// The most output times (CSV rows) a command writes. More is a step given in the wrong
/// unit, and would not fit in memory (predict asked for 40 TB at --step 1e-12).
pub const MAX_TIMES: usize = 10_000_000;

/// Parses `a:b:step` into the times a, a + step, …, up to b (inclusive within rounding).
pub fn parse_times(spec: &str) -> anyhow::Result<Vec<f64>> {
    let parts: Vec<&str> = spec.split(':').collect();
    let [a, b, h] = parts[..] else { bail!("--times must be a:b:step, got `{spec}`") };
    let number = |s: &str| -> anyhow::Result<f64> {
        let v: f64 = s.trim().parse().map_err(|_| anyhow!("--times: `{s}` is not a number"))?;
        if !v.is_finite() {
            bail!("--times: `{s}` is not a finite number");
        }
        Ok(v)
    };
    let (a, b, h) = (number(a)?, number(b)?, number(h)?);
    if h <= 0.0 || b < a {
        bail!("--times a:b:step needs a ≤ b and step > 0, got {spec}");
    }
    spaced(a, b, h, &format!("--times {spec}"))
}

/// The times a, a + h, …, up to b (inclusive within rounding), for a ≤ b and h > 0; `what`
/// names the options that asked for them in the error when they are more than [`MAX_TIMES`].
pub fn spaced(a: f64, b: f64, h: f64, what: &str) -> anyhow::Result<Vec<f64>> {
    let n = intervals((b - a) / h + 1e-9, what)?;
    Ok((0..=n).map(|i| a + h * i as f64).collect())
}

/// The number of intervals `count` (rounded down), refused when the times would be more
/// than [`MAX_TIMES`]; `what` names the options that asked for them.
pub fn intervals(count: f64, what: &str) -> anyhow::Result<usize> {
    if count.is_nan() || count >= MAX_TIMES as f64 {
        bail!(
            "{what} asks for {:.1e} times, more than the {MAX_TIMES} a command writes",
            count + 1.0
        );
    }
    Ok(count.floor() as usize)
}

fn model_csv(path: &Path, args: &SimulateArgs) -> anyhow::Result<String> {
    let model = Model::load(path)?;
    let times = parse_times(args.times.as_deref().unwrap_or_default())?;
    // Inputs come from a data file; a model without inputs needs none.
    let inputs = if model.file.inputs.is_empty() {
        Inputs::default()
    } else {
        let data = match &args.data {
            Some(d) => d.as_path(),
            None => model.data_path()?,
        };
        sysid_model::data::read(&model.file, data)?.inputs
    };
    let system = model.system(inputs);
    let sig = system.signature().clone();
    let mut y0 = vec![f64::NAN; sig.n_states()];
    let mut p = vec![f64::NAN; sig.n_parameters()];
    let mut assign = |name: &str, value: f64| -> anyhow::Result<()> {
        if let Some(i) = sig.state(name) {
            y0[i] = value;
        } else if let Some(k) = sig.parameter(name) {
            p[k] = value;
        } else {
            bail!("--set: `{name}` is not a state or parameter of {}", path.display());
        }
        Ok(())
    };
    for (name, value) in &model.file.known {
        assign(name, *value)?;
    }
    for u in &model.file.unknowns {
        assign(&u.name, u.guess)?;
    }
    for s in &args.set {
        let (name, value) =
            s.split_once('=').ok_or_else(|| anyhow!("--set takes NAME=VALUE, got `{s}`"))?;
        let value: f64 =
            value.trim().parse().map_err(|_| anyhow!("--set {name}: `{value}` is not a number"))?;
        if !value.is_finite() {
            bail!("--set {name}: `{value}` is not a finite number");
        }
        assign(name.trim(), value)?;
    }
    let t0 = model.file.data.t0;
    let sol = Ivp::new(&system, t0, &y0, &p)
        .solve(&model.file.integrator, &times)
        .with_context(|| format!("simulating {}", path.display()))?;
    let n_out = sig.outputs().len();
    let mut h = vec![0.0; n_out];
    let mut u = vec![0.0; sig.n_inputs()];
    let mut text = String::from("t");
    for name in sig.states().iter().chain(sig.outputs()) {
        text += &format!(",{name}");
    }
    text += "\n";
    for (m, &t) in times.iter().enumerate() {
        text += &format!("{t}");
        for v in sol.state(m) {
            text += &format!(",{v}");
        }
        if n_out > 0 {
            system.input_values(t, sysid_ode::Side::After, &mut u);
            system.outputs(t, sol.state(m), &p, &u, &mut h);
            for v in &h {
                text += &format!(",{v}");
            }
        }
        text += "\n";
    }
    Ok(text)
}

struct DataOf {
    seed: u64,
}

impl Visit for DataOf {
    type Output = anyhow::Result<Data>;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        Ok(case.data(self.seed)?)
    }
}

/// The data as CSV: a header row `t,<series...>`, one row per time, empty cells where a
/// series has no sample. Every digit is kept (shortest round-trip representation). A record
/// given as a function is sampled every `step` (rounded to divide the record evenly).
fn data_csv(data: &Data, step: f64) -> anyhow::Result<String> {
    let columns: Vec<(String, Vec<(f64, f64)>)> = data
        .series
        .iter()
        .map(|s| {
            let points = match (&s.samples, data.record) {
                (Samples::Points { times, values }, _) => {
                    times.iter().copied().zip(values.iter().copied()).collect()
                }
                (Samples::Function(f), Record::Continuous { t_lo, t_hi }) => {
                    let what = format!("--step {step:e} over the record [{t_lo}, {t_hi}]");
                    let n = intervals(((t_hi - t_lo) / step).round(), &what)?;
                    (0..=n)
                        .map(|i| t_lo + (t_hi - t_lo) * i as f64 / n as f64)
                        .map(|t| (t, f(t)))
                        .collect()
                }
                (Samples::Function(_), Record::Discrete) => Vec::new(),
            };
            Ok((s.name.clone(), points))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut times: Vec<f64> = columns.iter().flat_map(|c| c.1.iter().map(|p| p.0)).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let mut out = String::from("t");
    for (name, _) in &columns {
        out += &format!(",{name}");
    }
    out += "\n";
    let mut cursor = vec![0; columns.len()];
    for &t in &times {
        out += &format!("{t}");
        for (c, (_, points)) in columns.iter().enumerate() {
            out += ",";
            if points.get(cursor[c]).is_some_and(|p| p.0.total_cmp(&t).is_eq()) {
                out += &format!("{}", points[cursor[c]].1);
                cursor[c] += 1;
            }
        }
        out += "\n";
    }
    Ok(out)
}
