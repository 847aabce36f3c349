//! A data file (CSV) read against a model: measured series and input signals.

use std::path::Path;

use crate::table::{Table, TableError, cell_position, without_bom};
use sysid_core::{Data, Noise, Transform};
use sysid_ode::{Inputs, Signal};

use crate::error::ModelError;
use crate::file::{ModelFile, NoiseSpec, RecordKind};

/// The measurements and input signals of a data file.
pub struct ModelData {
    /// The measured series.
    pub data: Data,
    /// The input signals, in the model's input order.
    pub inputs: Inputs,
    /// Number of rows.
    pub rows: usize,
    /// The series whose σ is an expression, with their output's index: the problem gives
    /// them their noise function.
    pub modelled: Vec<(usize, usize)>,
}

/// Where the initial values of a data file's experiment are given: t0, and where it is
/// written (for the error of data before it).
#[derive(Clone, Copy, Debug)]
pub struct Start<'a> {
    /// Time of the initial values.
    pub t0: f64,
    /// Byte offset of the `t0` value in the model file, if given.
    pub at: Option<usize>,
    /// Which table gives it: "`[data]`" or "experiment `low`".
    pub table: &'a str,
    /// What names the data file, for an error that cannot read it: "that `[data] file` in
    /// m.toml names", "given by --data".
    pub named_by: &'a str,
}

/// The largest weighted magnitude whose square an f64 holds: a value beyond it makes the
/// cost infinite whatever the model predicts.
const LARGEST: f64 = 1.3e154;

/// Refuses a measured value whose weighted square overflows, at its cell.
fn overflow(table: &Table, text: &str, name: &str, weight: f64) -> Result<(), ModelError> {
    let field = 1 + table.names().iter().position(|n| n == name).expect("a column");
    let cells = table.column(name).expect("a column");
    match cells.iter().position(|v| v.is_some_and(|v| v.abs() * weight.sqrt() > LARGEST)) {
        None => Ok(()),
        Some(row) => {
            let line = table.line(row);
            Err(ModelError {
                file: table.source().to_string(),
                line: line.map(|l| l as usize),
                column: line.and_then(|l| cell_position(text, l, field)),
                message: format!(
                    "column `{name}`: {:e} is too large for least squares: its weighted square overflows (the largest usable magnitude is {LARGEST:.1e}/√w, w = {})",
                    cells[row].unwrap_or_default(),
                    sysid_core::format::shortest(weight)
                ),
            })
        }
    }
}

fn table_error(e: TableError) -> ModelError {
    ModelError {
        file: e.source,
        line: e.line.map(|l| l as usize),
        column: e.position,
        message: match e.column {
            Some(c) => format!("column `{c}`: {}", e.message),
            None => e.message,
        },
    }
}

/// Reads `path` against `model`: the time column first (named `t` or `time`), then columns
/// named after states, outputs or inputs; empty cells are missing values. A leading
/// byte-order mark is skipped.
pub fn read(model: &ModelFile, path: &Path) -> Result<ModelData, ModelError> {
    let named_by = format!("that `[data] file` in {} names", model.path.display());
    let start =
        Start { t0: model.data.t0, at: model.data.t0_at, table: "[data]", named_by: &named_by };
    read_from(model, path, start)
}

/// Reads `path` against `model` as [`read`] does, for an experiment starting at `start`.
pub fn read_from(
    model: &ModelFile,
    path: &Path,
    start: Start<'_>,
) -> Result<ModelData, ModelError> {
    let file = path.display().to_string();
    let held = model.tables.iter().find(|(p, _)| p == path).map(|(_, t)| t.clone());
    let (text, table) = match held {
        Some(table) => (String::new(), table),
        None => {
            let text = std::fs::read_to_string(path).map_err(|e| {
                ModelError::file(&file, format!("{e}: the data file {}", start.named_by))
            })?;
            let text = without_bom(&text).to_string();
            check_time_column(&text, &file)?;
            let table = Table::parse(&text, &file).map_err(table_error)?;
            (text, table)
        }
    };
    let text = text.as_str();
    check_columns(model, &table, &file)?;
    check_weights(model, &table, &file)?;
    let signals = input_signals(model, &table, &file)?;
    let (data, modelled) = measured_series(model, &table, text, &file)?;
    check_start(model, &table, text, start)?;
    Ok(ModelData { data, inputs: Inputs::new(signals), rows: table.time().len(), modelled })
}

/// Whether a column is measured: it names a state or an output.
fn measurable(model: &ModelFile, name: &str) -> bool {
    model.states.iter().any(|s| s == name) || model.outputs.iter().any(|o| o.name == name)
}

/// Whether a column holds the σ of an output (`sigma = { column = "NAME" }`).
fn sigma_column(model: &ModelFile, name: &str) -> bool {
    model.outputs.iter().any(|o| matches!(&o.noise, NoiseSpec::Column(c) if c == name))
}

/// Checks the first column's name is `t` or `time`, before its values are read as times.
fn check_time_column(text: &str, file: &str) -> Result<(), ModelError> {
    let refuse = |message: String| ModelError {
        file: file.to_string(),
        line: Some(1),
        column: None,
        message,
    };
    if text.trim().is_empty() {
        return Err(refuse(
            "the file is empty: its first row must name the columns, the time first (`t` or `time`)"
                .into(),
        ));
    }
    // The header as the table reads it, so that a quoted name (`"t","x"`, as R's write.csv
    // writes it) is its name; a header the reader refuses is the table's to report.
    let mut reader = csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(text.as_bytes());
    let Ok(header) = reader.headers() else { return Ok(()) };
    let time = header.get(0).unwrap_or_default();
    if !time.eq_ignore_ascii_case("t") && !time.eq_ignore_ascii_case("time") {
        return Err(refuse(format!(
            "the first column must be the time, named `t` or `time`; found `{time}`"
        )));
    }
    Ok(())
}

/// Checks every column names a state, an output, an input or an output's σ.
fn check_columns(model: &ModelFile, table: &Table, file: &str) -> Result<(), ModelError> {
    let outputs: Vec<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
    for name in table.names() {
        if !measurable(model, name)
            && !model.inputs.iter().any(|i| i == name)
            && !sigma_column(model, name)
        {
            return Err(ModelError {
                file: file.to_string(),
                line: Some(1),
                column: None,
                message: format!(
                    "column `{name}` names nothing in the model (states: {}; outputs: {}; inputs: {})",
                    model.states.join(", "),
                    if outputs.is_empty() { "none".into() } else { outputs.join(", ") },
                    if model.inputs.is_empty() { "none".into() } else { model.inputs.join(", ") }
                ),
            });
        }
    }
    Ok(())
}

/// Checks each `[data.weights]` entry weights a measured column of the table, locating a
/// wrong one in the model file.
fn check_weights(model: &ModelFile, table: &Table, file: &str) -> Result<(), ModelError> {
    for (name, _, at) in &model.data.weights {
        if !table.names().iter().any(|n| n == name) || !measurable(model, name) {
            return Err(model
                .err(*at, format!("[data.weights]: `{name}` is not a measured column of {file}")));
        }
    }
    // Relative weights all below 1e-300: ε and the normal matrix underflow (1e-320 alone was
    // fitted to nothing and reported an exact fit with standard errors 0).
    let weighted = table.names().iter().filter(|n| {
        measurable(model, n)
            && model.outputs.iter().all(|o| o.name != **n || matches!(o.noise, NoiseSpec::Weights))
    });
    // Each weighted column's weight and where it is given (none: 1, from nowhere).
    let weight_of =
        |n: &String| model.data.weights.iter().find(|w| &w.0 == n).map_or((1.0, 0), |w| (w.1, w.2));
    let largest = weighted.map(weight_of).max_by(|a, b| a.0.total_cmp(&b.0));
    let least = crate::file::LEAST_WEIGHT;
    if let Some((largest, at)) = largest.filter(|w| w.0 < least) {
        return Err(model.err(
            at,
            format!(
                "[data.weights]: the largest weight, {largest:e}, is below {least:e}: ε and its derivatives underflow (relative weights may be scaled up together, which changes no estimate or standard error; beside a noise model they are 1/σ², a σ above 1e150)"
            ),
        ));
    }
    Ok(())
}

/// The input signals, in the model's input order, each from its column.
fn input_signals(model: &ModelFile, table: &Table, file: &str) -> Result<Vec<Signal>, ModelError> {
    model
        .inputs
        .iter()
        .map(|name| {
            let (times, values) = table.samples(name).ok_or_else(|| {
                ModelError::file(
                    file,
                    format!(
                        "input `{name}` has no column (the inputs are read from the data file)"
                    ),
                )
            })?;
            Signal::new(times, values, model.input_mode)
                .map_err(|e| ModelError::file(file, format!("input `{name}`: {e}")))
        })
        .collect()
}

/// Refuses data before t0, at the first such sample: the initial values are given at t0 and
/// the model is integrated forward from there. (A continuous record spans every row, so
/// its first row must not lie before t0 either, measured or not.)
fn check_start(
    model: &ModelFile,
    table: &Table,
    text: &str,
    start: Start<'_>,
) -> Result<(), ModelError> {
    let t0 = start.t0;
    let continuous = model.data.record == RecordKind::Continuous;
    let measured: Vec<&String> = table.names().iter().filter(|n| measurable(model, n)).collect();
    for (row, &t) in table.time().iter().enumerate().take_while(|(_, t)| **t < t0) {
        let column = measured
            .iter()
            .position(|n| table.column(n).expect("a column")[row].is_some())
            .map(|c| measured[c].as_str());
        let (name, what) = match column {
            Some(name) => (name, "a sample"),
            None if continuous => (table.time_name(), "the continuous record"),
            None => continue,
        };
        let field = table.names().iter().position(|n| n == name).map_or(0, |i| i + 1);
        let t0_in = match start.at {
            Some(at) => {
                let e = model.err(at, "");
                match (e.line, e.column) {
                    (Some(line), Some(column)) => format!("{}:{line}:{column}", e.file),
                    _ => e.file,
                }
            }
            None => format!("the default: {} has no {} t0", model.path.display(), start.table),
        };
        let line = table.line(row);
        return Err(ModelError {
            file: table.source().to_string(),
            line: line.map(|l| l as usize),
            column: line.and_then(|l| cell_position(text, l, field)),
            message: format!(
                "column `{name}`: {what} at t = {} lies before t0 = {} ({t0_in}), the time of the initial values: the data must start at t0 or later",
                sysid_core::format::shortest(t),
                sysid_core::format::shortest(t0)
            ),
        });
    }
    Ok(())
}

/// An error at a cell of the table: column `name`, row `row`.
fn at_cell(table: &Table, text: &str, name: &str, row: usize, message: String) -> ModelError {
    let field = 1 + table.names().iter().position(|n| n == name).unwrap_or(0);
    let line = table.line(row);
    ModelError {
        file: table.source().to_string(),
        line: line.map(|l| l as usize),
        column: line.and_then(|l| cell_position(text, l, field)),
        message,
    }
}

/// The measured series in column order, weighted or with their noise models; at least one,
/// none empty, none overflowing; and the series whose σ is an expression.
fn measured_series(
    model: &ModelFile,
    table: &Table,
    text: &str,
    file: &str,
) -> Result<(Data, Vec<(usize, usize)>), ModelError> {
    let times = table.time();
    let mut data = match model.data.record {
        RecordKind::Discrete => Data::discrete(),
        RecordKind::Continuous => Data::continuous(times[0], times[times.len() - 1]),
    };
    let mut modelled = Vec::new();
    for name in table.names().iter().filter(|n| measurable(model, n)) {
        let (t, v) = table.samples(name).expect("a column of the table");
        if t.is_empty() {
            return Err(ModelError::file(file, format!("column `{name}` has no values")));
        }
        let output = model.outputs.iter().position(|o| &o.name == name);
        let (noise, transform) = output
            .map(|o| (&model.outputs[o].noise, model.outputs[o].transform))
            .unwrap_or((&NoiseSpec::Weights, Transform::Lin));
        let cells = table.column(name).expect("a column");
        let rows: Vec<usize> = (0..cells.len()).filter(|&i| cells[i].is_some()).collect();
        if transform != Transform::Lin
            && let Some(&row) = rows.iter().find(|&&i| cells[i].is_some_and(|v| v <= 0.0))
        {
            return Err(at_cell(
                table,
                text,
                name,
                row,
                format!(
                    "column `{name}`: {} is not positive, and `{name}` is measured on the {} scale",
                    cells[row].unwrap_or_default(),
                    transform.name()
                ),
            ));
        }
        let noise = match noise {
            NoiseSpec::Weights => {
                let weight = model.data.weights.iter().find(|w| &w.0 == name).map_or(1.0, |w| w.1);
                overflow(table, text, name, weight)?;
                data = data.weighted_series(name, weight, &t, &v);
                continue;
            }
            NoiseSpec::Number(sigma) => Noise::Known(vec![*sigma; t.len()]),
            NoiseSpec::Column(column) => {
                let sigmas = table.column(column).ok_or_else(|| {
                    ModelError::file(
                        file,
                        format!(
                            "`{name}` takes its σ from column `{column}`, which this file lacks"
                        ),
                    )
                })?;
                let mut list = Vec::with_capacity(rows.len());
                for &row in &rows {
                    let checked = match sigmas[row] {
                        Some(s) => crate::file::check_sigma(s).map(|()| s),
                        None => {
                            Err("must be a positive number where it is measured, got an empty cell"
                                .into())
                        }
                    };
                    match checked {
                        Ok(s) => list.push(s),
                        Err(m) => {
                            return Err(at_cell(
                                table,
                                text,
                                column,
                                row,
                                format!(
                                    "column `{column}`: the σ of `{name}` at t = {} {m}",
                                    times[row]
                                ),
                            ));
                        }
                    }
                }
                Noise::Known(list)
            }
            NoiseSpec::Expression(_) => {
                modelled.push((data.series.len(), output.expect("an output has the expression")));
                Noise::Known(vec![1.0; t.len()])
            }
        };
        // A known σ (a number or a column); an expression's is known only in the fit.
        let known = matches!(
            output.map(|o| &model.outputs[o].noise),
            Some(NoiseSpec::Number(_) | NoiseSpec::Column(_))
        );
        if let (Noise::Known(sigmas), Transform::Lin, true) = (&noise, transform, known) {
            for (&row, sigma) in rows.iter().zip(sigmas) {
                let value = cells[row].unwrap_or_default();
                if value.abs() / sigma > LARGEST {
                    return Err(at_cell(
                        table,
                        text,
                        name,
                        row,
                        format!(
                            "column `{name}`: {value:e} is too large for least squares with σ = {sigma:e}: its weighted square overflows (the largest usable magnitude is {LARGEST:.1e}·σ)"
                        ),
                    ));
                }
            }
        }
        data = data.series_with_noise(name, &t, &v, noise, transform);
        if let (Some(o), Some(series)) = (output, data.series.last_mut()) {
            series.distribution = model.outputs[o].distribution;
        }
    }
    if data.series.is_empty() {
        return Err(ModelError::file(
            file,
            "no measured column: name columns after states or outputs",
        ));
    }
    Ok((data, modelled))
}
