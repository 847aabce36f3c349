//! The pieces the importer's stages hand each other: the outputs and their σ, the
//! experiments and their measurements, the states with their equations, and the small
//! readers of table cells they share.

use std::collections::HashMap;

use sysid_model::ModelError;
use sysid_model::file::document::Value;

use crate::math::Math;
use crate::tsv::{Cell, Tsv};

/// An output of the model file: one observable with one set of replacements.
#[derive(PartialEq)]
pub(crate) struct Output {
    pub(crate) observable: String,
    pub(crate) value: Math,
    pub(crate) sigma: Sigma,
    pub(crate) transform: &'static str,
    /// "normal" or "laplace".
    pub(crate) distribution: &'static str,
}

#[derive(Clone, PartialEq)]
pub(crate) enum Sigma {
    Number(f64),
    /// An expression in which [`OWN`] stands for the output's own value.
    Expression(Math),
}

/// Stands for the output's own value in a σ expression until the output is named.
pub(crate) const OWN: &str = "\u{1}own\u{1}";

/// A measurement: its time, its output's index and its value.
pub(crate) type Sample = (f64, usize, f64);

/// What an experiment is made of: its preequilibration condition, its simulation condition,
/// and whether it then runs to its own steady state (the measurements at time `inf` after a
/// preequilibration).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Key {
    pub(crate) pre: Option<String>,
    pub(crate) sim: String,
    pub(crate) steady: bool,
}

/// What the measurement tables give: the outputs, and each experiment's measurements.
#[derive(Default)]
pub(crate) struct Measured {
    pub(crate) outputs: Vec<Output>,
    pub(crate) experiments: Vec<(Key, Vec<Sample>)>,
    /// Per experiment, what it sets (filled by [`crate::Builder::merge_same_simulations`]).
    pub(crate) simulations: Vec<Simulation>,
    /// The output of each (observable, observable parameters, noise parameters) that a row
    /// has given: rows that repeat them (Beer's 27 132 rows have 72 outputs) are not
    /// substituted, resolved and rendered again.
    pub(crate) read: HashMap<[String; 3], usize>,
}

/// A condition's entries of an experiment's `set`, and of its `initial` (the species it
/// re-initialises after a preequilibration): the model file's name and value of each.
pub(crate) type ConditionSettings = (Vec<(String, Value)>, Vec<(String, Value)>);

/// What an experiment sets: its condition's `set` and `initial`
/// entries, its preequilibration's, whether it runs to its own steady state, and the other
/// conditions it answers to (`also`: they set the same values).
pub(crate) struct Simulation {
    pub(crate) settings: ConditionSettings,
    pub(crate) preequilibrate: Option<Vec<(String, Value)>>,
    pub(crate) steady: bool,
    pub(crate) also: Vec<String>,
}

/// The states of the model file, with their equations and initial values.
pub(crate) struct Dynamics {
    pub(crate) states: Vec<String>,
    pub(crate) equations: Vec<(String, Math)>,
    pub(crate) initial: Vec<(String, Math)>,
}

/// The row of `condition` in a condition table.
pub(crate) fn condition_row(t: &Tsv, condition: &str) -> Option<usize> {
    let c = t.column("conditionId")?;
    (0..t.rows.len()).find(|&r| t.cell(r, c).text == condition)
}

/// A scale cell (`parameterScale`, `observableTransformation`): `lin` (also empty or
/// absent), `log` or `log10`; anything else is an error naming the cell and `what` it is.
pub(crate) fn scale_of(cell: Option<Cell<'_>>, what: &str) -> Result<&'static str, ModelError> {
    match cell.map(|c| (c, c.text)) {
        None | Some((_, "" | "lin")) => Ok("lin"),
        Some((_, "log")) => Ok("log"),
        Some((_, "log10")) => Ok("log10"),
        Some((c, other)) => Err(c.err(format!("`{other}`: the {what} is lin, log or log10"))),
    }
}
