//! What is known and what is unknown: `[unknowns]`, `[initial]` and `[known]`, which together
//! (with what every experiment sets) give every state and parameter exactly once.

use super::document::{Node, Table, Value};
use sysid_core::{Distribution, Initialization, Prior, Transform, Unknown};

use super::names::{Names, Scope};
use super::reader::Reader;
use super::{ExperimentSpec, Expression, NoiseSpec, OutputSpec, SetValue};
use crate::error::ModelError;

/// What a model file gives as known: numbers, and initial values as expressions.
pub(super) struct Values {
    /// Known initial values and parameters, `[initial]` first.
    pub(super) known: Vec<(String, f64)>,
    /// Initial values given as expressions.
    pub(super) initial: Vec<(String, Expression)>,
}

/// Reads `[initial]` and `[known]` given the unknowns; checks each state and parameter is
/// given once, and then that none is missing (a parameter that every experiment sets needs
/// nothing more).
pub(super) fn read_values(
    r: &Reader<'_>,
    doc: &Table,
    names: &Names<'_>,
    scope: &Scope,
    unknowns: &[Unknown],
    (outputs, experiments): (&[OutputSpec], &[ExperimentSpec]),
) -> Result<Values, ModelError> {
    let mut given = Given::default();
    let Values { mut known, initial } = read_initial(r, doc, scope, &mut given)?;
    known.extend(read_known(r, doc, scope, &mut given)?);
    for (u, (_, at)) in unknowns.iter().zip(&scope.unknowns_at) {
        given.mark(r, &u.name, "unknowns", *at)?;
    }
    check_unknowns_used(r, scope, (outputs, &initial, experiments))?;
    given.check_complete(r, names, experiments)?;
    Ok(Values { known, initial })
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

    /// Checks every state, then every parameter, is given (a parameter also by being set in
    /// every experiment), locating a missing one where it is declared.
    fn check_complete(
        &self,
        r: &Reader<'_>,
        names: &Names<'_>,
        experiments: &[ExperimentSpec],
    ) -> Result<(), ModelError> {
        for (name, at) in &names.states {
            if !self.0.iter().any(|(n, _)| n == name) {
                return Err(r.err(
                    *at,
                    format!("state `{name}` is neither in [initial] nor in [unknowns]"),
                ));
            }
        }
        for (name, at) in &names.parameters {
            if self.0.iter().any(|(n, _)| n == name) {
                continue;
            }
            let sets = |e: &ExperimentSpec| e.set.iter().any(|(p, _, _)| p == name);
            match experiments.iter().find(|e| !sets(e)) {
                None if !experiments.is_empty() => {}
                None => {
                    return Err(r.err(
                        *at,
                        format!("parameter `{name}` is neither in [known] nor in [unknowns]"),
                    ));
                }
                Some(e) => {
                    return Err(r.err(
                        e.at,
                        format!(
                            "experiment `{}` does not set parameter `{name}`, which is neither in [known] nor in [unknowns]",
                            e.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Reads `[initial]`: for each state it lists, a finite number or an expression of the
/// parameters and unknowns.
fn read_initial(
    r: &Reader<'_>,
    doc: &Table,
    scope: &Scope,
    given: &mut Given,
) -> Result<Values, ModelError> {
    let Some(value) = doc.get("initial") else {
        return Ok(Values { known: Vec::new(), initial: Vec::new() });
    };
    let (mut known, mut expressions) = (Vec::new(), Vec::new());
    for (key, value) in r.table(value, "[initial]")?.iter() {
        let name = key.name.as_str();
        if !scope.states.iter().any(|n| n == name) {
            return Err(r.err(
                key.at,
                format!("[initial]: `{name}` is not a state (names: {})", scope.states.join(", ")),
            ));
        }
        given.mark(r, name, "initial", key.at)?;
        let what = format!("[initial] {name}");
        match &value.value {
            Value::String(_) | Value::Expr(_) => {
                let resolve = |n: &str| scope.resolve_setting(n);
                let e = r.expression_with_names(value, &what, &resolve, &scope.setting_names())?;
                expressions.push((name.to_string(), e));
            }
            _ => known.push((name.to_string(), r.number(value, &what)?)),
        }
    }
    Ok(Values { known, initial: expressions })
}

/// Reads `[known]`: a finite number for each parameter it lists.
fn read_known(
    r: &Reader<'_>,
    doc: &Table,
    scope: &Scope,
    given: &mut Given,
) -> Result<Vec<(String, f64)>, ModelError> {
    let Some(value) = doc.get("known") else {
        return Ok(Vec::new());
    };
    let mut known = Vec::new();
    for (key, value) in r.table(value, "[known]")?.iter() {
        let name = key.name.as_str();
        if !scope.parameters.iter().any(|n| n == name) {
            return Err(r.err(
                key.at,
                format!(
                    "[known]: `{name}` is not a parameter (names: {})",
                    scope.parameters.join(", ")
                ),
            ));
        }
        given.mark(r, name, "known", key.at)?;
        known.push((name.to_string(), r.number(value, &format!("[known] {name}"))?));
    }
    Ok(known)
}

/// What `[unknowns]` gives.
pub(super) struct Unknowns {
    /// The unknowns, in the file's order.
    pub(super) list: Vec<Unknown>,
    /// The names of their own (neither states nor parameters), with their keys' offsets.
    pub(super) extras: Vec<(String, usize)>,
    /// Every unknown's name and its key's offset.
    pub(super) keys: Vec<(String, usize)>,
}

/// Reads `[unknowns]`: for each name it lists (a state, a parameter, or a name of its own
/// that a σ or a setting uses), a guess and optional bounds; returns them, the names of
/// their own, and every key's byte offset.
pub(super) fn read_unknowns(
    r: &Reader<'_>,
    doc: &Table,
    scope: &Scope,
) -> Result<Unknowns, ModelError> {
    let Some(value) = doc.get("unknowns") else {
        return Ok(Unknowns { list: Vec::new(), extras: Vec::new(), keys: Vec::new() });
    };
    let mut at = Vec::new();
    let mut unknowns = Vec::new();
    let mut extras = Vec::new();
    for (key, value) in r.table(value, "[unknowns]")?.iter() {
        let name = key.name.as_str();
        let model = scope.states.iter().chain(&scope.parameters).any(|n| n == name);
        if !model {
            r.identifier(name, key.at)?;
            if scope.inputs.iter().any(|n| n == name) {
                return Err(r.err(key.at, format!("[unknowns]: `{name}` is an input")));
            }
            extras.push((name.to_string(), key.at));
        }
        if unknowns.iter().any(|u: &Unknown| u.name == *name) {
            return Err(r.err(key.at, format!("[unknowns]: `{name}` is listed twice")));
        }
        unknowns.push(read_unknown(r, name, value)?);
        at.push((name.to_string(), key.at));
    }
    Ok(Unknowns { list: unknowns, extras, keys: at })
}

/// Refuses an unknown that nothing uses: a name of its own that no `sigma`, `set`,
/// `preequilibrate`, `initial` or `[initial]` expression mentions.
fn check_unknowns_used(
    r: &Reader<'_>,
    scope: &Scope,
    (outputs, initial, experiments): (&[OutputSpec], &[(String, Expression)], &[ExperimentSpec]),
) -> Result<(), ModelError> {
    let mut used: Vec<&str> = Vec::new();
    for o in outputs {
        if let NoiseSpec::Expression(e) = &o.noise {
            used.extend(e.uses.iter().map(String::as_str));
        }
    }
    for (_, e) in initial {
        used.extend(e.uses.iter().map(String::as_str));
    }
    for x in experiments {
        let pre = x.preequilibrate.iter().flatten();
        for (_, v, _) in x.set.iter().chain(pre).chain(&x.initial) {
            if let SetValue::Expression(e) = v {
                used.extend(e.uses.iter().map(String::as_str));
            }
        }
    }
    for (name, at) in &scope.extras_at {
        if !used.contains(&name.as_str()) {
            return Err(r.err(
                *at,
                format!("[unknowns]: `{name}` is used nowhere: it is no state or parameter, and no sigma, set, preequilibrate, initial or [initial] expression names it"),
            ));
        }
    }
    Ok(())
}

/// Reads one unknown: a number, its guess, or a table `{ guess, min, max, log }`.
fn read_unknown(r: &Reader<'_>, name: &str, value: &Node) -> Result<Unknown, ModelError> {
    let Value::Table(t) = &value.value else {
        return Ok(Unknown::new(name, r.number(value, &format!("[unknowns] {name}"))?));
    };
    let guess = t
        .get("guess")
        .ok_or_else(|| r.err(value.at, format!("[unknowns] {name}: an unknown needs `guess`")))?;
    let mut u = Unknown::new(name, r.number(guess, &format!("[unknowns] {name}.guess"))?);
    for (k, v) in t.iter() {
        match k.name.as_str() {
            "guess" => {}
            "min" => u.min = Some(r.number(v, &format!("[unknowns] {name}.min"))?),
            "max" => u.max = Some(r.number(v, &format!("[unknowns] {name}.max"))?),
            "log" => match &v.value {
                Value::Bool(b) => u.log = *b,
                _ => {
                    return Err(r.err(v.at, format!("[unknowns] {name}.log must be true or false")));
                }
            },
            "prior" => u.prior = Some(read_prior(r, name, v)?),
            "initialization" => u.initialization = Some(read_initialization(r, name, v)?),
            other => {
                return Err(r.err(
                    k.at,
                    format!(
                        "[unknowns] {name}: unknown key `{other}` (keys: guess, min, max, log, prior, initialization)"
                    ),
                ));
            }
        }
    }
    Ok(u)
}

/// Reads `initialization = { distribution, a, b, on }`: where multistart draws this unknown's
/// starts, a `uniform` (a, b the ends), `normal` (mean, sd) or `laplace` (location, scale)
/// distribution of the value (`on = "lin"`, the default), its ln (`"log"`) or its log10.
fn read_initialization(
    r: &Reader<'_>,
    name: &str,
    value: &Node,
) -> Result<Initialization, ModelError> {
    let what = format!("[unknowns] {name}.initialization");
    let t = r.table(value, &what)?;
    let needed = |key: &str| {
        t.get(key)
            .ok_or_else(|| r.err(value.at, format!("{what}: an initialization needs `{key}`")))
    };
    let kind = needed("distribution")?;
    let distribution = match r.string(kind, &format!("{what}.distribution"))? {
        "uniform" => Distribution::Uniform,
        "normal" => Distribution::Normal,
        "laplace" => Distribution::Laplace,
        other => {
            return Err(r.err(
                kind.at,
                format!("{what}.distribution: `{other}` (distributions: uniform, normal, laplace)"),
            ));
        }
    };
    let a = r.number(needed("a")?, &format!("{what}.a"))?;
    let b = r.number(needed("b")?, &format!("{what}.b"))?;
    let mut on = Transform::Lin;
    for (k, v) in t.iter() {
        match k.name.as_str() {
            "distribution" | "a" | "b" => {}
            "on" => on = read_scale(r, v, &format!("{what}.on"))?,
            other => {
                return Err(r.err(
                    k.at,
                    format!("{what}: unknown key `{other}` (keys: distribution, a, b, on)"),
                ));
            }
        }
    }
    let init = Initialization { distribution, a, b, on };
    if !init.is_valid() {
        let at = t.get("b").map_or(value.at, |v| v.at);
        let rule = match distribution {
            Distribution::Uniform => "a < b",
            _ => "b > 0",
        };
        return Err(r.err(
            at,
            format!("{what}: a {} one needs {rule}, got a = {a}, b = {b}", distribution.name()),
        ));
    }
    Ok(init)
}

/// Reads a scale: "lin", "log" or "log10".
fn read_scale(r: &Reader<'_>, v: &Node, what: &str) -> Result<Transform, ModelError> {
    match r.string(v, what)? {
        "lin" => Ok(Transform::Lin),
        "log" => Ok(Transform::Log),
        "log10" => Ok(Transform::Log10),
        other => Err(r.err(v.at, format!("{what}: `{other}` (scales: lin, log, log10)"))),
    }
}

/// Reads `prior = { mean, sd, on, distribution }`: a normal prior (`distribution =
/// "normal"`, the default; or `"laplace"`, mean its location and sd its scale b) on the value
/// (`on = "lin"`, the default), its natural logarithm (`"log"`) or its log10 (`"log10"`).
fn read_prior(r: &Reader<'_>, name: &str, value: &Node) -> Result<Prior, ModelError> {
    let what = format!("[unknowns] {name}.prior");
    let t = r.table(value, &what)?;
    let number = |key: &str| -> Result<f64, ModelError> {
        let v =
            t.get(key).ok_or_else(|| r.err(value.at, format!("{what}: a prior needs `{key}`")))?;
        r.number(v, &format!("{what}.{key}"))
    };
    let (mean, sd) = (number("mean")?, number("sd")?);
    if sd <= 0.0 || sd.is_nan() {
        let at = t.get("sd").map_or(value.at, |v| v.at);
        return Err(r.err(at, format!("{what}.sd must be positive, got {sd}")));
    }
    let mut on = Transform::Lin;
    let mut laplace = false;
    for (k, v) in t.iter() {
        match k.name.as_str() {
            "mean" | "sd" => {}
            "on" => on = read_scale(r, v, &format!("{what}.on"))?,
            "distribution" => {
                laplace = match r.string(v, &format!("{what}.distribution"))? {
                    "normal" => false,
                    "laplace" => true,
                    other => {
                        return Err(r.err(
                            v.at,
                            format!("{what}.distribution: `{other}` (normal, laplace)"),
                        ));
                    }
                }
            }
            other => {
                return Err(r.err(
                    k.at,
                    format!("{what}: unknown key `{other}` (keys: mean, sd, on, distribution)"),
                ));
            }
        }
    }
    Ok(if laplace { Prior::laplace(mean, sd, on) } else { Prior::normal(mean, sd, on) })
}
