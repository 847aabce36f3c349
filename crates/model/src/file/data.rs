//! The `[data]` table: the data file, t0, the kind of record and the weights.

use std::path::Path;

use toml::de::DeTable;

use super::reader::Reader;
use super::{DataSpec, RecordKind};
use crate::error::ModelError;

/// Reads `[data]`; the file is relative to the model file at `path`.
pub(super) fn read_data(
    r: &Reader<'_>,
    t: &DeTable<'_>,
    path: &Path,
) -> Result<DataSpec, ModelError> {
    let mut spec =
        DataSpec { file: None, t0: 0.0, record: RecordKind::Discrete, weights: Vec::new() };
    for (key, value) in t.iter() {
        match key.get_ref().as_ref() {
            "file" => {
                let f = r.string(value, "[data] file")?;
                let base = path.parent().unwrap_or(Path::new(""));
                spec.file = Some(base.join(f));
            }
            "t0" => spec.t0 = r.number(value, "[data] t0")?,
            "record" => {
                spec.record = match r.string(value, "[data] record")? {
                    "discrete" => RecordKind::Discrete,
                    "continuous" => RecordKind::Continuous,
                    other => {
                        return Err(r.err(value.span().start, format!("[data] record must be \"discrete\" or \"continuous\", got \"{other}\"")));
                    }
                }
            }
            "weights" => {
                for (k, w) in r.table(value, "[data.weights]")?.iter() {
                    let weight = r.number(w, &format!("[data.weights] {}", k.get_ref()))?;
                    if weight <= 0.0 {
                        return Err(r.err(
                            w.span().start,
                            format!(
                                "[data.weights] {} must be positive, got {weight}",
                                k.get_ref()
                            ),
                        ));
                    }
                    spec.weights.push((k.get_ref().to_string(), weight, k.span().start));
                }
            }
            other => {
                return Err(r.err(
                    key.span().start,
                    format!("unknown key `{other}` in [data] (keys: file, t0, record, weights)"),
                ));
            }
        }
    }
    Ok(spec)
}
