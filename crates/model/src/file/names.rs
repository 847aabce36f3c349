//! The names a model file declares: `states`, `parameters`, `inputs` and the keys of
//! `[outputs]`, each a valid identifier used once; and the scope expressions resolve them in.

use super::document::{Node, Table, Value};
use sysid_ode::Interpolation;

use super::reader::{Entry, Reader};
use crate::error::ModelError;
use crate::expr::Slot;

/// The declared names, each with the byte offset where it is written.
pub(super) struct Names<'a> {
    /// State names, in state order.
    pub(super) states: Vec<(String, usize)>,
    /// Byte offset of the `states` value, to locate model-wide errors.
    pub(super) states_at: usize,
    /// Parameter names.
    pub(super) parameters: Vec<(String, usize)>,
    /// Input names.
    pub(super) inputs: Vec<(String, usize)>,
    /// How inputs are interpolated between samples.
    pub(super) input_mode: Interpolation,
    /// The `[outputs]` entries: their expressions are compiled once every name is known.
    pub(super) outputs: Vec<Entry<'a>>,
}

impl<'a> Names<'a> {
    /// Reads `states`, `parameters`, `inputs` and the `[outputs]` keys; checks each name is
    /// valid and used once.
    pub(super) fn read(r: &Reader<'_>, doc: &'a Table) -> Result<Self, ModelError> {
        let (states, states_at) = read_states(r, doc)?;
        let parameters = match doc.get("parameters") {
            Some(v) => r.names(v, "parameters")?,
            None => Vec::new(),
        };
        let (inputs, input_mode) = match doc.get("inputs") {
            None => (Vec::new(), Interpolation::Linear),
            Some(v) => read_inputs(r, v)?,
        };
        let outputs: Vec<Entry<'a>> = match doc.get("outputs") {
            Some(v) => r.table(v, "[outputs]")?.iter().collect(),
            None => Vec::new(),
        };
        let names = Self { states, states_at, parameters, inputs, input_mode, outputs };
        names.check_unique(r)?;
        Ok(names)
    }

    /// Checks the output names are valid identifiers and no name is used twice across
    /// states, parameters, inputs and outputs.
    fn check_unique(&self, r: &Reader<'_>) -> Result<(), ModelError> {
        let mut seen: Vec<(&str, &str)> = Vec::new();
        let outputs_named: Vec<(String, usize)> =
            self.outputs.iter().map(|(k, _)| (k.name.to_string(), k.at)).collect();
        for (kind, list) in [
            ("a state", &self.states),
            ("a parameter", &self.parameters),
            ("an input", &self.inputs),
            ("an output", &outputs_named),
        ] {
            for (name, at) in list {
                if kind == "an output" {
                    r.identifier(name, *at)?;
                }
                if let Some((_, first)) = seen.iter().find(|(n, _)| n == name) {
                    return Err(r.err(
                        *at,
                        format!("the name `{name}` is used twice (as {first} and as {kind})"),
                    ));
                }
                seen.push((name, kind));
            }
        }
        Ok(())
    }
}

/// Reads `states`: required, a non-empty list of names; returns them and the list's offset.
fn read_states(r: &Reader<'_>, doc: &Table) -> Result<(Vec<(String, usize)>, usize), ModelError> {
    let value =
        doc.get("states").ok_or_else(|| r.file_err("`states` is missing: list the state names"))?;
    let states = r.names(value, "states")?;
    if states.is_empty() {
        return Err(r.err(value.at, "`states` is empty: a model needs at least one state"));
    }
    Ok((states, value.at))
}

/// Reads `inputs`: a list of names (linear between samples) or a table `{ names, mode }`.
fn read_inputs(
    r: &Reader<'_>,
    value: &Node,
) -> Result<(Vec<(String, usize)>, Interpolation), ModelError> {
    match &value.value {
        Value::Array(_) => Ok((r.names(value, "inputs")?, Interpolation::Linear)),
        Value::Table(t) => read_inputs_table(r, value, t),
        _ => Err(r.err(value.at, "`inputs` must be a list of names or a table {names, mode}")),
    }
}

/// Reads the `[inputs]` table: `names` is required, `mode` is checked before stray keys.
fn read_inputs_table(
    r: &Reader<'_>,
    value: &Node,
    t: &Table,
) -> Result<(Vec<(String, usize)>, Interpolation), ModelError> {
    let names = match t.get("names") {
        Some(n) => r.names(n, "inputs.names")?,
        None => return Err(r.err(value.at, "[inputs] needs `names = [...]`")),
    };
    let mode = match t.get("mode") {
        None => Interpolation::Linear,
        Some(m) => read_input_mode(r, m)?,
    };
    for (key, _) in t.iter() {
        if !["names", "mode"].contains(&key.name.as_str()) {
            return Err(r.err(
                key.at,
                format!("unknown key `{}` in [inputs] (keys: names, mode)", key.name),
            ));
        }
    }
    Ok((names, mode))
}

/// Reads `inputs.mode`: "linear" or "step".
fn read_input_mode(r: &Reader<'_>, m: &Node) -> Result<Interpolation, ModelError> {
    match r.string(m, "inputs.mode")? {
        "linear" => Ok(Interpolation::Linear),
        "step" => Ok(Interpolation::Step),
        other => {
            Err(r.err(m.at, format!("inputs.mode must be \"linear\" or \"step\", got \"{other}\"")))
        }
    }
}

/// The names an expression may use: states, parameters, inputs and `t` in the model's
/// equations and outputs; the parameters and the extra unknowns in a setting; and in a σ
/// also t, the states and the output's own value.
pub(super) struct Scope {
    /// State names, in state order.
    pub(super) states: Vec<String>,
    /// Parameter names.
    pub(super) parameters: Vec<String>,
    /// Input names.
    pub(super) inputs: Vec<String>,
    /// Unknowns that are neither states nor parameters.
    pub(super) extras: Vec<String>,
    /// The same, with the byte offsets of their keys.
    pub(super) extras_at: Vec<(String, usize)>,
    /// Every unknown's key and its byte offset.
    pub(super) unknowns_at: Vec<(String, usize)>,
    /// Every name, listed for an error about an unknown one.
    pub(super) listed: String,
}

impl Scope {
    /// The scope of the declared states, parameters and inputs.
    pub(super) fn new(names: &Names<'_>) -> Self {
        let plain = |list: &[(String, usize)]| list.iter().map(|s| s.0.clone()).collect();
        let states: Vec<String> = plain(&names.states);
        let parameters: Vec<String> = plain(&names.parameters);
        let inputs: Vec<String> = plain(&names.inputs);
        let listed = states
            .iter()
            .chain(&parameters)
            .chain(&inputs)
            .map(String::as_str)
            .chain(["t"])
            .collect::<Vec<_>>()
            .join(", ");
        Self {
            states,
            parameters,
            inputs,
            extras: Vec::new(),
            extras_at: Vec::new(),
            unknowns_at: Vec::new(),
            listed,
        }
    }

    /// The slot of a parameter or an extra unknown in a setting's parameter vector (the
    /// parameters, then the extras).
    pub(super) fn resolve_setting(&self, name: &str) -> Option<Slot> {
        let np = self.parameters.len();
        self.parameters
            .iter()
            .position(|s| s == name)
            .or_else(|| self.extras.iter().position(|s| s == name).map(|x| np + x))
            .map(Slot::Parameter)
    }

    /// The names a setting may use, listed.
    pub(super) fn setting_names(&self) -> String {
        self.parameters.iter().chain(&self.extras).cloned().collect::<Vec<_>>().join(", ")
    }

    /// The slot of a name in the σ of `output`: t, a state, a parameter or extra (as in a
    /// setting), or the output's own value (the parameter after the extras).
    pub(super) fn resolve_sigma(&self, name: &str, output: &str) -> Option<Slot> {
        if name == output {
            return Some(Slot::Parameter(self.parameters.len() + self.extras.len()));
        }
        if name == "t" {
            return Some(Slot::Time);
        }
        self.states
            .iter()
            .position(|s| s == name)
            .map(Slot::State)
            .or_else(|| self.resolve_setting(name))
    }

    /// The names the σ of `output` may use, listed.
    pub(super) fn sigma_names(&self, output: &str) -> String {
        let mut names: Vec<String> = self.states.clone();
        names.extend(self.parameters.iter().chain(&self.extras).cloned());
        names.push(output.to_string());
        names.push("t".into());
        names.join(", ")
    }

    /// The slot a name refers to, if any.
    pub(super) fn resolve(&self, name: &str) -> Option<Slot> {
        if name == "t" {
            return Some(Slot::Time);
        }
        self.states
            .iter()
            .position(|s| s == name)
            .map(Slot::State)
            .or_else(|| self.parameters.iter().position(|s| s == name).map(Slot::Parameter))
            .or_else(|| self.inputs.iter().position(|s| s == name).map(Slot::Input))
    }
}
