//! The measurement tables: each row's experiment (its conditions), output and sample, and
//! the experiments that are one simulation merged.

use sysid_model::ModelError;
use sysid_model::table::Table;

use crate::observables::{Observable, placeholders};
use crate::parts::{Key, Measured, Output, Sample, Sigma, Simulation, condition_row};
use crate::tsv::{Cell, Tsv};
use crate::{Builder, at};

/// The largest measurement the importer takes: no measured quantity is that large in any
/// unit, and the weighted square of a larger one overflows for σ below about 1e-4.
pub(crate) const MAX_MEASUREMENT: f64 = 1e150;

/// The largest |measurement|/σ a known σ allows: beyond it the weighted square overflows.
pub(crate) const MAX_WEIGHTED: f64 = 1.3e154;

impl Builder<'_> {
    /// The outputs and the experiments' measurements, from the measurement table.
    pub(crate) fn measured(&self, states: &[String]) -> Result<Measured, ModelError> {
        let mut measured = Measured::default();
        for t in &self.tables.measurements {
            for row in 0..t.rows.len() {
                self.measurement(t, row, states, &mut measured)?;
            }
        }
        if measured.experiments.is_empty() {
            return Err(ModelError::file(&self.tables.measurements[0].file, "no measurements"));
        }
        let used: Vec<&str> = measured.outputs.iter().map(|o| o.observable.as_str()).collect();
        self.check_unused_observables(&used, states)?;
        Ok(measured)
    }

    /// One experiment for the conditions that set the same values after the same
    /// preequilibration (the same settings, to the text of the model file): they are one
    /// simulation, integrated once, and their measurements are its data. Bachmann's 36
    /// conditions are 12 simulations. The experiment keeps the first condition's name and
    /// answers to the others' (`also`). Returns the experiments, each with what it sets
    /// (the model file's text is written from it), and their names.
    pub(crate) fn merge_same_simulations(
        &self,
        measured: Measured,
        parameters: &[String],
        states: &[String],
    ) -> Result<(Measured, Vec<String>), ModelError> {
        let names = experiment_names(&measured.experiments);
        let mut merged = Measured { outputs: measured.outputs, ..Measured::default() };
        let mut kept = Vec::new();
        for ((key, samples), name) in measured.experiments.into_iter().zip(names) {
            let Key { pre, sim, steady } = &key;
            let simulation = Simulation {
                settings: self.condition_settings(sim, parameters, states, pre.as_deref())?,
                preequilibrate: match pre {
                    Some(p) => Some(self.condition_settings(p, parameters, states, None)?.0),
                    None => None,
                },
                steady: *steady,
                also: Vec::new(),
            };
            let same = |s: &Simulation| {
                (&s.settings, &s.preequilibrate, s.steady)
                    == (&simulation.settings, &simulation.preequilibrate, simulation.steady)
            };
            match merged.simulations.iter().position(same) {
                Some(i) => {
                    merged.experiments[i].1.extend(samples);
                    merged.simulations[i].also.push(name);
                }
                None => {
                    merged.experiments.push((key, samples));
                    merged.simulations.push(simulation);
                    kept.push(name);
                }
            }
        }
        Ok((merged, kept))
    }

    /// Reads row `row` of a measurement table into `measured`: its experiment (conditions),
    /// its output (the observable with this row's parameters) and its time and value.
    pub(crate) fn measurement(
        &self,
        t: &Tsv,
        row: usize,
        states: &[String],
        measured: &mut Measured,
    ) -> Result<(), ModelError> {
        let known_condition = |c: Cell<'_>| -> Result<String, ModelError> {
            match self.tables.conditions.iter().any(|ct| condition_row(ct, c.text).is_some()) {
                true => Ok(c.text.to_string()),
                false => {
                    Err(c.err(format!("condition `{}` is not in the condition table", c.text)))
                }
            }
        };
        let pre = match t.cell_named(row, "preequilibrationConditionId") {
            Some(c) if !c.is_blank() => Some(known_condition(c)?),
            _ => None,
        };
        let oc = t.cell(row, t.required("observableId")?);
        let observable = self
            .observables
            .get(oc.text)
            .ok_or_else(|| oc.err(format!("`{}` is not in the observable table", oc.text)))?;
        let simulation = known_condition(t.cell(row, t.required("simulationConditionId")?))?;
        let time_cell = t.cell(row, t.required("time")?);
        let mut time = time_cell.number()?;
        let (mut pre, mut steady) = (pre, false);
        if time == f64::INFINITY {
            // At steady state: an experiment of its own, measured at once, that starts from
            // the steady state under its condition: a preequilibration under its own
            // condition, or after its preequilibration, its own steady state from there.
            match pre {
                Some(_) => steady = true,
                None => pre = Some(simulation.clone()),
            }
            time = 0.0;
        }
        if time < 0.0 {
            return Err(time_cell.err(format!("time {time} is before the experiment starts at 0")));
        }
        if pre.is_some()
            && let Some(event) = self.sbml.events.first()
        {
            let c = t.cell_named(row, "preequilibrationConditionId").unwrap_or(time_cell);
            return Err(c.err(format!(
                "a preequilibration (or a steady state) in a model with events (event `{}`) is not supported",
                event.id
            )));
        }
        let value_cell = t.cell(row, t.required("measurement")?);
        let value = value_cell.number()?;
        if !value.is_finite() {
            return Err(value_cell.err("the measurement is not finite"));
        }
        if value.abs() > MAX_MEASUREMENT {
            return Err(value_cell.err(format!(
                "{value:e} is larger than any measured quantity (the largest magnitude taken is {MAX_MEASUREMENT:e}, beyond which a weighted square overflows for σ below about 1e-4; a unit slip?)"
            )));
        }
        if observable.transform != "lin" && value <= 0.0 {
            return Err(value_cell.err(format!(
                "{value} is not positive, and `{}` is measured on the {} scale",
                oc.text, observable.transform
            )));
        }
        let cell_text = |column: &str| t.cell_named(row, column).map_or("", |c| c.text).to_string();
        let read_key =
            [oc.text.to_string(), cell_text("observableParameters"), cell_text("noiseParameters")];
        let index = match measured.read.get(&read_key) {
            Some(&index) => index,
            None => {
                let output = self.output(t, row, oc, observable, states)?;
                let outputs = &mut measured.outputs;
                let index = match outputs.iter().position(|o| o == &output) {
                    Some(i) => i,
                    None => {
                        outputs.push(output);
                        outputs.len() - 1
                    }
                };
                measured.read.insert(read_key, index);
                index
            }
        };
        let output = &measured.outputs[index];
        if let Sigma::Number(v) = output.sigma
            && output.transform == "lin"
            && value.abs() / v > MAX_WEIGHTED
        {
            return Err(value_cell.err(format!(
                "{value:e} is too large for least squares with σ = {v:e}: its weighted square overflows (the largest usable magnitude is {MAX_WEIGHTED:.1e}·σ)"
            )));
        }
        let key = Key { pre, sim: simulation, steady };
        match measured.experiments.iter_mut().find(|e| e.0 == key) {
            Some(e) => e.1.push((time, index, value)),
            None => measured.experiments.push((key, vec![(time, index, value)])),
        }
        Ok(())
    }

    /// The output row `row` measures: observable `oc` with the row's observable and noise
    /// parameters in place of its placeholders, its σ a number or an expression.
    fn output(
        &self,
        t: &Tsv,
        row: usize,
        oc: Cell<'_>,
        observable: &Observable,
        states: &[String],
    ) -> Result<Output, ModelError> {
        let [formula, noise] =
            placeholders(t, row, oc, [&observable.formula, &observable.noise], "observable")?;
        let [noise] = placeholders(t, row, oc, [&noise], "noise")?;
        // The row's cells that filled the placeholders: the noise formula may hold the
        // observable's parameters too.
        let (given, noise_given) =
            (t.cell_named(row, "observableParameters"), t.cell_named(row, "noiseParameters"));
        let value_cells: Vec<Cell<'_>> = given.into_iter().collect();
        let noise_cells: Vec<Cell<'_>> = noise_given.into_iter().chain(given).collect();
        let written = (&observable.formula, &observable.formula_at, &value_cells[..]);
        let value_math = self.resolve_names(&self.dynamic(&formula), oc, states, None, written)?;
        let written = (&observable.noise, &observable.noise_at, &noise_cells[..]);
        let noise_math =
            self.resolve_names(&self.dynamic(&noise), oc, states, Some(oc.text), written)?;
        Ok(Output {
            observable: oc.text.to_string(),
            value: value_math,
            sigma: match noise_math.number() {
                Some(v) if sysid_model::file::check_sigma(v).is_ok() => Sigma::Number(v),
                Some(v) => {
                    let problem = sysid_model::file::check_sigma(v).err().unwrap_or_default();
                    let message = format!("σ of `{}` {problem}", oc.text);
                    let placeholder =
                        observable.noise.names().iter().any(|n| n.starts_with("noiseParameter"));
                    return Err(match (placeholder, t.cell_named(row, "noiseParameters")) {
                        (true, Some(c)) => c.err(message),
                        _ => at(&observable.noise_at, message),
                    });
                }
                None => Sigma::Expression(noise_math),
            },
            transform: observable.transform,
            distribution: observable.distribution,
        })
    }
}

/// Each experiment's name: its simulation condition's, and its preequilibration's too
/// where one simulation condition follows several (`SIM-after-PRE`, `SIM-steady` for the
/// steady-state measurements of SIM, `SIM-steady-after-PRE` for those after PRE).
pub(crate) fn experiment_names(experiments: &[(Key, Vec<Sample>)]) -> Vec<String> {
    experiments
        .iter()
        .map(|(Key { pre, sim, steady }, _)| {
            match (pre, *steady, experiments.iter().filter(|e| &e.0.sim == sim).count()) {
                (Some(pre), true, 2..) => format!("{sim}-steady-after-{pre}"),
                (Some(pre), false, 2..) if pre == sim => format!("{sim}-steady"),
                (Some(pre), false, 2..) => format!("{sim}-after-{pre}"),
                _ => sim.clone(),
            }
        })
        .collect()
}

/// An experiment's measurements as the data table its model-file experiment reads: the time
/// and a column per output it measures, a row per measurement (replicates repeat a time).
pub(crate) fn data_table(
    spec: &sysid_model::ExperimentSpec,
    rows: &[Sample],
    output_names: &[String],
) -> Result<Table, ModelError> {
    let mut columns: Vec<usize> = rows.iter().map(|r| r.1).collect();
    columns.sort_unstable();
    columns.dedup();
    let mut headers = vec!["t".to_string()];
    headers.extend(columns.iter().map(|&c| output_names[c].clone()));
    let table_rows = rows
        .iter()
        .map(|&(time, output, value)| {
            let mut cells = vec![None; columns.len()];
            cells[columns.iter().position(|&c| c == output).expect("listed")] = Some(value);
            (time, cells)
        })
        .collect();
    let source = spec.file.display().to_string();
    Table::from_rows(&source, headers, table_rows).map_err(|e| {
        ModelError::file(&source, format!("experiment `{}`: {}", spec.name, e.message))
    })
}
