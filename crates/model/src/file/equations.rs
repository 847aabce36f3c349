//! The expressions of a model file: `[equations]`, one per state, and `[outputs]`.

use super::document::{Node, Table, Value};
use sysid_core::{NoiseDistribution, Transform};

use super::names::{Names, Scope};
use super::reader::Reader;
use super::{NoiseSpec, OutputSpec};
use crate::error::ModelError;
use crate::expr::Program;

/// Reads `[equations]`: required, a table of expressions keyed by state, one for every
/// state; returns them in state order.
pub(super) fn read_equations(
    r: &Reader<'_>,
    doc: &Table,
    names: &Names<'_>,
    scope: &Scope,
) -> Result<Vec<Program>, ModelError> {
    let value = doc.get("equations").ok_or_else(|| {
        r.err(names.states_at, "[equations] is missing: give d(state)/dt for every state")
    })?;
    let mut equations: Vec<Option<Program>> = vec![None; names.states.len()];
    for (key, value) in r.table(value, "[equations]")?.iter() {
        let name = key.name.as_str();
        let Some(i) = scope.states.iter().position(|s| s == name) else {
            return Err(r.err(
                key.at,
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

/// Compiles the `[outputs]`, in the order they are written: a string (the expression), or a
/// table `{ value, sigma, transform, distribution }`.
pub(super) fn read_outputs(
    r: &Reader<'_>,
    names: &Names<'_>,
    scope: &Scope,
) -> Result<Vec<OutputSpec>, ModelError> {
    names
        .outputs
        .iter()
        .map(|(key, value)| {
            let name = key.name.to_string();
            let at = key.at;
            let what = format!("output {name}");
            let Value::Table(t) = &value.value else {
                let value = r.expression(value, &what, &|n| scope.resolve(n), &scope.listed)?;
                let (noise, transform) = (NoiseSpec::Weights, Transform::Lin);
                let distribution = NoiseDistribution::Normal;
                return Ok(OutputSpec { name, value, noise, transform, distribution, at });
            };
            let expression = t.get("value").ok_or_else(|| {
                r.err(value.at, format!("[outputs] {name}: a table needs `value`, the output's expression"))
            })?;
            let program = r.expression(expression, &what, &|n| scope.resolve(n), &scope.listed)?;
            let mut output = OutputSpec {
                name: name.clone(),
                value: program,
                noise: NoiseSpec::Weights,
                transform: Transform::Lin,
                distribution: NoiseDistribution::Normal,
                at,
            };
            for (k, v) in t.iter() {
                match k.name.as_str() {
                    "value" => {}
                    "sigma" => output.noise = read_sigma(r, &name, v, scope, names)?,
                    "transform" => {
                        output.transform = match r.string(v, &format!("[outputs] {name}.transform"))? {
                            "lin" => Transform::Lin,
                            "log" => Transform::Log,
                            "log10" => Transform::Log10,
                            other => {
                                return Err(r.err(
                                    v.at,
                                    format!("[outputs] {name}.transform must be \"lin\", \"log\" or \"log10\", got \"{other}\""),
                                ));
                            }
                        }
                    }
                    "distribution" => {
                        output.distribution = match r.string(v, &format!("[outputs] {name}.distribution"))? {
                            "normal" => NoiseDistribution::Normal,
                            "laplace" => NoiseDistribution::Laplace,
                            other => {
                                return Err(r.err(
                                    v.at,
                                    format!("[outputs] {name}.distribution must be \"normal\" or \"laplace\", got \"{other}\""),
                                ));
                            }
                        }
                    }
                    other => {
                        return Err(r.err(
                            k.at,
                            format!("[outputs] {name}: unknown key `{other}` (keys: value, sigma, transform, distribution)"),
                        ));
                    }
                }
            }
            if output.distribution == NoiseDistribution::Laplace
                && matches!(output.noise, NoiseSpec::Weights)
            {
                return Err(r.err(
                    at,
                    format!("[outputs] {name}: laplace noise needs a `sigma`, its scale b"),
                ));
            }
            Ok(output)
        })
        .collect()
}

/// Reads an output's `sigma`: a positive number, an expression, or `{ column = "NAME" }` (a
/// column that names nothing else: not a state's, an output's or an input's).
fn read_sigma(
    r: &Reader<'_>,
    output: &str,
    v: &Node,
    scope: &Scope,
    names: &Names<'_>,
) -> Result<NoiseSpec, ModelError> {
    let what = format!("[outputs] {output}.sigma");
    match &v.value {
        Value::String(_) | Value::Expr(_) => {
            let resolve = |n: &str| scope.resolve_sigma(n, output);
            let e = r.expression_with_names(v, &what, &resolve, &scope.sigma_names(output))?;
            if e.program.is_constant() {
                let sigma = e.program.eval::<f64>(0.0, &[], &[], &[]);
                check_sigma(sigma).map_err(|m| r.err(v.at, format!("{what} {m}")))?;
                return Ok(NoiseSpec::Number(sigma));
            }
            Ok(NoiseSpec::Expression(e))
        }
        Value::Table(t) => {
            let column = t.get("column").ok_or_else(|| {
                r.err(
                    v.at,
                    format!("{what}: a table takes `column = \"NAME\"`, the data column of σ"),
                )
            })?;
            if let Some((k, _)) = t.iter().find(|(k, _)| k.name != "column") {
                return Err(r.err(k.at, format!("{what}: unknown key `{}` (keys: column)", k.name)));
            }
            let name = r.string(column, &format!("{what}.column"))?;
            let taken = [
                ("a state", names.states.iter().any(|(n, _)| n == name)),
                ("an output", names.outputs.iter().any(|(k, _)| k.name == name)),
                ("an input", names.inputs.iter().any(|(n, _)| n == name)),
            ];
            if let Some((what_else, _)) = taken.iter().find(|(_, taken)| *taken) {
                return Err(r.err(
                    column.at,
                    format!(
                        "{what}.column `{name}` is {what_else}'s name: the σ column must name nothing else (a column of its own, such as `{output}_sigma`)"
                    ),
                ));
            }
            Ok(NoiseSpec::Column(name.to_string()))
        }
        _ => {
            let sigma = r.number(v, &what)?;
            check_sigma(sigma).map_err(|m| r.err(v.at, format!("{what} {m}")))?;
            Ok(NoiseSpec::Number(sigma))
        }
    }
}

/// The smallest and largest σ a fit can weigh a residual by: beyond them the weight 1/σ²
/// overflows or vanishes.
pub const SIGMA_RANGE: (f64, f64) = (1e-150, 1e150);

/// The least weight the largest weighted column of a data file may have: 1/σ² of the
/// largest σ of [`SIGMA_RANGE`]; below it ε and its derivatives underflow.
pub const LEAST_WEIGHT: f64 = 1e-300;

/// Checks a known σ: positive, and within [`SIGMA_RANGE`]; the error says what is wrong
/// without naming the σ.
pub fn check_sigma(sigma: f64) -> Result<(), String> {
    let (lo, hi) = SIGMA_RANGE;
    if !(sigma > 0.0 && sigma.is_finite()) {
        return Err(format!("must be positive, got {sigma}"));
    }
    if !(lo..=hi).contains(&sigma) {
        return Err(format!(
            "must lie between {lo:e} and {hi:e}, got {sigma:e}: its weight 1/σ² would {} (a unit slip?)",
            if sigma < lo { "overflow" } else { "vanish" }
        ));
    }
    Ok(())
}
