//! `[[events]]`: where a condition on the state turns true, states are reset.

use super::document::{Node, Value};

use super::names::Scope;
use super::reader::Reader;
use super::{EventSpec, ExperimentSpec};
use crate::error::ModelError;
use crate::expr::Slot;

/// Reads `[[events]]` (optional): an array of tables `{ trigger, set }`, the trigger a
/// comparison of expressions (`lt(U, 1e-8)`) and `set` a table of states and the expressions
/// they are reset to, evaluated with the values just before the event.
pub(super) fn read_events(
    r: &Reader<'_>,
    value: Option<&Node>,
    scope: &Scope,
    experiments: &[ExperimentSpec],
) -> Result<Vec<EventSpec>, ModelError> {
    let Some(value) = value else {
        return Ok(Vec::new());
    };
    let Value::Array(items) = &value.value else {
        return Err(
            r.err(value.at, "`events` must be an array of tables: write each as [[events]]")
        );
    };
    // The events see states, parameters and t; inputs are refused by name below.
    let input = std::cell::Cell::new(None::<String>);
    let resolve = |n: &str| match scope.resolve(n) {
        Some(Slot::Input(_)) => {
            input.set(Some(n.to_string()));
            None
        }
        slot => slot,
    };
    // The error of `label`'s expression, where it named an input.
    let no_inputs = |label: &str, e: ModelError| match input.take() {
        Some(name) => ModelError {
            message: format!("{label}: `{name}` is an input, which events may not use"),
            ..e
        },
        None => e,
    };
    let mut out = Vec::with_capacity(items.len());
    for (number, item) in items.iter().enumerate() {
        let what = format!("event {}", number + 1);
        let table = r.table(item, "each [[events]]")?;
        let at = item.at;
        let trigger = table.get("trigger").ok_or_else(|| {
            r.err(at, format!("[[events]] {what}: `trigger` is missing: the comparison that fires it, like \"lt(x, 1e-8)\""))
        })?;
        let label = format!("{what}: trigger");
        let condition = r
            .trigger(trigger, &label, &resolve, &scope.listed)
            .map_err(|e| no_inputs(&label, e))?;
        let set = table.get("set").ok_or_else(|| {
            r.err(at, format!("[[events]] {what}: `set` is missing: the states it resets, like {{ x = \"0\" }}"))
        })?;
        let mut resets = Vec::new();
        for (key, value) in r.table(set, &format!("[[events]] {what}: set"))?.iter() {
            let name = key.name.as_str();
            let Some(i) = scope.states.iter().position(|s| s == name) else {
                return Err(r.err(
                    key.at,
                    format!(
                        "[[events]] {what}: `{name}` is not a state: an event resets states (states: {})",
                        scope.states.join(", ")
                    ),
                ));
            };
            let label = format!("{what}: {name}");
            let reset = match &value.value {
                Value::String(_) | Value::Expr(_) => r
                    .expression(value, &label, &resolve, &scope.listed)
                    .map_err(|e| no_inputs(&label, e))?,
                _ => {
                    let v = r.number(value, &format!("[[events]] {what}: {name}"))?;
                    crate::expr::Program::compile(&crate::expr::Expr::Num(v), &resolve)
                        .expect("a number compiles")
                }
            };
            resets.push((i, reset));
        }
        if let Some((k, _)) =
            table.iter().find(|(k, _)| !["trigger", "set"].contains(&k.name.as_str()))
        {
            return Err(r.err(
                k.at,
                format!("[[events]] {what}: unknown key `{}` (keys: trigger, set)", k.name),
            ));
        }
        out.push(EventSpec { condition, resets, at });
    }
    if !out.is_empty()
        && let Some(e) = experiments.iter().find(|e| e.steady || e.preequilibrate.is_some())
    {
        return Err(r.err(
            e.at,
            format!(
                "experiment `{}` starts from a steady state, which is solved without the model's [[events]]: events and steady states together are not supported",
                e.name
            ),
        ));
    }
    Ok(out)
}
