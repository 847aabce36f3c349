//! `sysid simulate`: a catalogue system's data, or a model's trajectory, as CSV.

use std::path::PathBuf;

use anyhow::{Context as _, anyhow, bail};
use clap::Args;
use sysid_core::{Data, Record, Samples};
use sysid_model::Model;
use sysid_ode::{Inputs, Ivp, System};
use sysid_systems::{Case, Visit};

use crate::Outcome;
use crate::options::SourceArgs;
use crate::output::{decimal, intervals, parse_times, write_output};
use crate::problem::{no_source, visit_system};

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
    #[arg(long = "set", value_name = "NAME=VALUE", allow_hyphen_values = true)]
    set: Vec<String>,
    /// Sample spacing for a catalogue record given as a function (continuous systems).
    #[arg(long, default_value_t = 0.001, value_name = "DT", allow_negative_numbers = true)]
    step: f64,
    /// Write to this file instead of standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// Runs `sysid simulate`.
pub fn run(args: &SimulateArgs) -> anyhow::Result<Outcome> {
    let text = match (&args.source.system, &args.source.model) {
        (Some(name), _) => {
            if !(args.step > 0.0 && args.step.is_finite()) {
                bail!("--step must be positive, got {}", args.step);
            }
            let data = visit_system(name, DataOf { seed: args.source.seed })??;
            data_csv(&data, args.step)?
        }
        (None, Some(path)) => model_csv(path, args)?,
        (None, None) => return Err(no_source()),
    };
    write_output(args.out.as_deref(), &text)?;
    Ok(Outcome::Success)
}

fn model_csv(path: &std::path::Path, args: &SimulateArgs) -> anyhow::Result<String> {
    let model = Model::load(path)?;
    let Some(times) = &args.times else {
        bail!("a model's trajectory needs its times: add --times A:B:STEP, e.g. --times 0:10:0.1");
    };
    let times = parse_times(times)?;
    // Inputs come from a data file; a model without inputs needs none.
    let inputs = if model.file.inputs.is_empty() {
        Inputs::default()
    } else {
        let data = match &args.source.data {
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
        // The data's times as a person wrote them: 0.3, not 0.30000000000000004 (3 × 0.1).
        out += &format!("{}", decimal(t));
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
