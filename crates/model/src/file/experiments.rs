//! `[[experiments]]`: the conditions a model is fitted under, each with its own data file,
//! t0 and parameter settings.

use std::path::Path;

use super::document::{Node, Value};

use super::names::Scope;
use super::reader::Reader;
use super::{ExperimentSpec, SetValue};
use crate::error::ModelError;

/// Reads `[[experiments]]` (optional): an array of tables `{ name, file, t0, set,
/// preequilibrate, steady, initial, also }`.
pub(super) fn read_experiments(
    r: &Reader<'_>,
    value: Option<&Node>,
    path: &Path,
    scope: &Scope,
) -> Result<Vec<ExperimentSpec>, ModelError> {
    let Some(value) = value else {
        return Ok(Vec::new());
    };
    let Value::Array(items) = &value.value else {
        return Err(r.err(
            value.at,
            "`experiments` must be an array of tables: write each as [[experiments]]",
        ));
    };
    let mut out: Vec<ExperimentSpec> = Vec::with_capacity(items.len());
    for item in items {
        let table = r.table(item, "each [[experiments]]")?;
        let name_value = table
            .get("name")
            .ok_or_else(|| r.err(item.at, "[[experiments]]: an experiment needs `name`"))?;
        let name = r.string(name_value, "[[experiments]] name")?.to_string();
        let at = name_value.at;
        let valid = |name: &str| {
            !name.is_empty() && name.chars().all(|c| c.is_alphanumeric() || c == '_' || c == '-')
        };
        if !valid(&name) {
            return Err(
                r.err(at, format!("[[experiments]] name `{name}`: use letters, digits, _ and -"))
            );
        }
        if out.iter().any(|e| e.name == name || e.also.contains(&name)) {
            return Err(r.err(at, format!("[[experiments]]: two experiments are called `{name}`")));
        }
        let what = |key: &str| format!("experiment `{name}`: {key}");
        let file = table
            .get("file")
            .ok_or_else(|| r.err(item.at, what("`file` is missing: name its data file")))?;
        let base = path.parent().unwrap_or(Path::new(""));
        let file_path = base.join(r.string(file, &what("file"))?);
        let mut spec = ExperimentSpec {
            name: name.clone(),
            file: file_path,
            t0: 0.0,
            t0_at: None,
            set: Vec::new(),
            preequilibrate: None,
            steady: false,
            initial: Vec::new(),
            also: Vec::new(),
            at,
        };
        for (key, v) in table.iter() {
            match key.name.as_str() {
                "name" | "file" => {}
                "t0" => {
                    spec.t0 = r.number(v, &what("t0"))?;
                    spec.t0_at = Some(v.at);
                }
                "also" => {
                    let Value::Array(items) = &v.value else {
                        return Err(
                            r.err(v.at, what("also must be a list of names, like [\"a\", \"b\"]"))
                        );
                    };
                    for item in items {
                        let alias = r.string(item, &what("each entry of also"))?.to_string();
                        let at = item.at;
                        if !valid(&alias) {
                            return Err(r.err(
                                at,
                                what(&format!("also `{alias}`: use letters, digits, _ and -")),
                            ));
                        }
                        let taken = alias == name
                            || spec.also.contains(&alias)
                            || out.iter().any(|e| e.name == alias || e.also.contains(&alias));
                        if taken {
                            return Err(r.err(
                                at,
                                format!("[[experiments]]: two experiments are called `{alias}`"),
                            ));
                        }
                        spec.also.push(alias);
                    }
                }
                "steady" => {
                    let Value::Bool(steady) = &v.value else {
                        return Err(r.err(v.at, what("steady must be true or false")));
                    };
                    if *steady && !scope.inputs.is_empty() {
                        return Err(r.err(
                            v.at,
                            what("steady: a model with inputs has no steady state to run to"),
                        ));
                    }
                    spec.steady = *steady;
                }
                key @ ("set" | "preequilibrate" | "initial") => {
                    if key == "preequilibrate" && !scope.inputs.is_empty() {
                        return Err(r.err(
                            v.at,
                            what(
                                "preequilibrate: a model with inputs has no steady state to run to",
                            ),
                        ));
                    }
                    let mut list = Vec::new();
                    for (p, x) in r.table(v, &what(key))?.iter() {
                        let parameter = p.name.to_string();
                        if key == "initial" && !scope.states.contains(&parameter) {
                            return Err(r.err(
                                p.at,
                                format!(
                                    "experiment `{name}`: initial `{parameter}`: not a state (states: {})",
                                    scope.states.join(", ")
                                ),
                            ));
                        }
                        if key != "initial" && !scope.parameters.contains(&parameter) {
                            return Err(r.err(
                                p.at,
                                format!(
                                    "experiment `{name}`: {key} `{parameter}`: not a parameter (parameters: {})",
                                    scope.parameters.join(", ")
                                ),
                            ));
                        }
                        let key_what = what(&format!("{key} {parameter}"));
                        let value = match &x.value {
                            Value::String(_) | Value::Expr(_) => {
                                let resolve = |n: &str| scope.resolve_setting(n);
                                SetValue::Expression(r.expression_with_names(
                                    x,
                                    &key_what,
                                    &resolve,
                                    &scope.setting_names(),
                                )?)
                            }
                            _ => SetValue::Number(r.number(x, &key_what)?),
                        };
                        list.push((parameter, value, p.at));
                    }
                    match key {
                        "set" => spec.set = list,
                        "initial" => spec.initial = list,
                        _ => spec.preequilibrate = Some(list),
                    }
                }
                other => {
                    return Err(r.err(
                        key.at,
                        format!(
                            "experiment `{name}`: unknown key `{other}` (keys: name, file, t0, set, preequilibrate, steady, initial, also)"
                        ),
                    ));
                }
            }
        }
        out.push(spec);
    }
    Ok(out)
}
