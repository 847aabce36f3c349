//! The TOML model file: reading it with the position of every key and value, checking it,
//! and compiling its expressions.

use std::path::{Path, PathBuf};

use sysid_core::{NoiseDistribution, Transform, Unknown};
use sysid_ode::{Integrator, Interpolation};

use crate::error::ModelError;
use crate::expr::Program;

mod data;
pub mod document;
mod equations;
mod events;
mod experiments;
mod integrator;
mod names;
mod reader;
mod values;

use data::read_data;
use document::{Document, Table};
pub use equations::{LEAST_WEIGHT, SIGMA_RANGE, check_sigma};
use equations::{read_equations, read_outputs};
use events::read_events;
use experiments::read_experiments;
use integrator::read_integrator;
use names::{Names, Scope};
use reader::{Positions, Reader};
use values::{Values, read_unknowns, read_values};

/// An expression of a model file that is not an equation (a setting, an initial value, a
/// σ), with the names it uses.
#[derive(Clone, Debug)]
pub struct Expression {
    /// As written.
    pub text: String,
    /// Compiled (see [`ModelFile`] for the slots each kind of expression uses).
    pub program: Program,
    /// The names it uses.
    pub uses: Vec<String>,
    /// Byte offset of the string in the model file.
    pub at: usize,
    /// The name, when the expression is nothing but one name.
    pub bare: Option<String>,
}

/// How a measured quantity's noise is given.
#[derive(Clone, Debug)]
pub enum NoiseSpec {
    /// No `sigma`: `[data.weights]` (default 1) as relative weights.
    Weights,
    /// A known σ.
    Number(f64),
    /// σ per sample, from a column of the data file.
    Column(String),
    /// σ as an expression of t, the states, the parameters, the unknowns and the output's
    /// own value (the output's name).
    Expression(Expression),
}

/// A measured output: its expression and its noise model.
#[derive(Clone, Debug)]
pub struct OutputSpec {
    /// Its name.
    pub name: String,
    /// h(t, y, α, u).
    pub value: Program,
    /// Its noise.
    pub noise: NoiseSpec,
    /// The scale its residuals are formed on.
    pub transform: Transform,
    /// The noise's distribution (`distribution`: "normal", the default, or "laplace").
    pub distribution: NoiseDistribution,
    /// Byte offset of its key.
    pub at: usize,
}

/// A value an experiment sets a parameter to.
#[derive(Clone, Debug)]
pub enum SetValue {
    /// A number.
    Number(f64),
    /// An expression of the unknowns and the parameters given outside the experiments.
    Expression(Expression),
}

/// One `[[experiments]]` entry.
#[derive(Clone, Debug)]
pub struct ExperimentSpec {
    /// Its name, unique.
    pub name: String,
    /// Its data file, relative to the model file.
    pub file: PathBuf,
    /// Time of its initial values (default 0).
    pub t0: f64,
    /// Byte offset of its `t0`, if given.
    pub t0_at: Option<usize>,
    /// The parameters it sets: name, value, byte offset of the key.
    pub set: Vec<(String, SetValue, usize)>,
    /// `preequilibrate`: before t0 the system runs to a steady state with the parameters
    /// outside the experiments and these settings, and starts the experiment from it.
    pub preequilibrate: Option<Vec<(String, SetValue, usize)>>,
    /// `steady = true`: the experiment starts from the steady state it reaches under its own
    /// settings (after its preequilibration, if any), so its data are that steady state.
    pub steady: bool,
    /// `initial`: the initial values of some states in this experiment, replacing
    /// `[initial]` (or, after a preequilibration, the steady state): state, value, byte
    /// offset of the key.
    pub initial: Vec<(String, SetValue, usize)>,
    /// `also`: other names it answers to (`--experiment`), as unique as names.
    pub also: Vec<String>,
    /// Byte offset of its `name`.
    pub at: usize,
}

/// How the data are taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordKind {
    /// Samples at discrete times.
    Discrete,
    /// The columns are a continuous record b(t), linear between samples.
    Continuous,
}

/// An event of `[[events]]`: where its condition falls from positive to zero or below
/// (its trigger turns true, integrating forward), the states `resets` name are set to their
/// expressions' values just before.
#[derive(Clone, Debug)]
pub struct EventSpec {
    /// The condition: a − b of a trigger `lt(a, b)` or `le(a, b)`, b − a of `gt` or `ge`.
    pub condition: Program,
    /// (state, the expression it is reset to).
    pub resets: Vec<(usize, Program)>,
    /// Byte offset of the event's table.
    pub at: usize,
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
    /// Its text: as written, or for a built document (an imported problem) as TOML
    /// ([`Document::to_toml`]).
    pub text: String,
    /// Empty where the positions (`at`) are byte offsets into `text`; for a built document,
    /// where each position was written ([`Document::origins`]), so that an error found later
    /// (σ at the start, say) names the user's file.
    pub origins: Vec<ModelError>,
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
    /// Measured outputs: expressions and noise models.
    pub outputs: Vec<OutputSpec>,
    /// Known initial values and parameters.
    pub known: Vec<(String, f64)>,
    /// Initial values given as expressions of the parameters and unknowns (`A = "dose"`),
    /// compiled with parameter slots for the parameters followed by the extras.
    pub initial: Vec<(String, Expression)>,
    /// Unknowns with guesses, bounds and scales.
    pub unknowns: Vec<Unknown>,
    /// The byte offset of each unknown's key in `[unknowns]`, in the order of `unknowns`: an
    /// error found later in an unknown (its bounds, a noise scale's guess) is located there.
    pub unknowns_at: Vec<usize>,
    /// The unknowns that are neither states nor parameters (used by a σ or a setting), in
    /// the order of `[unknowns]`.
    pub extras: Vec<String>,
    /// The `[data]` table.
    pub data: DataSpec,
    /// The `[[experiments]]`, when there are (then there is no `[data]`).
    pub experiments: Vec<ExperimentSpec>,
    /// The integrator (`[integrator]`, default DOPRI5 with rtol 1e-8, atol 1e-10).
    pub integrator: Integrator,
    /// The `[[events]]`: state resets where a condition on the state turns true.
    pub events: Vec<EventSpec>,
    /// Byte offset of the `states` key, to locate model-wide errors.
    pub states_at: usize,
    /// Data tables held in memory, by the data-file path they stand for: an imported
    /// problem's measurements (a PEtab measurement table), read instead of that file.
    pub tables: Vec<(PathBuf, crate::table::Table)>,
    /// The files an imported problem was made from besides `path` (a PEtab problem's SBML
    /// and tables); empty for a model file.
    pub sources: Vec<PathBuf>,
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
    "experiments",
    "integrator",
    "events",
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
        let file = path.display().to_string();
        let doc = Document::parse(text).map_err(|(at, m)| ModelError::at(&file, text, at, m))?;
        let mut model = Self::check(&doc.root, path, Positions::Text(text))?;
        model.text = text.to_string();
        Ok(model)
    }

    /// Checks a built document as [`parse`](Self::parse) checks a file's, each error located
    /// at its key's or value's origin; `path` names the document (an error at a position
    /// without an origin names it) and anchors relative data paths. Its expressions may be
    /// trees ([`document::Value::Expr`]), compiled as they are.
    pub fn from_document(doc: &Document, path: &Path) -> Result<Self, ModelError> {
        let mut model = Self::check(&doc.root, path, Positions::Origins(&doc.origins))?;
        model.text = doc.to_toml();
        model.origins = doc.origins.clone();
        Ok(model)
    }

    /// An error at position `at` of the document (a key's or value's `at`).
    pub fn err(&self, at: usize, message: impl Into<String>) -> ModelError {
        self.positions().err(&self.path.display().to_string(), at, message)
    }

    fn positions(&self) -> Positions<'_> {
        match self.origins.is_empty() {
            true => Positions::Text(&self.text),
            false => Positions::Origins(&self.origins),
        }
    }

    fn check(doc: &Table, path: &Path, positions: Positions<'_>) -> Result<Self, ModelError> {
        let r = Reader::new(path, positions);
        check_top_level_keys(&r, doc)?;
        let names = Names::read(&r, doc)?;
        let mut scope = Scope::new(&names);
        let equations = read_equations(&r, doc, &names, &scope)?;
        let read = read_unknowns(&r, doc, &scope)?;
        let unknowns = read.list;
        scope.unknowns_at = read.keys;
        let unknowns_at = scope.unknowns_at.iter().map(|(_, at)| *at).collect();
        let extras: Vec<String> = read.extras.iter().map(|e| e.0.clone()).collect();
        scope.extras = extras.clone();
        scope.extras_at = read.extras;
        let outputs = read_outputs(&r, &names, &scope)?;
        let experiments = read_experiments(&r, doc.get("experiments"), path, &scope)?;
        let Values { known, initial } =
            read_values(&r, doc, &names, &scope, &unknowns, (&outputs, &experiments))?;
        let data = read_data(&r, doc.get("data"), path)?;
        if let (Some(value), false) = (doc.get("data"), experiments.is_empty()) {
            return Err(r.err(
                value.at,
                "[data] and [[experiments]] together: with experiments, each experiment names its own data file",
            ));
        }
        for o in &outputs {
            if !matches!(o.noise, NoiseSpec::Weights)
                && let Some((_, _, at)) = data.weights.iter().find(|w| w.0 == o.name)
            {
                return Err(r.err(
                    *at,
                    format!(
                        "[data.weights] {}: the output has a `sigma`; give its noise one way",
                        o.name
                    ),
                ));
            }
        }
        let integrator = read_integrator(&r, doc.get("integrator"))?;
        let events = read_events(&r, doc.get("events"), &scope, &experiments)?;
        Ok(Self {
            path: path.to_path_buf(),
            text: String::new(),
            origins: Vec::new(),
            states: scope.states,
            parameters: scope.parameters,
            inputs: scope.inputs,
            input_mode: names.input_mode,
            equations,
            outputs,
            known,
            initial,
            unknowns,
            unknowns_at,
            extras,
            data,
            experiments,
            integrator,
            events,
            states_at: names.states_at,
            tables: Vec::new(),
            sources: Vec::new(),
        })
    }
}

/// Checks every top-level key is one of the model file's sections.
fn check_top_level_keys(r: &Reader<'_>, doc: &Table) -> Result<(), ModelError> {
    for (key, _) in doc.iter() {
        if !TOP_LEVEL.contains(&key.name.as_str()) {
            return Err(r.err(
                key.at,
                format!("unknown key `{}` (keys: {})", key.name, TOP_LEVEL.join(", ")),
            ));
        }
    }
    Ok(())
}
