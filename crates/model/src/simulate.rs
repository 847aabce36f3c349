//! What `sysid simulate` writes: a model's trajectory at chosen values, and a data set, as
//! CSV (a header row, time first, every digit kept).

use std::path::Path;

use sysid_core::{Data, Record, Samples};
use sysid_ode::{Inputs, Ivp, Side, System};

use crate::Model;
use crate::error::ModelError;

/// A time as a person wrote it: the float nearest to its 15-significant-digit decimal form,
/// so 3 × 0.1 prints as 0.3, not 0.30000000000000004 (a change below 5e-16 relative, under
/// the error of the arithmetic that made it).
pub fn decimal(t: f64) -> f64 {
    format!("{t:.14e}").parse().unwrap_or(t)
}

impl Model {
    /// The model's states and outputs at `times`, as CSV, with every unknown at its guess
    /// unless `set` gives it (or a known value) another; inputs from `data` or the model's
    /// data file (a model without inputs needs none).
    pub fn simulate(
        &self,
        set: &[(String, f64)],
        data: Option<&Path>,
        times: &[f64],
    ) -> Result<String, ModelError> {
        let path = self.file.path.display().to_string();
        let inputs = if self.file.inputs.is_empty() {
            Inputs::default()
        } else {
            let data = match data {
                Some(d) => d,
                None => self.data_path()?,
            };
            crate::data::read(&self.file, data)?.inputs
        };
        let system = self.system(inputs);
        let sig = system.signature().clone();
        let mut y0 = vec![f64::NAN; sig.n_states()];
        let mut p = vec![f64::NAN; sig.n_parameters()];
        let mut assign = |name: &str, value: f64| {
            match (sig.state(name), sig.parameter(name)) {
                (Some(i), _) => y0[i] = value,
                (None, Some(k)) => p[k] = value,
                (None, None) => {
                    let message = format!("--set: `{name}` is not a state or parameter");
                    return Err(ModelError::file(&path, message));
                }
            }
            Ok(())
        };
        let guesses = self.file.unknowns.iter().map(|u| (u.name.as_str(), u.guess));
        let known = self.file.known.iter().map(|(n, v)| (n.as_str(), *v));
        for (name, value) in known.chain(guesses).chain(set.iter().map(|(n, v)| (n.as_str(), *v))) {
            assign(name, value)?;
        }
        let sol = Ivp::new(&system, self.file.data.t0, &y0, &p)
            .solve(&self.file.integrator, times)
            .map_err(|e| ModelError::file(&path, format!("cannot be simulated: {e}")))?;
        let mut h = vec![0.0; sig.outputs().len()];
        let mut u = vec![0.0; sig.n_inputs()];
        let mut text = String::from("t");
        for name in sig.states().iter().chain(sig.outputs()) {
            text += &format!(",{name}");
        }
        text += "\n";
        for (m, &t) in times.iter().enumerate() {
            text += &format!("{}", decimal(t));
            for v in sol.state(m) {
                text += &format!(",{v}");
            }
            if !h.is_empty() {
                system.input_values(t, Side::After, &mut u);
                system.outputs(t, sol.state(m), &p, &u, &mut h);
                for v in &h {
                    text += &format!(",{v}");
                }
            }
            text += "\n";
        }
        Ok(text)
    }
}

/// `data` as CSV: a header row `t,<series...>`, one row per time, empty cells where a series
/// has no sample. A record given as a function is sampled at `intervals + 1` evenly spaced
/// times over its span.
pub fn data_csv(data: &Data, intervals: usize) -> String {
    let columns: Vec<(&str, Vec<(f64, f64)>)> = data
        .series
        .iter()
        .map(|s| {
            let points = match (&s.samples, data.record) {
                (Samples::Points { times, values }, _) => {
                    times.iter().copied().zip(values.iter().copied()).collect()
                }
                (Samples::Function(f), Record::Continuous { t_lo, t_hi }) => (0..=intervals)
                    .map(|i| t_lo + (t_hi - t_lo) * i as f64 / intervals.max(1) as f64)
                    .map(|t| (t, f(t)))
                    .collect(),
                (Samples::Function(_), Record::Discrete) => Vec::new(),
            };
            (s.name.as_str(), points)
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
    out
}
