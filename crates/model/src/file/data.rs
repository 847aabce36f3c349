//! The `[data]` table: the data file, t0, the kind of record and the weights.

use std::path::Path;

use super::document::Node;

use super::reader::Reader;
use super::{DataSpec, RecordKind};
use crate::error::ModelError;

/// Reads `[data]` (optional): the data file, relative to the model file at `path`, t0, the
/// kind of record and the weights; refuses other keys.
pub(super) fn read_data(
    r: &Reader<'_>,
    value: Option<&Node>,
    path: &Path,
) -> Result<DataSpec, ModelError> {
    let mut spec = DataSpec {
        file: None,
        t0: 0.0,
        t0_at: None,
        record: RecordKind::Discrete,
        weights: Vec::new(),
    };
    let Some(value) = value else {
        return Ok(spec);
    };
    for (key, value) in r.table(value, "[data]")?.iter() {
        match key.name.as_str() {
            "file" => {
                let f = r.string(value, "[data] file")?;
                let base = path.parent().unwrap_or(Path::new(""));
                spec.file = Some(base.join(f));
            }
            "t0" => {
                spec.t0 = r.number(value, "[data] t0")?;
                spec.t0_at = Some(value.at);
            }
            "record" => spec.record = read_record(r, value)?,
            "weights" => spec.weights = read_weights(r, value)?,
            other => {
                return Err(r.err(
                    key.at,
                    format!("unknown key `{other}` in [data] (keys: file, t0, record, weights)"),
                ));
            }
        }
    }
    Ok(spec)
}

/// Reads `[data] record`: "discrete" or "continuous".
fn read_record(r: &Reader<'_>, value: &Node) -> Result<RecordKind, ModelError> {
    match r.string(value, "[data] record")? {
        "discrete" => Ok(RecordKind::Discrete),
        "continuous" => Ok(RecordKind::Continuous),
        other => Err(r.err(
            value.at,
            format!("[data] record must be \"discrete\" or \"continuous\", got \"{other}\""),
        )),
    }
}

/// Reads `[data.weights]`: a positive number per column, with the offset of the column's
/// name (the data file, read later, says whether it is measured).
fn read_weights(r: &Reader<'_>, value: &Node) -> Result<Vec<(String, f64, usize)>, ModelError> {
    let mut weights = Vec::new();
    for (k, w) in r.table(value, "[data.weights]")?.iter() {
        let weight = r.number(w, &format!("[data.weights] {}", k.name))?;
        if weight <= 0.0 {
            return Err(
                r.err(w.at, format!("[data.weights] {} must be positive, got {weight}", k.name))
            );
        }
        // Weights are relative: one may be as small as a float holds beside others (the
        // data file's check refuses them all tiny), and one as large as a float holds where
        // its measured values' weighted squares do not overflow (checked at each value).
        weights.push((k.name.to_string(), weight, k.at));
    }
    Ok(weights)
}
