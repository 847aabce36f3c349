//! The TOML model file: reading it with the position of every key and value, checking it,
//! and compiling its expressions.

use std::path::{Path, PathBuf};

use sysid_core::Unknown;
use sysid_ode::{Integrator, Interpolation};
use toml::de::DeTable;

use crate::error::ModelError;
use crate::expr::Program;

mod data;
mod equations;
mod integrator;
mod names;
mod reader;
mod values;

use data::read_data;
use equations::{read_equations, read_outputs};
use integrator::read_integrator;
use names::{Names, Scope};
use reader::Reader;
use values::{Values, read_values};

/// How the data are taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordKind {
    /// Samples at discrete times.
    Discrete,
    /// The columns are a continuous record b(t), linear between samples.
    Continuous,
}

/// The `[data]` table.
#[derive(Clone, Debug, PartialEq)]
pub struct DataSpec {
    /// The data file, relative to the model file.
    pub file: Option<PathBuf>,
    /// Time of the initial values (default 0); the data start there or later.
    pub t0: f64,
    /// Byte offset of the `t0` value in the model file, if it is given.
    pub t0_at: Option<usize>,
    /// Discrete or continuous.
    pub record: RecordKind,
    /// Weight per measured column (default 1).
    pub weights: Vec<(String, f64, usize)>,
}

/// A model file, read and checked, expressions compiled.
#[derive(Clone, Debug)]
pub struct ModelFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// Its text, for locating errors found later.
    pub text: String,
    /// State names.
    pub states: Vec<String>,
    /// Parameter names.
    pub parameters: Vec<String>,
    /// Input names.
    pub inputs: Vec<String>,
    /// How inputs are interpolated between samples.
    pub input_mode: Interpolation,
    /// One right-hand side per state, in state order.
    pub equations: Vec<Program>,
    /// Measured outputs: names and expressions.
    pub outputs: Vec<(String, Program)>,
    /// Known initial values and parameters.
    pub known: Vec<(String, f64)>,
    /// Unknowns with guesses, bounds and scales.
    pub unknowns: Vec<Unknown>,
    /// The `[data]` table.
    pub data: DataSpec,
    /// The integrator (`[integrator]`, default DOPRI5 with rtol 1e-8, atol 1e-10).
    pub integrator: Integrator,
    /// Byte offset of the `states` key, to locate model-wide errors.
    pub states_at: usize,
}

/// The top-level keys: the sections of a model file.
const TOP_LEVEL: &[&str] = &[
    "states",
    "parameters",
    "inputs",
    "equations",
    "initial",
    "known",
    "unknowns",
    "outputs",
    "data",
    "integrator",
];

impl ModelFile {
    /// Reads and checks a model file.
    pub fn read(path: &Path) -> Result<Self, ModelError> {
        let file = path.display().to_string();
        let text =
            std::fs::read_to_string(path).map_err(|e| ModelError::file(&file, e.to_string()))?;
        Self::parse(&text, path)
    }

    /// Checks a model file's text; `path` names it and anchors relative data paths.
    ///
    /// The sections are checked in a fixed order, whatever their order in the file, and the
    /// first mistake is reported: TOML syntax and top-level keys; the names, which every
    /// expression and value refers to; `[equations]`, `[outputs]`, `[initial]`, `[known]`,
    /// `[unknowns]`, `[data]` and `[integrator]`. A leading byte-order mark is skipped.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ModelError> {
        let text = crate::table::without_bom(text);
        let r = Reader::new(path, text);
        let doc = r.document()?;
        let doc = doc.get_ref();
        check_top_level_keys(&r, doc)?;
        let names = Names::read(&r, doc)?;
        let scope = Scope::new(&names);
        let equations = read_equations(&r, doc, &names, &scope)?;
        let outputs = read_outputs(&r, &names, &scope)?;
        let Values { known, unknowns } = read_values(&r, doc, &names, &scope)?;
        let data = read_data(&r, doc.get("data"), path)?;
        let integrator = read_integrator(&r, doc.get("integrator"))?;
        Ok(Self {
            path: path.to_path_buf(),
            text: text.to_string(),
            states: scope.states,
            parameters: scope.parameters,
            inputs: scope.inputs,
            input_mode: names.input_mode,
            equations,
            outputs,
            known,
            unknowns,
            data,
            integrator,
            states_at: names.states_at,
        })
    }
}

/// Checks every top-level key is one of the model file's sections.
fn check_top_level_keys(r: &Reader<'_>, doc: &DeTable<'_>) -> Result<(), ModelError> {
    for (key, _) in doc.iter() {
        if !TOP_LEVEL.contains(&key.get_ref().as_ref()) {
            return Err(r.err(
                key.span().start,
                format!("unknown key `{}` (keys: {})", key.get_ref(), TOP_LEVEL.join(", ")),
            ));
        }
    }
    Ok(())
}
