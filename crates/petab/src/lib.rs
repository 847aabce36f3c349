//! # sysid-petab: PEtab problems as sysid model files
//!
//! A PEtab problem (PEtab-dev/PEtab, format v1) is an SBML model and four TSV tables
//! (conditions, measurements, observables, parameters) tied together by a YAML file. This
//! crate reads them and writes the same problem as a multi-experiment model file
//! ([`sysid_model::ModelFile`]), so that every method, study and report works on it without
//! knowing where it came from:
//!
//! * the SBML species, compartments, parameters, reactions and rules become states,
//!   parameters and equations ([`sbml`] reads the subset it knows and refuses the rest by
//!   name; `dynamics` resolves the rules and writes the equations);
//! * SBML events that fire when time reaches a value and set what nothing else changes
//!   become switches in time; events that reset states, or whose trigger depends on the
//!   state, become the model file's `[[events]]`, located by root finding (`events`);
//! * each simulation condition becomes an experiment that sets the condition table's
//!   parameters (`conditions`); its measurements are a data table held in memory, times may
//!   repeat (`measurements`);
//! * each observable, with the observable and noise parameters of a measurement row put in
//!   place of its `observableParameter{n}_{id}` / `noiseParameter{n}_{id}`, becomes an
//!   output with its σ and its transformation, one output per distinct replacement
//!   (`observables`);
//! * the parameter table's estimated parameters become the unknowns, with their bounds, on a
//!   log scale where `parameterScale` is `log` or `log10` (the optimum does not depend on
//!   the base), starting from `nominalValue`; the others are known (`parameters`);
//! * a preequilibration condition becomes the experiment's `preequilibrate`: it starts from
//!   the steady state under that condition; measurements at time `inf` (steady state)
//!   become an experiment that preequilibrates under its own condition and is measured at
//!   t = 0.
//!
//! `parts` holds what these stages hand each other (outputs, experiments, states).
//! `document` builds the model file's document: its expressions as trees, each key and value
//! with its place in the tables or the SBML, so that every error names the file, the line and
//! the column of what caused it. The model file's reader checks it as it checks a file.
//! What is not supported (events with delays, algebraic rules, …) is refused by name.
#![warn(missing_docs)]

mod conditions;
mod document;
mod dynamics;
mod events;
pub mod math;
mod measurements;
mod observables;
mod parameters;
mod parts;
pub mod sbml;
pub mod tsv;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use serde::Deserialize;
use sysid_model::{Model, ModelError, ModelFile};

use conditions::is_condition_label;
use math::Math;
use measurements::data_table;
use observables::Observable;
use parameters::Parameter;
use parts::condition_row;
use sbml::Sbml;
use tsv::Tsv;

/// A PEtab problem, imported.
#[derive(Clone, Debug)]
pub struct Imported {
    /// The problem as a model file, its measurements held in memory.
    pub model: Model,
    /// The model file's text (what `sysid` would read as `--model`, but for the data).
    pub text: String,
    /// What the import changed that the user should know of, each naming the file, line and
    /// id (an estimated parameter's nominal value outside its bounds, moved onto the bound
    /// as the fits' start).
    pub warnings: Vec<String>,
    /// The parameter table's nominal values that lie outside their bounds, by parameter id,
    /// where they can be represented on the parameter's scale (positive on a log scale): the
    /// fits start from the bound, but the NLL at nominal (`sysid evaluate`) is taken here, at
    /// the point the problem was published with.
    pub nominal: Vec<(String, f64)>,
}

#[derive(Deserialize)]
struct ProblemFile {
    format_version: serde_saphyr_value::Version,
    parameter_file: String,
    problems: Vec<SubProblem>,
}

#[derive(Deserialize)]
struct SubProblem {
    sbml_files: Vec<String>,
    condition_files: Vec<String>,
    measurement_files: Vec<String>,
    observable_files: Vec<String>,
}

mod serde_saphyr_value {
    use serde::Deserialize;

    /// `format_version`: a number or a string.
    #[derive(Deserialize)]
    #[serde(untagged)]
    pub enum Version {
        Number(f64),
        Text(String),
    }

    impl Version {
        pub fn is_one(&self) -> bool {
            match self {
                Version::Number(v) => (*v - 1.0).abs() < 1e-12,
                Version::Text(s) => s.trim() == "1" || s.trim().starts_with("1."),
            }
        }
    }
}

/// Words the model file's expression language keeps for itself: an SBML or PEtab id that is
/// one of them gets a trailing `_`.
const RESERVED: &[&str] = &[
    "t", "exp", "log", "sqrt", "sin", "cos", "tan", "tanh", "abs", "min", "max", "if", "lt", "le",
    "gt", "ge", "eq", "ne", "and", "or", "not",
];

/// The YAML reader's error as the user's: at its line and column where it gives them, in
/// words rather than the reader's types ("cannot deserialize null into string; use
/// Option<String>" is a missing value where a text was expected).
fn yaml_error(file: &str, message: &str) -> ModelError {
    let reason = first_line(message);
    let reason = reason.strip_prefix("error: ").unwrap_or(reason);
    // The reader's advice to its programmer, not to the user.
    let reason = reason.split("; use Option<").next().unwrap_or(reason);
    let reason = match reason.split_once("cannot deserialize ") {
        Some((before, what)) => match what.split_once(" into ") {
            Some((found, expected)) => format!("{before}expected {expected}, found {found}"),
            None => reason.to_string(),
        },
        None => reason.to_string(),
    };
    let place = reason.strip_prefix("line ").and_then(|rest| {
        let (line, rest) = rest.split_once(" column ")?;
        let (column, rest) = rest.split_once(": ")?;
        Some((line.parse().ok()?, column.parse().ok()?, rest.to_string()))
    });
    match place {
        Some((line, column, rest)) => ModelError {
            file: file.to_string(),
            line: Some(line),
            column: Some(column),
            message: format!("not a PEtab problem file: {rest}"),
        },
        None => ModelError::file(file, format!("not a PEtab problem file: {reason}")),
    }
}

/// Imports the PEtab problem of the YAML file `yaml`.
pub fn import(yaml: &Path) -> Result<Imported, ModelError> {
    let name = yaml.display().to_string();
    let text = std::fs::read_to_string(yaml)
        .map_err(|e| ModelError::file(&name, format!("cannot be read: {e}")))?;
    let problem: ProblemFile =
        serde_saphyr::from_str(&text).map_err(|e| yaml_error(&name, &e.to_string()))?;
    if !problem.format_version.is_one() {
        return Err(ModelError::file(&name, "only PEtab format version 1 is supported"));
    }
    let [sub] = problem.problems.as_slice() else {
        return Err(ModelError::file(&name, "`problems` must list exactly one problem"));
    };
    let base = yaml.parent().unwrap_or(Path::new(""));
    let [sbml_file] = sub.sbml_files.as_slice() else {
        return Err(ModelError::file(&name, "`sbml_files` must name exactly one SBML file"));
    };
    let sbml_path = base.join(sbml_file);
    let sbml_text = sbml::read_text(&sbml_path)?;
    let sbml = Sbml::parse(&sbml_text, &sbml_path.display().to_string())?;
    let read_all = |files: &[String], what: &str| -> Result<Vec<Tsv>, ModelError> {
        if files.is_empty() {
            return Err(ModelError::file(&name, format!("no {what} file")));
        }
        files.iter().map(|f| Tsv::read(&base.join(f))).collect()
    };
    let tables = Tables {
        parameters: Tsv::read(&base.join(&problem.parameter_file))?,
        conditions: read_all(&sub.condition_files, "condition")?,
        measurements: read_all(&sub.measurement_files, "measurement")?,
        observables: read_all(&sub.observable_files, "observable")?,
    };
    let mut imported =
        Builder::new((&sbml, sbml_path.display().to_string()), &tables, yaml)?.build()?;
    imported.model.file.sources = std::iter::once(sbml_path)
        .chain(std::iter::once(base.join(&problem.parameter_file)))
        .chain(
            [&sub.condition_files, &sub.measurement_files, &sub.observable_files]
                .into_iter()
                .flatten()
                .map(|f| base.join(f)),
        )
        .collect();
    Ok(imported)
}

fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or(s)
}

struct Tables {
    parameters: Tsv,
    conditions: Vec<Tsv>,
    measurements: Vec<Tsv>,
    observables: Vec<Tsv>,
}

/// `template` (an error at a cell, its message the cell's prefix) with `message`.
fn at(template: &ModelError, message: impl std::fmt::Display) -> ModelError {
    ModelError { message: format!("{}{message}", template.message), ..template.clone() }
}

struct Builder<'a> {
    sbml: &'a Sbml,
    /// The SBML file, as errors name it.
    sbml_file: String,
    tables: &'a Tables,
    yaml: &'a Path,
    /// The model file's name of each SBML and PEtab id.
    names: HashMap<String, String>,
    /// Assignment rules and the initial assignments of parameters, resolved.
    rules: HashMap<String, Math>,
    /// What the events make of the variables they set: a switch in time between the
    /// variable's own value (before any event) and the events' values.
    events: HashMap<String, Math>,
    /// The events that reset states, written as the model file's `[[events]]`.
    state_events: Vec<events::StateEvent>,
    parameters: BTreeMap<String, (Parameter, usize)>,
    observables: HashMap<String, Observable>,
    /// The species a condition table sets the initial value of, each with the two known
    /// parameters that carry the setting into the model file: a switch (0 by default, 1
    /// where a condition sets it) and the value it sets.
    overrides: Vec<Override>,
    /// See [`Imported::warnings`].
    warnings: Vec<String>,
    /// See [`Imported::nominal`].
    outside: Vec<(String, f64)>,
}

/// A species whose initial value a condition sets: its initial value in the model file is
/// `switch · value + (1 − switch) · (the SBML initial value)`, with `switch` and `value`
/// known parameters (0 by default) that an experiment's `set` or `preequilibrate` gives.
struct Override {
    species: String,
    switch: String,
    value: String,
}

impl<'a> Builder<'a> {
    fn new(
        (sbml, sbml_file): (&'a Sbml, String),
        tables: &'a Tables,
        yaml: &'a Path,
    ) -> Result<Self, ModelError> {
        let mut b = Self {
            sbml,
            sbml_file,
            tables,
            yaml,
            names: HashMap::new(),
            rules: HashMap::new(),
            events: HashMap::new(),
            state_events: Vec::new(),
            parameters: BTreeMap::new(),
            observables: HashMap::new(),
            overrides: Vec::new(),
            warnings: Vec::new(),
            outside: Vec::new(),
        };
        b.read_parameters()?;
        b.read_observables()?;
        b.check_conditions()?;
        b.warn_sizeless();
        b.name_ids();
        b.name_overrides();
        b.resolve_rules()?;
        b.resolve_events()?;
        Ok(b)
    }

    /// A warning for each compartment whose element gives no size, where neither the
    /// tables nor an initial assignment give one and a species in it is in concentration:
    /// SBML Level 2 and 3 leave such a size undefined, and the import takes it as 1 (as Level
    /// 1 did, and most tools do), which scales those species' rates.
    fn warn_sizeless(&mut self) {
        let s = self.sbml;
        for c in &s.sizeless {
            let given = self.parameters.contains_key(c)
                || self.set_by_conditions(c)
                || s.initial_assignments.iter().any(|a| &a.0 == c);
            let concentration = s.species.iter().any(|x| &x.compartment == c && !x.amount);
            if !given && concentration {
                let origin = self.sbml_origin_or_file(c);
                self.warnings.push(
                    at(&origin, format!("compartment `{c}` has no size: it is taken as 1"))
                        .to_string(),
                );
            }
        }
    }

    /// Gives every SBML and PEtab id its model-file name: itself, or with trailing `_`s
    /// when it is a reserved word. A species that events set is a state holding its value
    /// before any event (the events' values enter the equations as a switch in time), so
    /// its name says so: `<id>_before_events`.
    fn name_ids(&mut self) {
        let s = self.sbml;
        let ids = s
            .species
            .iter()
            .map(|x| x.id.clone())
            .chain(s.compartments.iter().map(|c| c.0.clone()))
            .chain(s.parameters.iter().map(|p| p.0.clone()))
            .chain(self.parameters.keys().cloned())
            .chain(self.observables.keys().cloned());
        let mut taken: Vec<String> = Vec::new();
        for id in ids {
            if self.names.contains_key(&id) {
                continue;
            }
            let mut name = id.clone();
            // (A species that reactions change is reset by events as a state, keeping its
            // name.)
            if s.species.iter().any(|x| x.id == id && x.fixed) && s.set_by_events(&id) {
                name.push_str("_before_events");
            }
            while RESERVED.contains(&name.as_str()) || taken.contains(&name) {
                name.push('_');
            }
            taken.push(name.clone());
            self.names.insert(id, name);
        }
    }

    fn name(&self, id: &str) -> String {
        self.names.get(id).cloned().unwrap_or_else(|| id.to_string())
    }

    /// The switch and value parameters of every species a condition table has a column
    /// for, named `<species>_initial_set` and `<species>_initial` (with `_` appended until
    /// no other name is taken).
    fn name_overrides(&mut self) {
        let columns: Vec<String> = self
            .tables
            .conditions
            .iter()
            .flat_map(|t| t.headers().iter().filter(|h| !is_condition_label(h)).cloned())
            .filter(|c| self.sbml.species.iter().any(|x| &x.id == c))
            .collect();
        for species in columns {
            if self.overrides.iter().any(|o| o.species == species) {
                continue;
            }
            let mut fresh = |suffix: &str| {
                let mut name = format!("{}{suffix}", self.name(&species));
                while self.names.contains_key(&name) || self.names.values().any(|n| n == &name) {
                    name.push('_');
                }
                self.names.insert(name.clone(), name.clone());
                name
            };
            let (switch, value) = (fresh("_initial_set"), fresh("_initial"));
            self.overrides.push(Override { species, switch, value });
        }
    }

    fn build(self) -> Result<Imported, ModelError> {
        let dynamics = self.dynamics()?;
        let measured = self.measured(&dynamics.states)?;
        let (parameters, extras) = self.split_parameters(&dynamics, &measured)?;
        let outputs = self.output_names(&measured.outputs, &dynamics.states, &parameters);
        let (measured, experiments) =
            self.merge_same_simulations(measured, &parameters, &dynamics.states)?;
        let document =
            self.document(&dynamics, &measured, (&parameters, &extras), &outputs, &experiments)?;
        // An error is the user's where its key or value has a place in the problem's files
        // (a division by 0 in a formula, say); elsewhere it is the importer's.
        let mut file = ModelFile::from_document(&document, self.yaml)?;
        for (spec, (_, rows)) in file.experiments.clone().iter().zip(&measured.experiments) {
            file.tables.push((spec.file.clone(), data_table(spec, rows, &outputs)?));
        }
        Ok(Imported {
            text: file.text.clone(),
            model: Model { file },
            warnings: self.warnings.clone(),
            nominal: self.outside.clone(),
        })
    }

    /// Whether a column of the condition table sets `id` (its values override the model's
    /// and the parameter table's, per condition).
    fn set_by_conditions(&self, id: &str) -> bool {
        self.tables.conditions.iter().any(|t| t.headers().iter().any(|h| h == id))
    }

    /// [`sbml_origin`](Self::sbml_origin), or the SBML file where it does not declare `id`.
    fn sbml_origin_or_file(&self, id: &str) -> ModelError {
        self.sbml_origin(id).unwrap_or_else(|| ModelError::file(&self.sbml_file, ""))
    }

    /// Where the SBML declares `id`, as an error there begins.
    fn sbml_origin(&self, id: &str) -> Option<ModelError> {
        let &(line, column) = self.sbml.positions.get(id)?;
        Some(ModelError {
            file: self.sbml_file.clone(),
            line: Some(line),
            column: Some(column),
            message: String::new(),
        })
    }

    /// The parameter table's row of `id`, as an error there begins.
    fn parameter_origin(&self, id: &str) -> Option<ModelError> {
        let (_, row) = self.parameters.get(id)?;
        let t = &self.tables.parameters;
        Some(t.cell(*row, t.column("parameterId")?).err(""))
    }

    /// The condition table's row of condition `id`, as an error there begins.
    fn condition_origin(&self, id: &str) -> Option<ModelError> {
        self.tables.conditions.iter().find_map(|t| {
            let row = condition_row(t, id)?;
            Some(t.cell(row, t.column("conditionId")?).err(""))
        })
    }
}
