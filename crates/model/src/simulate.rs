//! What `sysid simulate` writes: a model's trajectory at chosen values, and a data set, as
//! CSV (a header row, time first, every digit kept; exponent form outside [1e-4, 1e9), so
//! that 1e-60 is not sixty zeros).

use std::path::Path;

use sysid_core::format::shortest;
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

/// `t`, one of times spaced `h` apart, as a person wrote it ([`decimal`]) where that moves it
/// by at most a millionth of `h`; else `t` itself: 1.7e9 + 1e-6 is not 1.7e9, and distinct
/// times stay distinct.
pub fn decimal_within(t: f64, h: f64) -> f64 {
    match decimal(t) {
        d if (d - t).abs() <= 1e-6 * h => d,
        _ => t,
    }
}

impl Model {
    /// The model's states and outputs at `times` (from each experiment's t0), as CSV, with
    /// every unknown at its guess unless `set` gives it (or a known value, or an initial
    /// value) another; inputs from each experiment's data file (`data` instead of a single
    /// experiment's). `experiment` picks one experiment; with several, a first column names
    /// the experiment of each row.
    pub fn simulate(
        &self,
        set: &[(String, f64)],
        data: Option<&Path>,
        times: &[f64],
        experiment: Option<&str>,
    ) -> Result<String, ModelError> {
        let path = self.file.path.display().to_string();
        let f = &self.file;
        // Experiments, inputs, initial values by expressions and unknowns of their own need
        // the problem (its data files); a plain model is simulated from its values alone.
        let plain = f.experiments.is_empty()
            && f.inputs.is_empty()
            && f.initial.is_empty()
            && f.extras.is_empty();
        let runs = if plain {
            if let Some(name) = experiment.filter(|&n| n != sysid_core::plan::SINGLE_EXPERIMENT) {
                return Err(ModelError::file(
                    &path,
                    format!(
                        "--experiment {name}: no such experiment (experiments: {})",
                        sysid_core::plan::SINGLE_EXPERIMENT
                    ),
                ));
            }
            let mut v = Vec::new();
            let known = f.known.iter().map(|(n, v)| (n, *v));
            for (name, value) in known.chain(f.unknowns.iter().map(|u| (&u.name, u.guess))) {
                v.push((name.clone(), value));
            }
            // A plain model's initial values are all its own: each is its state's size.
            let (y0, p) = self.point_from(&v)?;
            vec![(
                sysid_core::plan::SINGLE_EXPERIMENT.to_string(),
                self.system(Inputs::default()),
                f.data.t0,
                y0.clone(),
                (y0, p),
            )]
        } else {
            let problem = self.problem(data)?;
            let mut values: Vec<f64> = problem.declared().iter().map(|u| u.guess).collect();
            for (name, value) in set {
                if let Some(j) = problem.declared().iter().position(|u| &u.name == name) {
                    values[j] = *value;
                }
            }
            if let Some(name) = experiment
                && !problem.experiments().iter().any(|e| e.answers_to(name))
            {
                let names: Vec<&str> = problem.experiments().iter().map(|e| e.name()).collect();
                return Err(ModelError::file(
                    &path,
                    format!(
                        "--experiment {name}: no such experiment (experiments: {})",
                        names.join(", ")
                    ),
                ));
            }
            // An experiment's own setting of a parameter is its condition: `--set dose=3` was
            // ignored where the experiments set the dose, and `--set scale=2` overrode the
            // setting of one that set it; neither is a trajectory of the file's experiment.
            // (A preequilibration's settings hold before t0 only: the experiment runs on the
            // value given here.) Its own initial values likewise.
            for (name, _) in set {
                let sets = |x: &crate::file::ExperimentSpec| {
                    x.set.iter().chain(&x.initial).any(|(n, ..)| n == name)
                };
                let mut chosen = f.experiments.iter().filter(|x| {
                    experiment.is_none_or(|n| x.name == n || x.also.iter().any(|a| a == n))
                });
                if let Some(x) = chosen.find(|x| sets(x)) {
                    return Err(ModelError::file(
                        &path,
                        format!(
                            "--set {name}: experiment `{}` sets `{name}` itself (its condition, in its `set` or `initial`); change it there, or simulate the others with --experiment",
                            x.name
                        ),
                    ));
                }
            }
            problem
                .experiments()
                .iter()
                .filter(|e| experiment.is_none_or(|n| e.answers_to(n)))
                .map(|e| {
                    let (y0, p) = e.point(&values);
                    (e.name().to_string(), e.system().clone(), e.t0(), e.sizes(&y0), (y0, p))
                })
                .collect()
        };
        let several = runs.len() > 1;
        let mut text = String::new();
        // The states' sizes for their tolerances: their initial values, but for a steady
        // state's ([`Planned::sizes`](sysid_core::Planned::sizes)); a value `--set` gives is
        // given too.
        for (name, system, t0, mut sizes, (mut y0, mut p)) in runs {
            let sig = system.signature().clone();
            for (key, value) in set {
                match (sig.state(key), sig.parameter(key)) {
                    (Some(i), _) => (y0[i], sizes[i]) = (*value, *value),
                    (None, Some(k)) => p[k] = *value,
                    (None, None) if f.unknowns.iter().any(|u| &u.name == key) => {}
                    (None, None) => {
                        let message =
                            format!("--set: `{key}` is not a state, parameter or unknown");
                        return Err(ModelError::file(&path, message));
                    }
                }
            }
            // A trajectory runs forward from its t0 (data before it are refused as well):
            // earlier times were integrated backwards, to negative concentrations, or failed
            // with a blow-up that did not say the times began before t0.
            if let Some(first) = times.iter().copied().find(|&t| t < t0) {
                let whose = match several || name != sysid_core::plan::SINGLE_EXPERIMENT {
                    true => format!("experiment `{name}`'s"),
                    false => "the model's".into(),
                };
                return Err(ModelError::file(
                    &path,
                    format!(
                        "--times: {first} is before {whose} t0 = {t0}: a trajectory runs forward from t0"
                    ),
                ));
            }
            let sol = Ivp::new(&system, t0, &y0, &p)
                .sized(&sizes)
                .solve(&f.integrator, times)
                .map_err(|e| ModelError::file(&path, format!("cannot be simulated: {e}")))?;
            if text.is_empty() {
                text += if several { "experiment,t" } else { "t" };
                for n in sig.states().iter().chain(sig.outputs()) {
                    text += &format!(",{n}");
                }
                text += "\n";
            }
            let mut h = vec![0.0; sig.outputs().len()];
            let mut u = vec![0.0; sig.n_inputs()];
            for (m, &t) in times.iter().enumerate() {
                if several {
                    text += &format!("{name},");
                }
                text += &shortest(t);
                for v in sol.state(m) {
                    text += &format!(",{}", shortest(*v));
                }
                if !h.is_empty() {
                    system.input_values(t, Side::After, &mut u);
                    system.outputs(t, sol.state(m), &p, &u, &mut h);
                    for v in &h {
                        text += &format!(",{}", shortest(*v));
                    }
                }
                text += "\n";
            }
        }
        Ok(text)
    }

    /// y(t0) and α from values by name (every state and parameter given).
    fn point_from(&self, values: &[(String, f64)]) -> Result<(Vec<f64>, Vec<f64>), ModelError> {
        let f = &self.file;
        let find = |name: &str| values.iter().find(|(n, _)| n == name).map(|p| p.1);
        let y0 = f.states.iter().map(|s| find(s).unwrap_or(f64::NAN)).collect();
        let p = f.parameters.iter().map(|s| find(s).unwrap_or(f64::NAN)).collect();
        Ok((y0, p))
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
                (Samples::Function(f), Record::Continuous { t_lo, t_hi }) => {
                    let h = (t_hi - t_lo) / intervals.max(1) as f64;
                    (0..=intervals)
                        .map(|i| decimal_within(t_lo + h * i as f64, h))
                        .map(|t| (t, f(t)))
                        .collect()
                }
                (Samples::Function(_), Record::Discrete) => Vec::new(),
            };
            (s.name.as_str(), points)
        })
        .collect();
    let mut times: Vec<f64> = columns.iter().flat_map(|c| c.1.iter().map(|p| p.0)).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    // Printed as a person wrote them where that moves none by more than a millionth of the
    // closest two (a catalogue's grid 0.2·3 is 0.6; a file's 1700000000.000001 stays).
    let spacing = times.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let mut out = String::from("t");
    for (name, _) in &columns {
        out += &format!(",{name}");
    }
    out += "\n";
    let mut cursor = vec![0; columns.len()];
    for &t in &times {
        out += &shortest(if spacing.is_finite() { decimal_within(t, spacing) } else { t });
        for (c, (_, points)) in columns.iter().enumerate() {
            out += ",";
            if points.get(cursor[c]).is_some_and(|p| p.0.total_cmp(&t).is_eq()) {
                out += &shortest(points[cursor[c]].1);
                cursor[c] += 1;
            }
        }
        out += "\n";
    }
    out
}
