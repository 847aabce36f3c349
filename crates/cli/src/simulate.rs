//! `sysid simulate`: the data of a catalogue system as CSV.

use std::io::Write;

use anyhow::anyhow;
use clap::Args;
use sysid_core::{Data, Record, Samples};
use sysid_ode::System;
use sysid_systems::{Case, Visit};

use crate::Outcome;

/// Arguments of `sysid simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// The catalogue system (`sysid systems` lists them).
    #[arg(long, value_name = "NAME")]
    system: String,
    /// Seed of the synthetic noise: the same seed gives the same data on every machine.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Sample spacing for a record given as a function (continuous systems).
    #[arg(long, default_value_t = 0.001, value_name = "DT")]
    step: f64,
    /// Write to this file instead of standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<std::path::PathBuf>,
}

/// Runs `sysid simulate`.
pub fn run(args: &SimulateArgs) -> anyhow::Result<Outcome> {
    if !(args.step > 0.0 && args.step.is_finite()) {
        anyhow::bail!("--step must be positive, got {}", args.step);
    }
    let data =
        sysid_systems::visit(&args.system, DataOf { seed: args.seed }).ok_or_else(|| {
            anyhow!(
                "unknown system `{}` (systems: {})",
                args.system,
                sysid_systems::NAMES.join(", ")
            )
        })??;
    let text = csv(&data, args.step);
    match &args.out {
        Some(path) => {
            // Write to a temporary file first, so a failure leaves no partial output.
            let tmp = path.with_extension("csv.partial");
            std::fs::write(&tmp, text).map_err(|e| anyhow!("{}: {e}", tmp.display()))?;
            std::fs::rename(&tmp, path).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        }
        None => std::io::stdout().write_all(text.as_bytes())?,
    }
    Ok(Outcome::Success)
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
/// series has no sample. Every digit is kept (shortest round-trip representation).
fn csv(data: &Data, step: f64) -> String {
    let columns: Vec<(String, Vec<(f64, f64)>)> = data
        .series
        .iter()
        .map(|s| {
            let points = match (&s.samples, data.record) {
                (Samples::Points { times, values }, _) => {
                    times.iter().copied().zip(values.iter().copied()).collect()
                }
                (Samples::Function(f), Record::Continuous { t_lo, t_hi }) => {
                    let n = ((t_hi - t_lo) / step).round() as usize;
                    (0..=n)
                        .map(|i| t_lo + (t_hi - t_lo) * i as f64 / n as f64)
                        .map(|t| (t, f(t)))
                        .collect()
                }
                (Samples::Function(_), Record::Discrete) => Vec::new(),
            };
            (s.name.clone(), points)
        })
        .collect();
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
    out
}
