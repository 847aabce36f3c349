//! The expressions of a model file: `[equations]`, one per state, and `[outputs]`.

use toml::de::DeTable;

use super::names::{Names, Scope};
use super::reader::Reader;
use crate::error::ModelError;
use crate::expr::Program;

/// Reads `[equations]`: required, a table of expressions keyed by state, one for every
/// state; returns them in state order.
pub(super) fn read_equations(
    r: &Reader<'_>,
    doc: &DeTable<'_>,
    names: &Names<'_, '_>,
    scope: &Scope,
) -> Result<Vec<Program>, ModelError> {
    let value = doc.get("equations").ok_or_else(|| {
        r.err(names.states_at, "[equations] is missing: give d(state)/dt for every state")
    })?;
    let mut equations: Vec<Option<Program>> = vec![None; names.states.len()];
    for (key, value) in r.table(value, "[equations]")?.iter() {
        let name = key.get_ref();
        let Some(i) = scope.states.iter().position(|s| s == name) else {
            return Err(r.err(
                key.span().start,
                format!(
                    "[equations]: `{name}` is not a state (states: {})",
                    scope.states.join(", ")
                ),
            ));
        };
        let what = format!("equation of {name}");
        equations[i] = Some(r.expression(value, &what, &|n| scope.resolve(n), &scope.listed)?);
    }
    equations
        .into_iter()
        .zip(&names.states)
        .map(|(e, (name, at))| {
            e.ok_or_else(|| r.err(*at, format!("state `{name}` has no equation in [equations]")))
        })
        .collect()
}

/// Compiles the `[outputs]` expressions, in the order they are written.
pub(super) fn read_outputs(
    r: &Reader<'_>,
    names: &Names<'_, '_>,
    scope: &Scope,
) -> Result<Vec<(String, Program)>, ModelError> {
    names
        .outputs
        .iter()
        .map(|(key, value)| {
            let name = key.get_ref().to_string();
            let what = format!("output {name}");
            let program = r.expression(value, &what, &|n| scope.resolve(n), &scope.listed)?;
            Ok((name, program))
        })
        .collect()
}
