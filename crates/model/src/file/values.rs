//! What is known and what is unknown: `[initial]`, `[known]` and `[unknowns]`, which
//! together give every state and parameter exactly once.

use sysid_core::Unknown;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::names::{Names, Scope};
use super::reader::Reader;
use crate::error::ModelError;

/// What a model file gives as known and as unknown.
pub(super) struct Values {
    /// Known initial values and parameters, `[initial]` first.
    pub(super) known: Vec<(String, f64)>,
    /// Unknowns with guesses and bounds, in file order.
    pub(super) unknowns: Vec<Unknown>,
}

/// Reads `[initial]`, `[known]` and `[unknowns]`, in that order whatever their order in the
/// file; checks each state and parameter is given once, and then that none is missing.
pub(super) fn read_values(
    r: &Reader<'_>,
    doc: &DeTable<'_>,
    names: &Names<'_, '_>,
    scope: &Scope,
) -> Result<Values, ModelError> {
    let mut given = Given::default();
    let mut known = read_known(r, doc, ("initial", "state"), &scope.states, &mut given)?;
    known.extend(read_known(r, doc, ("known", "parameter"), &scope.parameters, &mut given)?);
    let unknowns = read_unknowns(r, doc, scope, &mut given)?;
    given.check_complete(r, names)?;
    Ok(Values { known, unknowns })
}

/// The section that gives each name so far.
#[derive(Default)]
struct Given(Vec<(String, &'static str)>);

impl Given {
    /// Records that `section` gives `name`; refuses a name given before.
    fn mark(
        &mut self,
        r: &Reader<'_>,
        name: &str,
        section: &'static str,
        at: usize,
    ) -> Result<(), ModelError> {
        if let Some((_, first)) = self.0.iter().find(|(n, _)| n == name) {
            return Err(
                r.err(at, format!("`{name}` is given twice (in [{first}] and in [{section}])"))
            );
        }
        self.0.push((name.to_string(), section));
        Ok(())
    }

    /// Checks every state, then every parameter, is given, locating a missing one where it
    /// is declared.
    fn check_complete(&self, r: &Reader<'_>, names: &Names<'_, '_>) -> Result<(), ModelError> {
        for (kind, section, list) in
            [("state", "[initial]", &names.states), ("parameter", "[known]", &names.parameters)]
        {
            for (name, at) in list {
                if !self.0.iter().any(|(n, _)| n == name) {
                    return Err(r.err(
                        *at,
                        format!("{kind} `{name}` is neither in {section} nor in [unknowns]"),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Reads `[initial]` or `[known]` (the `section`, giving values of a `kind` of name): a
/// finite number for each name it lists, each one of `names`.
fn read_known(
    r: &Reader<'_>,
    doc: &DeTable<'_>,
    (section, kind): (&'static str, &str),
    names: &[String],
    given: &mut Given,
) -> Result<Vec<(String, f64)>, ModelError> {
    let Some(value) = doc.get(section) else {
        return Ok(Vec::new());
    };
    let mut known = Vec::new();
    for (key, value) in r.table(value, &format!("[{section}]"))?.iter() {
        let name = key.get_ref();
        if !names.iter().any(|n| n == name) {
            return Err(r.err(
                key.span().start,
                format!("[{section}]: `{name}` is not a {kind} (names: {})", names.join(", ")),
            ));
        }
        given.mark(r, name, section, key.span().start)?;
        known.push((name.to_string(), r.number(value, &format!("[{section}] {name}"))?));
    }
    Ok(known)
}

/// Reads `[unknowns]`: for each state or parameter it lists, a guess and optional bounds.
fn read_unknowns(
    r: &Reader<'_>,
    doc: &DeTable<'_>,
    scope: &Scope,
    given: &mut Given,
) -> Result<Vec<Unknown>, ModelError> {
    let Some(value) = doc.get("unknowns") else {
        return Ok(Vec::new());
    };
    let mut unknowns = Vec::new();
    for (key, value) in r.table(value, "[unknowns]")?.iter() {
        let name = key.get_ref();
        let candidates = [scope.states.as_slice(), &scope.parameters].concat();
        if !candidates.iter().any(|n| n == name) {
            return Err(r.err(
                key.span().start,
                format!(
                    "[unknowns]: `{name}` is not a state or parameter (names: {})",
                    candidates.join(", ")
                ),
            ));
        }
        given.mark(r, name, "unknowns", key.span().start)?;
        unknowns.push(read_unknown(r, name, value)?);
    }
    Ok(unknowns)
}

/// Reads one unknown: a number, its guess, or a table `{ guess, min, max, log }`.
fn read_unknown(
    r: &Reader<'_>,
    name: &str,
    value: &Spanned<DeValue<'_>>,
) -> Result<Unknown, ModelError> {
    let DeValue::Table(t) = value.get_ref() else {
        return Ok(Unknown::new(name, r.number(value, &format!("[unknowns] {name}"))?));
    };
    let guess = t.get("guess").ok_or_else(|| {
        r.err(value.span().start, format!("[unknowns] {name}: an unknown needs `guess`"))
    })?;
    let mut u = Unknown::new(name, r.number(guess, &format!("[unknowns] {name}.guess"))?);
    for (k, v) in t.iter() {
        match k.get_ref().as_ref() {
            "guess" => {}
            "min" => u.min = Some(r.number(v, &format!("[unknowns] {name}.min"))?),
            "max" => u.max = Some(r.number(v, &format!("[unknowns] {name}.max"))?),
            "log" => match v.get_ref() {
                DeValue::Boolean(b) => u.log = *b,
                _ => {
                    return Err(r.err(
                        v.span().start,
                        format!("[unknowns] {name}.log must be true or false"),
                    ));
                }
            },
            other => {
                return Err(r.err(
                    k.span().start,
                    format!(
                        "[unknowns] {name}: unknown key `{other}` (keys: guess, min, max, log)"
                    ),
                ));
            }
        }
    }
    Ok(u)
}
