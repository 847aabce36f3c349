//! # sysid-petab: PEtab problems as sysid model files
//!
//! A PEtab problem (PEtab-dev/PEtab, format v1) is an SBML model and four TSV tables
//! (conditions, measurements, observables, parameters) tied together by a YAML file. This
//! crate reads them and writes the same problem as a multi-experiment model file
//! ([`sysid_model::ModelFile`]), so that every method, study and report works on it without
//! knowing where it came from:
//!
//! * the SBML species, compartments, parameters, reactions and rules become states,
//!   parameters and equations ([`sbml`]: the subset it reads, and what it refuses by name);
//! * each simulation condition becomes an experiment that sets the condition table's
//!   parameters; its measurements are a data table held in memory (times may repeat);
//! * each observable, with the observable and noise parameters of a measurement row put in
//!   place of its `observableParameter{n}_{id}` / `noiseParameter{n}_{id}`, becomes an
//!   output with its σ and its transformation (one output per distinct replacement);
//! * the parameter table's estimated parameters become the unknowns, with their bounds, on a
//!   log scale where `parameterScale` is `log` or `log10` (the optimum does not depend on
//!   the base), starting from `nominalValue`; the others are known.
//!
//! * a preequilibration condition becomes the experiment's `preequilibrate`: it starts from
//!   the steady state under that condition.
//!
//! * measurements at time `inf` (steady state) become an experiment that preequilibrates
//!   under its own condition and is measured at t = 0.
//!
//! Events and laplace noise are refused naming the feature. Every error names the file, the line and the column.
#![warn(missing_docs)]

pub mod math;
pub mod sbml;
pub mod tsv;

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

use serde::Deserialize;
use sysid_model::table::Table;
use sysid_model::{Model, ModelError, ModelFile, SourceMap};

use math::{Math, Rel, parse_formula};
use sbml::{Initial, Sbml};
use tsv::{Cell, Tsv};

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

/// Imports the PEtab problem of the YAML file `yaml`.
pub fn import(yaml: &Path) -> Result<Imported, ModelError> {
    let name = yaml.display().to_string();
    let text = std::fs::read_to_string(yaml)
        .map_err(|e| ModelError::file(&name, format!("cannot be read: {e}")))?;
    let problem: ProblemFile = serde_saphyr::from_str(&text).map_err(|e| {
        ModelError::file(&name, format!("not a PEtab problem file: {}", first_line(&e.to_string())))
    })?;
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

/// A row of the parameter table.
#[derive(Clone, Debug)]
struct Parameter {
    nominal: f64,
    estimate: bool,
    lower: f64,
    upper: f64,
    log: bool,
    /// A prior: distribution, mean or location, sd or scale, and the scale it is on.
    prior: Option<PriorEntry>,
    /// Where multistart draws its starts: distribution, its two parameters, and the scale
    /// it is on (none: uniform on its scale within its bounds).
    initialization: Option<(&'static str, f64, f64, &'static str)>,
}

/// An observable of the observable table.
struct Observable {
    formula: Math,
    noise: Math,
    transform: &'static str,
    /// Where its formula and its noise formula are written, as errors there begin.
    formula_at: ModelError,
    noise_at: ModelError,
}

/// `template` (an error at a cell, its message the cell's prefix) with `message`.
fn at(template: &ModelError, message: impl std::fmt::Display) -> ModelError {
    ModelError { message: format!("{}{message}", template.message), ..template.clone() }
}

/// An output of the model file: one observable with one set of replacements.
#[derive(PartialEq)]
struct Output {
    observable: String,
    value: String,
    sigma: Sigma,
    transform: &'static str,
}

#[derive(Clone, PartialEq)]
enum Sigma {
    Number(f64),
    /// An expression in which [`OWN`] stands for the output's own name.
    Expression(String),
}

/// A measurement: its time, its output's index and its value.
type Sample = (f64, usize, f64);

/// An experiment: its preequilibration condition, if any, and its simulation condition.
/// What an experiment is made of: its preequilibration condition, its simulation condition,
/// and whether it then runs to its own steady state (the measurements at time `inf` after a
/// preequilibration).
#[derive(Clone, Debug, PartialEq)]
struct Key {
    pre: Option<String>,
    sim: String,
    steady: bool,
}

/// The states of the model file, with their equations and initial values.
struct Dynamics {
    states: Vec<String>,
    equations: Vec<(String, Math)>,
    initial: Vec<(String, Math)>,
}

/// What the measurement tables give: the outputs, and each experiment's measurements.
struct Measured {
    outputs: Vec<Output>,
    experiments: Vec<(Key, Vec<Sample>)>,
    /// Per experiment, what it sets (filled by [`Builder::merge_same_simulations`]).
    simulations: Vec<Simulation>,
}

/// A condition's entries of an experiment's `set`, and of its `initial` (the species it
/// re-initialises after a preequilibration), as model-file text.
type ConditionSettings = (Vec<String>, Vec<String>);

/// What an experiment sets, as model-file text: its condition's `set` and `initial`
/// entries, its preequilibration's, whether it runs to its own steady state, and the other
/// conditions it answers to (`also`: they set the same values).
struct Simulation {
    settings: ConditionSettings,
    preequilibrate: Option<Vec<String>>,
    steady: bool,
    also: Vec<String>,
}

/// The largest measurement the importer takes: no measured quantity is that large in any
/// unit, and the weighted square of a larger one overflows for σ below about 1e-4.
const MAX_MEASUREMENT: f64 = 1e150;

/// The largest |measurement|/σ a known σ allows: beyond it the weighted square overflows.
const MAX_WEIGHTED: f64 = 1.3e154;

/// Stands for the output's own value in a σ expression until the output is named.
const OWN: &str = "\u{1}own\u{1}";

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
            parameters: BTreeMap::new(),
            observables: HashMap::new(),
            overrides: Vec::new(),
            warnings: Vec::new(),
            outside: Vec::new(),
        };
        b.read_parameters()?;
        b.read_observables()?;
        b.check_conditions()?;
        b.name_ids();
        b.name_overrides();
        b.resolve_rules()?;
        b.resolve_events()?;
        Ok(b)
    }

    /// The parameter table. PEtab v1 requires `parameterScale` in every row and both
    /// bounds of an estimated parameter (a number: `inf` and `-inf` are numbers, an empty
    /// cell or `nan` is not); a table without them is refused where the value is missing.
    fn read_parameters(&mut self) -> Result<(), ModelError> {
        let t = &self.tables.parameters;
        let id = t.required("parameterId")?;
        let scale = t.required("parameterScale")?;
        let nominal = t.required("nominalValue")?;
        let estimate = t.required("estimate")?;
        let any_estimated = (0..t.rows.len()).any(|row| t.cell(row, estimate).text == "1");
        let (lower, upper) = match any_estimated {
            true => (Some(t.required("lowerBound")?), Some(t.required("upperBound")?)),
            false => (t.column("lowerBound"), t.column("upperBound")),
        };
        for row in 0..t.rows.len() {
            let pid = t.cell(row, id);
            pid.id("parameter")?;
            let e = t.cell(row, estimate);
            let estimated = match e.text {
                "1" => true,
                "0" => false,
                other => return Err(e.err(format!("`{other}`: estimate is 0 or 1"))),
            };
            let scale_cell = t.cell(row, scale);
            if scale_cell.text.is_empty() {
                return Err(scale_cell.err(format!(
                    "`{}` has no scale: parameterScale is lin, log or log10 in every row",
                    pid.text
                )));
            }
            let scale_name = scale_of(Some(scale_cell), "scale")?;
            let log = scale_name != "lin";
            let bound = |column: Option<usize>, default: f64| -> Result<f64, ModelError> {
                match column.map(|c| t.cell(row, c)) {
                    Some(c) if estimated && c.is_blank() => Err(c.err(format!(
                        "`{}` is estimated, so it needs this bound: a number (inf and -inf are numbers), not `{}`",
                        pid.text,
                        if c.text.is_empty() { "" } else { c.text }
                    ))),
                    Some(c) if !c.is_blank() => c.number(),
                    _ => Ok(default),
                }
            };
            let nominal_cell = t.cell(row, nominal);
            let p = Parameter {
                nominal: nominal_cell.number()?,
                estimate: estimated,
                lower: bound(lower, f64::NEG_INFINITY)?,
                upper: bound(upper, f64::INFINITY)?,
                log,
                prior: if estimated { prior(t, row, scale_name)? } else { None },
                initialization: None,
            };
            let mut p = Parameter {
                initialization: match estimated {
                    true => initialization(t, row, scale_name, p.lower, p.upper)?,
                    false => None,
                },
                ..p
            };
            if estimated {
                let c = nominal_cell;
                if !p.nominal.is_finite() {
                    return Err(c.err(format!(
                        "nominal value {} of `{}` is not a finite number",
                        p.nominal, pid.text
                    )));
                }
                if p.lower > p.upper {
                    return Err(c.err(format!(
                        "`{}` has its lower bound {} above its upper bound {}",
                        pid.text, p.lower, p.upper
                    )));
                }
                // PEtab does not require the nominal value within the bounds (Lang's
                // kDpApc_1: 0 on a log scale bounded by 1e-24): the fits start from the
                // nearest bound, and the import says so.
                if p.nominal < p.lower || p.nominal > p.upper {
                    let moved = p.nominal.clamp(p.lower, p.upper);
                    let kept = !log || p.nominal > 0.0;
                    let nll = match kept {
                        true => "at the table's value",
                        false => "there too (a log scale cannot hold the table's value)",
                    };
                    self.warnings.push(c.err(format!(
                        "nominal value {} of `{}` is outside its bounds [{}, {}]: the fits start from {moved}, and the NLL at nominal is taken {nll}",
                        p.nominal, pid.text, p.lower, p.upper
                    )).to_string());
                    if kept {
                        self.outside.push((pid.text.to_string(), p.nominal));
                    }
                    p.nominal = moved;
                }
                if log && !(p.lower > 0.0 || p.lower == f64::NEG_INFINITY && p.nominal > 0.0) {
                    return Err(c.err(format!(
                        "`{}` is estimated on a log scale, so its bounds and nominal value must be positive",
                        pid.text
                    )));
                }
            }
            if self.parameters.insert(pid.text.to_string(), (p, row)).is_some() {
                return Err(pid.err(format!("parameter `{}` is listed twice", pid.text)));
            }
        }
        Ok(())
    }

    /// Every condition is defined once over the condition tables: a second row with the
    /// same `conditionId` would be ignored (PEtab v1 requires the ids to be unique).
    fn check_conditions(&self) -> Result<(), ModelError> {
        let mut seen: HashMap<&str, (&str, usize)> = HashMap::new();
        for t in &self.tables.conditions {
            let id = t.required("conditionId")?;
            for row in 0..t.rows.len() {
                let c = t.cell(row, id);
                c.id("condition")?;
                if let Some((file, line)) = seen.insert(c.text, (&t.file, t.line(row))) {
                    return Err(c.err(format!(
                        "condition `{}` is defined a second time (first at {file}:{line}): each conditionId is one row",
                        c.text
                    )));
                }
            }
        }
        Ok(())
    }

    fn read_observables(&mut self) -> Result<(), ModelError> {
        for t in &self.tables.observables {
            let id = t.required("observableId")?;
            let formula = t.required("observableFormula")?;
            let noise = t.required("noiseFormula")?;
            for row in 0..t.rows.len() {
                let oid = t.cell(row, id);
                oid.id("observable")?;
                let parse = |c: Cell<'_>| {
                    parse_formula(c.text).map_err(|e| {
                        let mut err = c.err(format!("`{}`: {}", abbreviated(c.text), e.message));
                        err.column = err.column.map(|col| col + e.position);
                        err
                    })
                };
                let transform =
                    scale_of(t.cell_named(row, "observableTransformation"), "transformation")?;
                if let Some(c) = t.cell_named(row, "noiseDistribution") {
                    match c.text {
                        "" | "normal" => {}
                        "laplace" => {
                            return Err(c.err("laplace noise is not supported (only normal)"));
                        }
                        other => {
                            return Err(
                                c.err(format!("`{other}`: the noise distribution is normal"))
                            );
                        }
                    }
                }
                let observable = Observable {
                    formula: parse(t.cell(row, formula))?,
                    noise: parse(t.cell(row, noise))?,
                    transform,
                    formula_at: t.cell(row, formula).err(""),
                    noise_at: t.cell(row, noise).err(""),
                };
                if self.observables.insert(oid.text.to_string(), observable).is_some() {
                    return Err(oid.err(format!("observable `{}` is defined twice", oid.text)));
                }
            }
        }
        Ok(())
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
            if s.species.iter().any(|x| x.id == id) && s.set_by_events(&id) {
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

    /// Assignment rules, and initial assignments of parameters and compartments (which the
    /// parameter table does not set), substituted into each other.
    fn resolve_rules(&mut self) -> Result<(), ModelError> {
        let s = self.sbml;
        let species = |n: &str| s.species.iter().any(|x| x.id == n);
        let mut raw: HashMap<String, Math> = HashMap::new();
        for (v, m) in &s.initial_assignments {
            if !species(v)
                && !self.parameters.contains_key(v)
                && !s.rate_rules.iter().any(|r| &r.0 == v)
            {
                raw.insert(v.clone(), m.clone());
            }
        }
        for (v, m) in &s.assignment_rules {
            raw.insert(v.clone(), m.clone());
        }
        let mut resolved: HashMap<String, Math> = HashMap::new();
        for key in raw.keys() {
            let m = resolve(key, &raw, &mut resolved, &mut Vec::new()).map_err(|e| match e {
                Unresolved::Cycle(cycle) => ModelError::file(
                    &self.sbml_file,
                    format!(
                        "assignment rules refer to each other in a cycle: {}",
                        cycle.join(" → ")
                    ),
                ),
                Unresolved::Chain(rule) => self.sbml_origin(&rule).map_or_else(
                    || ModelError::file(&self.sbml_file, "assignment rules chain too deeply"),
                    |at| ModelError {
                        message: format!(
                            "the rule of `{rule}` starts a chain of more than {MAX_CHAIN} assignment rules, each using the next"
                        ),
                        ..at
                    },
                ),
                Unresolved::Composed(rule, message) => {
                    let message = format!("the assignment rule of `{rule}` {message}");
                    match self.sbml_origin(&rule) {
                        Some(at) => ModelError { message, ..at },
                        None => ModelError::file(&self.sbml_file, message),
                    }
                }
            })?;
            resolved.insert(key.clone(), m);
        }
        self.rules = resolved;
        Ok(())
    }

    /// An expression with the rules substituted.
    fn ruled(&self, m: &Math) -> Math {
        m.substitute(&|n| self.rules.get(n).cloned())
    }

    /// An expression of the dynamics (an equation, an observable, a σ): the rules
    /// substituted, and each variable that events set replaced by its switch in time.
    fn dynamic(&self, m: &Math) -> Math {
        self.ruled(m).substitute(&|n| self.events.get(n).cloned())
    }

    /// Events that fire when time reaches a value (`time ≥ τ`, τ a number or an expression
    /// of parameters) and set variables nothing else changes (a boundary or constant
    /// species, a parameter without rules) to values of parameters: the integration's
    /// state never jumps, so each such variable X is written as a switch in time,
    ///
    /// X(t) = X + Σᵢ firedᵢ(t)·(vᵢ − X),
    ///
    /// firedᵢ(t) being 1 where event i has fired (t ≥ τᵢ, and τᵢ > 0 where its trigger
    /// counts as true before the start) and no later one setting X has (of two at the same
    /// time, the later in the file). X itself keeps its value before any event. The
    /// integrators stop at each τᵢ, where the switch is; a τᵢ that is estimated moves
    /// the switch with its sensitivity. Anything else is refused, naming the event.
    fn resolve_events(&mut self) -> Result<(), ModelError> {
        let s = self.sbml;
        let species = |n: &str| s.species.iter().find(|x| x.id == n);
        let mut by_variable: Vec<(String, Vec<Firing>)> = Vec::new();
        for event in &s.events {
            let refuse = |message: String| ModelError {
                file: self.sbml_file.clone(),
                line: Some(event.at.0),
                column: Some(event.at.1),
                message: format!("event `{}`: {message}", event.id),
            };
            // Neither time nor species: a number or an expression of parameters.
            let of_parameters = |m: &Math| {
                let mut time = false;
                m.visit(&mut |x| time |= matches!(x, Math::Time));
                !time && m.names().iter().all(|n| species(n).is_none())
            };
            let trigger = self.ruled(&event.trigger);
            let (rel, tau) = match &trigger {
                Math::Compare(rel @ (Rel::Ge | Rel::Gt), a, b) if **a == Math::Time => {
                    (*rel, (**b).clone())
                }
                Math::Compare(Rel::Le, a, b) if **b == Math::Time => (Rel::Ge, (**a).clone()),
                Math::Compare(Rel::Lt, a, b) if **b == Math::Time => (Rel::Gt, (**a).clone()),
                _ => {
                    return Err(refuse(
                        "only triggers that fire when time reaches a value (time ≥ τ) are supported"
                            .into(),
                    ));
                }
            };
            if !of_parameters(&tau) {
                return Err(refuse(
                    "its trigger time depends on species or time, which is not supported".into(),
                ));
            }
            for (variable, value) in &event.assignments {
                let why = match species(variable) {
                    Some(x) if !x.fixed => Some("reactions change"),
                    None if !s.parameters.iter().any(|p| &p.0 == variable) => {
                        Some("is no species or parameter")
                    }
                    _ if self.rules.contains_key(variable)
                        || s.rate_rules.iter().any(|r| &r.0 == variable) =>
                    {
                        Some("a rule gives")
                    }
                    _ => None,
                };
                if let Some(why) = why {
                    return Err(refuse(format!(
                        "it sets `{variable}`, which {why}: events may only set what nothing else changes (boundary or constant species, parameters without rules), since resetting a state is not supported"
                    )));
                }
                let value = self.ruled(value);
                if !of_parameters(&value) || value.names().iter().any(|n| s.set_by_events(n)) {
                    return Err(refuse(format!(
                        "the value it gives `{variable}` depends on species, time or variables that events set, which is not supported"
                    )));
                }
                let entry = match by_variable.iter().position(|(v, _)| v == variable) {
                    Some(i) => &mut by_variable[i].1,
                    None => {
                        by_variable.push((variable.clone(), Vec::new()));
                        &mut by_variable.last_mut().expect("pushed").1
                    }
                };
                entry.push(Firing {
                    rel,
                    tau: tau.clone(),
                    value,
                    initially_true: event.initially_true,
                });
            }
        }
        for (variable, events) in by_variable {
            let x = || Math::Name(variable.clone());
            let compare = |rel: Rel, a: Math, b: Math| Math::Compare(rel, Box::new(a), Box::new(b));
            // Where event i has fired: t reached τ (after the start, where its trigger counts
            // as true before it).
            let reached = |f: &Firing| {
                let mut factors = vec![compare(f.rel, Math::Time, f.tau.clone())];
                if f.initially_true {
                    factors.push(compare(Rel::Gt, f.tau.clone(), Math::Num(0.0)));
                }
                factors
            };
            let mut terms = vec![x()];
            for (i, event) in events.iter().enumerate() {
                let mut factors = reached(event);
                for (j, later) in events.iter().enumerate().filter(|(j, _)| *j != i) {
                    // Event j supersedes i where it has fired too, at a later time (or at
                    // the same time, coming later in the file).
                    let order = if j > i { Rel::Ge } else { Rel::Gt };
                    let mut overrides = reached(later);
                    overrides.push(compare(order, later.tau.clone(), event.tau.clone()));
                    factors
                        .push(Math::Sub(Box::new(Math::Num(1.0)), Box::new(Math::Mul(overrides))));
                }
                factors.push(Math::Sub(Box::new(event.value.clone()), Box::new(x())));
                terms.push(Math::Mul(factors));
            }
            self.events.insert(variable, Math::Add(terms));
        }
        Ok(())
    }

    fn build(self) -> Result<Imported, ModelError> {
        let dynamics = self.dynamics()?;
        let measured = self.measured(&dynamics.states)?;
        let (parameters, extras) = self.split_parameters(&dynamics, &measured);
        let outputs = self.output_names(&measured.outputs, &dynamics.states, &parameters);
        let (measured, experiments) =
            self.merge_same_simulations(measured, &parameters, &dynamics.states)?;
        let (text, source_map) =
            self.model_text(&dynamics, &measured, (&parameters, &extras), &outputs, &experiments)?;
        // An error in the text is the user's where the map knows the line's origin (a
        // division by 0 in a formula, say); elsewhere it is the importer's.
        let mut file = ModelFile::parse(&text, self.yaml).map_err(|e| {
            source_map.find(&e).unwrap_or_else(|| ModelError {
                message: format!(
                    "the model file made of this PEtab problem is refused, which is a bug of the importer: {} (line {} of the text it made)",
                    e.message,
                    e.line.unwrap_or(0)
                ),
                line: None,
                column: None,
                ..e
            })
        })?;
        file.source_map = source_map;
        for (spec, (_, rows)) in file.experiments.clone().iter().zip(&measured.experiments) {
            file.tables.push((spec.file.clone(), data_table(spec, rows, &outputs)?));
        }
        Ok(Imported {
            model: Model { file },
            text,
            warnings: self.warnings.clone(),
            nominal: self.outside.clone(),
        })
    }

    /// The states (the species no assignment rule gives, and the parameters with rate
    /// rules), their equations and their initial values.
    fn dynamics(&self) -> Result<Dynamics, ModelError> {
        let s = self.sbml;
        let rate_ruled = |n: &str| s.rate_rules.iter().find(|r| r.0 == n).map(|r| &r.1);
        let species: Vec<&sbml::Species> =
            s.species.iter().filter(|x| !self.rules.contains_key(&x.id)).collect();
        let ruled_parameters: Vec<&(String, f64)> =
            s.parameters.iter().filter(|p| rate_ruled(&p.0).is_some()).collect();
        let mut states: Vec<String> = species.iter().map(|x| x.id.clone()).collect();
        states.extend(ruled_parameters.iter().map(|p| p.0.clone()));
        if let Some((v, _)) = s.rate_rules.iter().find(|(v, _)| !states.contains(v)) {
            return Err(ModelError::file(
                &self.sbml_file,
                format!("a rate rule for `{v}`, which is no species or parameter"),
            ));
        }
        let mut equations: Vec<(String, Math)> = Vec::new();
        let mut initial: Vec<(String, Math)> = Vec::new();
        for x in &species {
            let equation = match rate_ruled(&x.id) {
                Some(r) => self.dynamic(r),
                None => self.reaction_equation(x),
            };
            equations.push((x.id.clone(), equation));
            let mut m = self.species_initial(x)?;
            if let Some(o) = self.overrides.iter().find(|o| o.species == x.id) {
                // switch · value + (1 − switch) · m
                let switch = || Math::Name(o.switch.clone());
                m = Math::Add(vec![
                    Math::Mul(vec![switch(), Math::Name(o.value.clone())]),
                    Math::Mul(vec![
                        Math::Add(vec![Math::Num(1.0), Math::Neg(Box::new(switch()))]),
                        m,
                    ]),
                ]);
            }
            initial.push((x.id.clone(), m));
        }
        for p in ruled_parameters {
            equations.push((p.0.clone(), self.dynamic(rate_ruled(&p.0).expect("filtered"))));
            let m = s
                .initial_assignments
                .iter()
                .find(|a| a.0 == p.0)
                .map_or(Math::Num(p.1), |a| self.ruled(&a.1));
            initial.push((p.0.clone(), m));
        }
        // An initial value may use another species' initial value.
        let initial_of: HashMap<String, Math> = initial.iter().cloned().collect();
        let initial =
            initial.iter().map(|(x, m)| (x.clone(), substitute_deep(m, &initial_of, 8))).collect();
        Ok(Dynamics { states, equations, initial })
    }

    /// dx/dt of a species from the reactions: Σ stoichiometry · rate, divided by its
    /// compartment's size where the species is a concentration; 0 for a boundary or
    /// constant species.
    fn reaction_equation(&self, x: &sbml::Species) -> Math {
        if x.fixed {
            return Math::Num(0.0);
        }
        let mut terms = Vec::new();
        for r in &self.sbml.reactions {
            let count = |list: &[(String, f64)]| -> f64 {
                list.iter().filter(|p| p.0 == x.id).map(|p| p.1).sum()
            };
            let net = count(&r.products) - count(&r.reactants);
            if net != 0.0 {
                let rate = self.dynamic(&r.rate);
                terms.push(match net {
                    1.0 => rate,
                    -1.0 => Math::Neg(Box::new(rate)),
                    _ => Math::Mul(vec![Math::Num(net), rate]),
                });
            }
        }
        let sum = match terms.len() {
            0 => return Math::Num(0.0),
            1 => terms.remove(0),
            _ => Math::Add(terms),
        };
        match x.amount {
            true => sum,
            false => Math::Div(Box::new(sum), Box::new(Math::Name(x.compartment.clone()))),
        }
    }

    /// A species' initial value in its own units: its initial assignment, or its initial
    /// concentration or amount converted by the compartment's size.
    fn species_initial(&self, x: &sbml::Species) -> Result<Math, ModelError> {
        if let Some((_, m)) = self.sbml.initial_assignments.iter().find(|a| a.0 == x.id) {
            return Ok(self.ruled(m));
        }
        let size = || Box::new(Math::Name(x.compartment.clone()));
        match (x.initial, x.amount) {
            (Some(Initial::Concentration(c)), false) | (Some(Initial::Amount(c)), true) => {
                Ok(Math::Num(c))
            }
            (Some(Initial::Concentration(c)), true) => Ok(Math::Mul(vec![Math::Num(c), *size()])),
            (Some(Initial::Amount(a)), false) => Ok(Math::Div(Box::new(Math::Num(a)), size())),
            (None, _) => Err(ModelError::file(
                &self.sbml_file,
                format!("species `{}` has no initial value", x.id),
            )),
        }
    }

    /// The outputs and the experiments' measurements, from the measurement table.
    fn measured(&self, states: &[String]) -> Result<Measured, ModelError> {
        let mut measured =
            Measured { outputs: Vec::new(), experiments: Vec::new(), simulations: Vec::new() };
        for t in &self.tables.measurements {
            for row in 0..t.rows.len() {
                self.measurement(t, row, states, &mut measured)?;
            }
        }
        if measured.experiments.is_empty() {
            return Err(ModelError::file(&self.tables.measurements[0].file, "no measurements"));
        }
        Ok(measured)
    }

    /// One experiment for the conditions that set the same values after the same
    /// preequilibration (the same settings, to the text of the model file): they are one
    /// simulation, integrated once, and their measurements are its data. Bachmann's 36
    /// conditions are 12 simulations. The experiment keeps the first condition's name and
    /// answers to the others' (`also`). Returns the experiments, each with what it sets
    /// (the model file's text is written from it), and their names.
    fn merge_same_simulations(
        &self,
        measured: Measured,
        parameters: &[String],
        states: &[String],
    ) -> Result<(Measured, Vec<String>), ModelError> {
        let names = experiment_names(&measured.experiments);
        let mut merged = Measured {
            outputs: measured.outputs,
            experiments: Vec::new(),
            simulations: Vec::new(),
        };
        let mut kept = Vec::new();
        for ((key, samples), name) in measured.experiments.into_iter().zip(names) {
            let Key { pre, sim, steady } = &key;
            let simulation = Simulation {
                settings: self.condition_settings(sim, parameters, states, pre.as_deref())?,
                preequilibrate: match pre {
                    Some(p) => Some(self.condition_settings(p, parameters, states, None)?.0),
                    None => None,
                },
                steady: *steady,
                also: Vec::new(),
            };
            let same = |s: &Simulation| {
                (&s.settings, &s.preequilibrate, s.steady)
                    == (&simulation.settings, &simulation.preequilibrate, simulation.steady)
            };
            match merged.simulations.iter().position(same) {
                Some(i) => {
                    merged.experiments[i].1.extend(samples);
                    merged.simulations[i].also.push(name);
                }
                None => {
                    merged.experiments.push((key, samples));
                    merged.simulations.push(simulation);
                    kept.push(name);
                }
            }
        }
        Ok((merged, kept))
    }

    /// Reads row `row` of a measurement table into `measured`: its experiment (conditions),
    /// its output (the observable with this row's parameters) and its time and value.
    fn measurement(
        &self,
        t: &Tsv,
        row: usize,
        states: &[String],
        measured: &mut Measured,
    ) -> Result<(), ModelError> {
        let known_condition = |c: Cell<'_>| -> Result<String, ModelError> {
            match self.tables.conditions.iter().any(|ct| condition_row(ct, c.text).is_some()) {
                true => Ok(c.text.to_string()),
                false => {
                    Err(c.err(format!("condition `{}` is not in the condition table", c.text)))
                }
            }
        };
        let pre = match t.cell_named(row, "preequilibrationConditionId") {
            Some(c) if !c.is_blank() => Some(known_condition(c)?),
            _ => None,
        };
        let oc = t.cell(row, t.required("observableId")?);
        let observable = self
            .observables
            .get(oc.text)
            .ok_or_else(|| oc.err(format!("`{}` is not in the observable table", oc.text)))?;
        let simulation = known_condition(t.cell(row, t.required("simulationConditionId")?))?;
        let time_cell = t.cell(row, t.required("time")?);
        let mut time = time_cell.number()?;
        let (mut pre, mut steady) = (pre, false);
        if time == f64::INFINITY {
            // At steady state: an experiment of its own, measured at once, that starts from
            // the steady state under its condition: a preequilibration under its own
            // condition, or after its preequilibration, its own steady state from there.
            match pre {
                Some(_) => steady = true,
                None => pre = Some(simulation.clone()),
            }
            time = 0.0;
        }
        if time < 0.0 {
            return Err(time_cell.err(format!("time {time} is before the experiment starts at 0")));
        }
        if pre.is_some()
            && let Some(event) = self.sbml.events.first()
        {
            let c = t.cell_named(row, "preequilibrationConditionId").unwrap_or(time_cell);
            return Err(c.err(format!(
                "a preequilibration (or a steady state) in a model with events (event `{}`) is not supported",
                event.id
            )));
        }
        let value_cell = t.cell(row, t.required("measurement")?);
        let value = value_cell.number()?;
        if !value.is_finite() {
            return Err(value_cell.err("the measurement is not finite"));
        }
        if value.abs() > MAX_MEASUREMENT {
            return Err(value_cell.err(format!(
                "{value:e} is too large for least squares: no measured quantity is that large, and its weighted square overflows for σ below about 1e-4 (the largest magnitude taken is {MAX_MEASUREMENT:e}; a unit slip?)"
            )));
        }
        if observable.transform != "lin" && value <= 0.0 {
            return Err(value_cell.err(format!(
                "{value} is not positive, and `{}` is measured on the {} scale",
                oc.text, observable.transform
            )));
        }
        let [formula, noise] =
            placeholders(t, row, oc, [&observable.formula, &observable.noise], "observable")?;
        let [noise] = placeholders(t, row, oc, [&noise], "noise")?;
        let value_math = self.resolve_names(&self.dynamic(&formula), oc, states, None)?;
        let noise_math = self.resolve_names(&self.dynamic(&noise), oc, states, Some(oc.text))?;
        let output = Output {
            observable: oc.text.to_string(),
            value: value_math.render(&|n| self.name(n)),
            sigma: match noise_math.number() {
                Some(v) if sysid_model::file::check_sigma(v).is_ok() => {
                    if observable.transform == "lin" && value.abs() / v > MAX_WEIGHTED {
                        return Err(value_cell.err(format!(
                            "{value:e} is too large for least squares with σ = {v:e}: its weighted square overflows (the largest usable magnitude is {MAX_WEIGHTED:.1e}·σ)"
                        )));
                    }
                    Sigma::Number(v)
                }
                Some(v) => {
                    let problem = sysid_model::file::check_sigma(v).err().unwrap_or_default();
                    let message = format!("σ of `{}` {problem}", oc.text);
                    let placeholder =
                        observable.noise.names().iter().any(|n| n.starts_with("noiseParameter"));
                    return Err(match (placeholder, t.cell_named(row, "noiseParameters")) {
                        (true, Some(c)) => c.err(message),
                        _ => at(&observable.noise_at, message),
                    });
                }
                None => Sigma::Expression(noise_math.render(&|n| {
                    if n == OWN { OWN.to_string() } else { self.name(n) }
                })),
            },
            transform: observable.transform,
        };
        let outputs = &mut measured.outputs;
        let index = match outputs.iter().position(|o| o == &output) {
            Some(i) => i,
            None => {
                outputs.push(output);
                outputs.len() - 1
            }
        };
        let key = Key { pre, sim: simulation, steady };
        match measured.experiments.iter_mut().find(|e| e.0 == key) {
            Some(e) => e.1.push((time, index, value)),
            None => measured.experiments.push((key, vec![(time, index, value)])),
        }
        Ok(())
    }

    /// The model's parameters (the SBML's parameters and compartments that are no rule or
    /// state, and the estimated PEtab parameters an output uses or nothing uses) and the
    /// unknowns of their own (estimated PEtab parameters only σ and settings use). A PEtab
    /// parameter that is not estimated is its nominal value wherever it appears.
    fn split_parameters(&self, d: &Dynamics, m: &Measured) -> (Vec<String>, Vec<String>) {
        let s = self.sbml;
        let mut parameters: Vec<String> = s
            .parameters
            .iter()
            .map(|p| p.0.clone())
            .chain(s.compartments.iter().map(|c| c.0.clone()))
            .filter(|p| !self.rules.contains_key(p) && !d.states.contains(p))
            .chain(self.overrides.iter().flat_map(|o| [o.switch.clone(), o.value.clone()]))
            .collect();
        let sbml_id = |id: &str| {
            s.parameters.iter().any(|p| p.0 == id)
                || s.compartments.iter().any(|c| c.0 == id)
                || s.species.iter().any(|x| x.id == id)
        };
        let in_outputs: Vec<String> = m.outputs.iter().flat_map(|o| names_in(&o.value)).collect();
        let elsewhere: Vec<String> = m
            .outputs
            .iter()
            .filter_map(|o| match &o.sigma {
                Sigma::Expression(e) => Some(names_in(e)),
                Sigma::Number(_) => None,
            })
            .flatten()
            .chain(self.condition_values())
            .chain(d.initial.iter().flat_map(|(_, m)| m.names()).map(|n| self.name(&n)))
            .chain(d.equations.iter().flat_map(|(_, m)| m.names()).map(|n| self.name(&n)))
            .collect();
        let mut extras = Vec::new();
        for (id, (p, _)) in &self.parameters {
            if sbml_id(id) || !p.estimate {
                continue;
            }
            let n = self.name(id);
            if in_outputs.contains(&n) || !elsewhere.contains(&n) {
                parameters.push(id.clone());
            } else {
                extras.push(id.clone());
            }
        }
        (parameters, extras)
    }

    /// Each output's name: its observable's, numbered (`__1`, `__2`, …) where the
    /// observable has several outputs, and kept apart from every other name.
    fn output_names(
        &self,
        outputs: &[Output],
        states: &[String],
        parameters: &[String],
    ) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for o in outputs {
            let count = outputs.iter().filter(|p| p.observable == o.observable).count();
            let base = self.name(&o.observable);
            let mut name = match count {
                1 => base.clone(),
                _ => {
                    let k = names.iter().filter(|n| n.starts_with(&format!("{base}__"))).count();
                    format!("{base}__{}", k + 1)
                }
            };
            while names.contains(&name)
                || states.iter().chain(parameters).any(|s| self.name(s) == name)
            {
                name.push('_');
            }
            names.push(name);
        }
        names
    }

    /// The known value of a model parameter that the parameter table does not estimate:
    /// its nominal value there, else its SBML value or size.
    fn known_value(&self, p: &str) -> Result<f64, ModelError> {
        if self.overrides.iter().any(|o| o.switch == p || o.value == p) {
            return Ok(0.0);
        }
        let s = self.sbml;
        let value = match self.parameters.get(p) {
            Some((q, _)) => q.nominal,
            None => s
                .parameters
                .iter()
                .find(|x| x.0 == p)
                .map(|x| x.1)
                .or_else(|| s.compartments.iter().find(|c| c.0 == p).map(|c| c.1))
                .unwrap_or(f64::NAN),
        };
        match value.is_finite() {
            true => Ok(value),
            false => Err(ModelError::file(
                &self.sbml_file,
                format!("parameter `{p}` has no value, and the parameter table does not give one"),
            )),
        }
    }

    /// The model file's text.
    fn model_text(
        &self,
        d: &Dynamics,
        m: &Measured,
        (parameters, extras): (&[String], &[String]),
        output_names: &[String],
        experiment_names: &[String],
    ) -> Result<(String, SourceMap), ModelError> {
        let mut text = String::new();
        let mut map = SourceMap::new(self.yaml.display().to_string());
        // The line the next `writeln!` writes.
        let line = |text: &String| text.matches('\n').count() + 1;
        let quote = |names: &[String]| {
            names.iter().map(|n| format!("\"{}\"", self.name(n))).collect::<Vec<_>>().join(", ")
        };
        let _ = writeln!(
            text,
            "# Imported from the PEtab problem {} by sysid-petab.\n",
            self.yaml.display()
        );
        let _ = writeln!(text, "states = [{}]", quote(&d.states));
        let _ = writeln!(text, "parameters = [{}]\n", quote(parameters));
        let _ = writeln!(text, "[equations]");
        for (x, e) in &d.equations {
            if let Some(origin) = self.sbml_origin(x) {
                map.record(line(&text), 1, origin);
            }
            let _ = writeln!(text, "{} = \"{}\"", self.name(x), self.render(e));
        }
        let _ = writeln!(text, "\n[initial]");
        for (x, e) in &d.initial {
            if let Some(origin) = self.sbml_origin(x) {
                map.record(line(&text), 1, origin);
            }
            let value = e.number().map_or_else(|| format!("\"{}\"", self.render(e)), toml_number);
            let _ = writeln!(text, "{} = {value}", self.name(x));
        }
        let _ = writeln!(text, "\n[known]");
        let mut unknowns = Vec::new();
        for p in parameters {
            match self.parameters.get(p) {
                Some((q, _)) if q.estimate => unknowns.push((p, q)),
                _ => {
                    if let Some(origin) = self.parameter_origin(p).or_else(|| self.sbml_origin(p)) {
                        map.record(line(&text), 1, origin);
                    }
                    let _ =
                        writeln!(text, "{} = {}", self.name(p), toml_number(self.known_value(p)?));
                }
            }
        }
        unknowns.extend(extras.iter().map(|x| (x, &self.parameters[x].0)));
        let _ = writeln!(text, "\n[outputs]");
        for (o, name) in m.outputs.iter().zip(output_names) {
            let sigma = match &o.sigma {
                Sigma::Number(v) => toml_number(*v),
                Sigma::Expression(e) => format!("\"{}\"", e.replace(OWN, name)),
            };
            let entry = format!(
                "{name} = {{ value = \"{}\", sigma = {sigma}, transform = \"{}\" }}",
                o.value, o.transform
            );
            if let Some(observable) = self.observables.get(&o.observable) {
                let sigma_at =
                    entry.find(", sigma =").map_or(1, |b| entry[..b].chars().count() + 3);
                map.record(line(&text), 1, observable.formula_at.clone());
                map.record(line(&text), sigma_at, observable.noise_at.clone());
            }
            let _ = writeln!(text, "{entry}");
        }
        let _ = writeln!(text, "\n[unknowns]");
        for (p, q) in unknowns {
            if let Some(origin) = self.parameter_origin(p) {
                map.record(line(&text), 1, origin);
            }
            let _ = writeln!(text, "{} = {}", self.name(p), unknown_entry(q));
        }
        let _ = writeln!(text);
        let measurement_file = Path::new(&self.tables.measurements[0].file)
            .file_name()
            .map_or("measurements".into(), |f| f.to_string_lossy().to_string());
        for ((simulation, name), (key, _)) in
            m.simulations.iter().zip(experiment_names).zip(&m.experiments)
        {
            let _ = writeln!(text, "[[experiments]]");
            let _ = writeln!(text, "name = \"{name}\"");
            if !simulation.also.is_empty() {
                // The conditions that set the same values: one simulation, their names too.
                let quoted: Vec<String> =
                    simulation.also.iter().map(|o| format!("\"{o}\"")).collect();
                let _ = writeln!(text, "also = [{}]", quoted.join(", "));
            }
            let _ = writeln!(text, "file = \"{measurement_file}#{name}\"");
            let (set, initial) = &simulation.settings;
            let condition = self.condition_origin(&key.sim);
            if !set.is_empty() {
                if let Some(origin) = &condition {
                    map.record(line(&text), 1, origin.clone());
                }
                let _ = writeln!(text, "set = {{ {} }}", set.join(", "));
            }
            if let Some(pre) = &simulation.preequilibrate {
                if let Some(origin) = key.pre.as_deref().and_then(|p| self.condition_origin(p)) {
                    map.record(line(&text), 1, origin);
                }
                let _ = writeln!(text, "preequilibrate = {{ {} }}", pre.join(", "));
            }
            if !initial.is_empty() {
                if let Some(origin) = &condition {
                    map.record(line(&text), 1, origin.clone());
                }
                let _ = writeln!(text, "initial = {{ {} }}", initial.join(", "));
            }
            if simulation.steady {
                let _ = writeln!(text, "steady = true");
            }
            let _ = writeln!(text);
        }
        let _ = writeln!(
            text,
            "[integrator]\nmethod = \"rodas5p\"\nrtol = 1e-8\natol = 1e-12\nmax_steps = 200000"
        );
        Ok((text, map))
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

    fn render(&self, m: &Math) -> String {
        m.render(&|n| self.name(n))
    }

    /// Checks every name of an observable's expression is something the model has, after
    /// putting the nominal value in place of a PEtab parameter that is not estimated.
    fn resolve_names(
        &self,
        m: &Math,
        at: Cell<'_>,
        states: &[String],
        own: Option<&str>,
    ) -> Result<Math, ModelError> {
        let s = self.sbml;
        let m = m.substitute(&|n| {
            if own == Some(n) {
                return Some(Math::Name(OWN.to_string()));
            }
            match self.parameters.get(n) {
                Some((p, _))
                    if !p.estimate
                        && !s.parameters.iter().any(|x| x.0 == n)
                        && !s.compartments.iter().any(|c| c.0 == n) =>
                {
                    Some(Math::Num(p.nominal))
                }
                _ => None,
            }
        });
        for n in m.names() {
            let known = n == OWN
                || states.contains(&n)
                || self.parameters.contains_key(&n)
                || s.parameters.iter().any(|p| p.0 == n)
                || s.compartments.iter().any(|c| c.0 == n);
            if !known {
                return Err(at.err(format!(
                    "observable `{}` uses `{n}`, which is no species, parameter or compartment of the model and not in the parameter table",
                    at.text
                )));
            }
        }
        Ok(m)
    }

    /// Names the condition tables use as values.
    fn condition_values(&self) -> Vec<String> {
        let mut out = Vec::new();
        for t in &self.tables.conditions {
            for row in 0..t.rows.len() {
                for (c, _) in t.headers().iter().enumerate().filter(|(_, h)| !is_condition_label(h))
                {
                    let cell = t.cell(row, c);
                    if !cell.is_blank() && tsv::parse_number(cell.text).is_none() {
                        out.push(self.name(cell.text));
                    }
                }
            }
        }
        out
    }

    /// The `set` entries of a condition: its parameters and compartment sizes, and for each
    /// species it sets, the species' switch and value (a `NaN` cell keeps the model's
    /// initial value). `after` is the preequilibration the condition follows, if any: then
    /// the species it sets are re-initialised, the second list's `initial` entries.
    fn condition_settings(
        &self,
        condition: &str,
        model_parameters: &[String],
        states: &[String],
        after: Option<&str>,
    ) -> Result<ConditionSettings, ModelError> {
        let (mut out, mut initial) = (Vec::new(), Vec::new());
        for t in &self.tables.conditions {
            let Some(row) = condition_row(t, condition) else { continue };
            for (c, target) in t.headers().iter().enumerate() {
                if is_condition_label(target) {
                    continue;
                }
                let cell = t.cell(row, c);
                if cell.is_blank() {
                    continue;
                }
                if let Some(o) = self.overrides.iter().find(|o| &o.species == target) {
                    if tsv::parse_number(cell.text).is_some_and(f64::is_nan) {
                        continue;
                    }
                    if !states.contains(target) {
                        return Err(cell.err(format!(
                            "a condition sets the initial value of species `{target}`, which an assignment rule gives"
                        )));
                    }
                    if after.is_some() {
                        initial.push(format!(
                            "{} = {}",
                            self.name(target),
                            self.setting_value(cell)?
                        ));
                        continue;
                    }
                    out.push(format!("{} = 1", o.switch));
                    out.push(format!("{} = {}", o.value, self.setting_value(cell)?));
                    continue;
                }
                if !model_parameters.contains(target) {
                    return Err(cell.err(format!(
                        "`{target}` is no parameter or compartment of the model that a condition can set"
                    )));
                }
                if self.parameters.get(target).is_some_and(|p| p.0.estimate) {
                    return Err(cell.err(format!(
                        "`{target}` is estimated (parameter table) and set by a condition"
                    )));
                }
                out.push(format!("{} = {}", self.name(target), self.setting_value(cell)?));
            }
        }
        Ok((out, initial))
    }

    /// A condition cell as the value of a `set` entry: a finite number, a parameter the
    /// parameter table fixes (its nominal value), or the name of an estimated or SBML
    /// parameter.
    fn setting_value(&self, cell: Cell<'_>) -> Result<String, ModelError> {
        Ok(match tsv::parse_number(cell.text) {
            Some(v) if v.is_finite() => toml_number(v),
            Some(v) => return Err(cell.err(format!("{v} is not a finite number"))),
            None => match self.parameters.get(cell.text) {
                Some((p, _)) if !p.estimate => toml_number(p.nominal),
                Some(_) => format!("\"{}\"", self.name(cell.text)),
                None if self.sbml.parameters.iter().any(|p| p.0 == cell.text) => {
                    format!("\"{}\"", self.name(cell.text))
                }
                None => {
                    return Err(cell.err(format!(
                        "`{}` is not a number, nor a parameter of the model or the parameter table",
                        cell.text
                    )));
                }
            },
        })
    }
}

/// `formulas` with row `row`'s observable or noise parameters (`kind`) in place of their
/// `{kind}Parameter{n}_{observableId}`: numbers or parameter ids, `;`-separated in the row's
/// `{kind}Parameters` cell. One left without a value is an error at that cell. The
/// observable's parameters replace their placeholders in its noise formula too (`formulas`
/// is then the observable and the noise formula: Raia's σ = a + b · (the observable) repeats
/// the observable's scaling); the noise parameters are the noise formula's alone.
fn placeholders<const N: usize>(
    t: &Tsv,
    row: usize,
    observable: Cell<'_>,
    formulas: [&Math; N],
    kind: &str,
) -> Result<[Math; N], ModelError> {
    let column = format!("{kind}Parameters");
    let given = t.cell_named(row, &column);
    let list: Vec<&str> = match given {
        Some(c) if !c.is_blank() => c.text.split(';').map(str::trim).collect(),
        _ => Vec::new(),
    };
    let prefix = format!("{kind}Parameter");
    let suffix = format!("_{}", observable.text);
    let index =
        |n: &str| -> Option<usize> { n.strip_prefix(&prefix)?.strip_suffix(&suffix)?.parse().ok() };
    let replaced = formulas.map(|f| {
        f.substitute(&|n| {
            list.get(index(n)?.checked_sub(1)?).map(|v| match tsv::parse_number(v) {
                Some(x) => Math::Num(x),
                None => Math::Name((*v).to_string()),
            })
        })
    });
    for m in &replaced {
        if let Some(n) = m.names().into_iter().find(|n| index(n).is_some()) {
            return Err(given.unwrap_or(observable).err(format!(
                "`{n}` of observable `{}` is not given a value in `{column}`",
                observable.text
            )));
        }
    }
    // As many values as placeholders: a value more has nothing to replace.
    let used = formulas.iter().flat_map(|f| f.names()).filter_map(|n| index(&n)).max().unwrap_or(0);
    if list.len() > used {
        return Err(given.unwrap_or(observable).err(format!(
            "{} value{} for observable `{}`, whose {kind} formula has {used} placeholder{} ({prefix}1{suffix}, …): one value per placeholder",
            list.len(),
            if list.len() == 1 { "" } else { "s" },
            observable.text,
            if used == 1 { "" } else { "s" }
        )));
    }
    Ok(replaced)
}

/// `text` as an error quotes it: at most 60 characters, the rest replaced by `…`.
fn abbreviated(text: &str) -> String {
    match text.char_indices().nth(60) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_string(),
    }
}

/// One event's setting of a variable: when t reaches τ (`rel` is ≥ or >), the value; whether
/// its trigger counts as true before the start.
struct Firing {
    rel: Rel,
    tau: Math,
    value: Math,
    initially_true: bool,
}

/// Whether a condition table's column names the condition (`conditionId`, the optional
/// `conditionName`) rather than setting a parameter or species.
fn is_condition_label(column: &str) -> bool {
    column == "conditionId" || column == "conditionName"
}

/// Each experiment's name: its simulation condition's, and its preequilibration's too
/// where one simulation condition follows several (`SIM-after-PRE`, `SIM-steady` for the
/// steady-state measurements of SIM, `SIM-steady-after-PRE` for those after PRE).
fn experiment_names(experiments: &[(Key, Vec<Sample>)]) -> Vec<String> {
    experiments
        .iter()
        .map(|(Key { pre, sim, steady }, _)| {
            match (pre, *steady, experiments.iter().filter(|e| &e.0.sim == sim).count()) {
                (Some(pre), true, 2..) => format!("{sim}-steady-after-{pre}"),
                (Some(pre), false, 2..) if pre == sim => format!("{sim}-steady"),
                (Some(pre), false, 2..) => format!("{sim}-after-{pre}"),
                _ => sim.clone(),
            }
        })
        .collect()
}

/// An experiment's measurements as the data table its model-file experiment reads: the time
/// and a column per output it measures, a row per measurement (replicates repeat a time).
fn data_table(
    spec: &sysid_model::ExperimentSpec,
    rows: &[Sample],
    output_names: &[String],
) -> Result<Table, ModelError> {
    let mut columns: Vec<usize> = rows.iter().map(|r| r.1).collect();
    columns.sort_unstable();
    columns.dedup();
    let mut headers = vec!["t".to_string()];
    headers.extend(columns.iter().map(|&c| output_names[c].clone()));
    let table_rows = rows
        .iter()
        .map(|&(time, output, value)| {
            let mut cells = vec![None; columns.len()];
            cells[columns.iter().position(|&c| c == output).expect("listed")] = Some(value);
            (time, cells)
        })
        .collect();
    let source = spec.file.display().to_string();
    Table::from_rows(&source, headers, table_rows).map_err(|e| {
        ModelError::file(&source, format!("experiment `{}`: {}", spec.name, e.message))
    })
}

/// A scale cell (`parameterScale`, `observableTransformation`): `lin` (also empty or
/// absent), `log` or `log10`; anything else is an error naming the cell and `what` it is.
fn scale_of(cell: Option<Cell<'_>>, what: &str) -> Result<&'static str, ModelError> {
    match cell.map(|c| (c, c.text)) {
        None | Some((_, "" | "lin")) => Ok("lin"),
        Some((_, "log")) => Ok("log"),
        Some((_, "log10")) => Ok("log10"),
        Some((c, other)) => Err(c.err(format!("`{other}`: the {what} is lin, log or log10"))),
    }
}

/// The row of `condition` in a condition table.
fn condition_row(t: &Tsv, condition: &str) -> Option<usize> {
    let c = t.column("conditionId")?;
    (0..t.rows.len()).find(|&r| t.cell(r, c).text == condition)
}

/// The names of a rendered expression.
fn names_in(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    let mut after_digit = false;
    for ch in text.chars().chain(std::iter::once(' ')) {
        if ch.is_alphanumeric() || ch == '_' {
            if current.is_empty() && (ch.is_ascii_digit() || after_digit) {
                after_digit = true;
                continue;
            }
            current.push(ch);
        } else {
            after_digit = false;
            if !current.is_empty() {
                out.push(std::mem::take(&mut current));
            }
        }
    }
    out
}

/// The longest chain of assignment rules, each using the next, that is resolved: the
/// resolution recurses along it.
const MAX_CHAIN: usize = 1_000;

/// Why a rule could not be resolved.
enum Unresolved {
    /// Rules that use each other in a cycle, in order.
    Cycle(Vec<String>),
    /// A chain longer than [`MAX_CHAIN`], from this rule.
    Chain(String),
    /// The rule's expression, resolved, would exceed the composed limits: which, and why.
    Composed(String, String),
}

fn resolve(
    key: &str,
    raw: &HashMap<String, Math>,
    done: &mut HashMap<String, Math>,
    stack: &mut Vec<String>,
) -> Result<Math, Unresolved> {
    if let Some(m) = done.get(key) {
        return Ok(m.clone());
    }
    if stack.iter().any(|s| s == key) {
        let mut cycle = stack.clone();
        cycle.push(key.to_string());
        return Err(Unresolved::Cycle(cycle));
    }
    if stack.len() >= MAX_CHAIN {
        return Err(Unresolved::Chain(stack[0].clone()));
    }
    stack.push(key.to_string());
    let m = &raw[key];
    let mut replacements: HashMap<String, Math> = HashMap::new();
    for n in m.names() {
        if raw.contains_key(&n) {
            let r = resolve(&n, raw, done, stack)?;
            replacements.insert(n, r);
        }
    }
    stack.pop();
    let measures: HashMap<&String, (usize, usize)> =
        replacements.iter().map(|(n, r)| (n, r.measure())).collect();
    math::check_composed(m.measure_with(&|n| measures.get(&n.to_string()).copied()))
        .map_err(|message| Unresolved::Composed(key.to_string(), message))?;
    let out = m.substitute(&|n| replacements.get(n).cloned());
    done.insert(key.to_string(), out.clone());
    Ok(out)
}

/// Substitutes `with` into `m` until no name of it is left, at most `depth` times.
fn substitute_deep(m: &Math, with: &HashMap<String, Math>, depth: usize) -> Math {
    let mut out = m.clone();
    for _ in 0..depth {
        if !out.names().iter().any(|n| with.contains_key(n)) {
            break;
        }
        out = out.substitute(&|n| with.get(n).cloned());
    }
    out
}

/// A prior as the parameter table gives it: (distribution, mean or location, sd or scale,
/// the scale it is on).
type PriorEntry = (&'static str, f64, f64, &'static str);

fn toml_number(v: f64) -> String {
    format!("{v:e}")
}

/// The objective prior of row `row` of the parameter table, (distribution, mean or
/// location, sd or scale, scale it is on): a normal or Laplace one on the value (`normal`,
/// `laplace`) or on the parameter's scale (`parameterScaleNormal`,
/// `parameterScaleLaplace`); a uniform one adds a constant within the bounds and leaves the
/// objective's minimum where it is, so it is not added; `logNormal` and `logLaplace`, whose
/// density in θ has a term ln θ besides the residual, are refused by name.
fn prior(t: &Tsv, row: usize, scale: &'static str) -> Result<Option<PriorEntry>, ModelError> {
    let Some(kind) = t.cell_named(row, "objectivePriorType").filter(|c| !c.is_blank()) else {
        return Ok(None);
    };
    let (distribution, on) = match kind.text {
        "normal" => ("normal", "lin"),
        "parameterScaleNormal" => ("normal", scale),
        "laplace" => ("laplace", "lin"),
        "parameterScaleLaplace" => ("laplace", scale),
        "uniform" | "parameterScaleUniform" => return Ok(None),
        other => {
            return Err(kind.err(format!(
                "a prior of type `{other}` is not supported (normal, parameterScaleNormal, laplace, parameterScaleLaplace, uniform, parameterScaleUniform)"
            )));
        }
    };
    let Some(cell) = t.cell_named(row, "objectivePriorParameters").filter(|c| !c.is_blank()) else {
        return Err(kind.err(format!(
            "the prior needs `objectivePriorParameters`: {}",
            if distribution == "normal" { "mean;sd" } else { "location;scale" }
        )));
    };
    let values = numbers(&cell)?;
    match values[..] {
        [mean, sd] if mean.is_finite() && sd > 0.0 && sd.is_finite() => {
            Ok(Some((distribution, mean, sd, on)))
        }
        _ => Err(cell.err(match distribution {
            "normal" => format!("`{}`: a normal prior is mean;sd with sd > 0", cell.text),
            _ => format!("`{}`: a laplace prior is location;scale with scale > 0", cell.text),
        })),
    }
}

/// The numbers of a `;`-separated cell (prior and initialization parameters).
fn numbers(cell: &tsv::Cell<'_>) -> Result<Vec<f64>, ModelError> {
    cell.text
        .split(';')
        .map(|v| tsv::parse_number(v).ok_or_else(|| cell.err(format!("`{v}` is not a number"))))
        .collect()
}

/// Where multistart draws the starts of row `row` (PEtab's `initializationPriorType` and
/// `initializationPriorParameters`, the latter defaulting to the bounds for the uniform
/// types): `None` for the default, uniform on the parameter's scale within its bounds.
fn initialization(
    t: &Tsv,
    row: usize,
    scale: &'static str,
    lower: f64,
    upper: f64,
) -> Result<Option<(&'static str, f64, f64, &'static str)>, ModelError> {
    let Some(kind) = t.cell_named(row, "initializationPriorType").filter(|c| !c.is_blank()) else {
        return Ok(None);
    };
    let (distribution, on) = match kind.text {
        "parameterScaleUniform" => ("uniform", scale),
        "uniform" => ("uniform", "lin"),
        "normal" => ("normal", "lin"),
        "laplace" => ("laplace", "lin"),
        "logNormal" => ("normal", "log"),
        "logLaplace" => ("laplace", "log"),
        "parameterScaleNormal" => ("normal", scale),
        "parameterScaleLaplace" => ("laplace", scale),
        other => {
            return Err(kind.err(format!(
                "an initialization prior of type `{other}` is not one of PEtab's (parameterScaleUniform, uniform, normal, laplace, logNormal, logLaplace, parameterScaleNormal, parameterScaleLaplace)"
            )));
        }
    };
    let cell = t.cell_named(row, "initializationPriorParameters").filter(|c| !c.is_blank());
    let Some(cell) = cell else {
        return match (kind.text, lower.is_finite() && upper.is_finite()) {
            // The default: uniform on the scale within the bounds, as without the column.
            ("parameterScaleUniform", _) => Ok(None),
            ("uniform", true) => Ok(Some(("uniform", lower, upper, "lin"))),
            _ => Err(kind.err(format!(
                "`{}` needs `initializationPriorParameters` (two numbers, `a;b`)",
                kind.text
            ))),
        };
    };
    let values = numbers(&cell)?;
    let [a, b] = values[..] else {
        return Err(cell.err(format!("`{}`: two numbers, `a;b`", cell.text)));
    };
    let valid =
        a.is_finite() && b.is_finite() && if distribution == "uniform" { a < b } else { b > 0.0 };
    if !valid {
        let rule = if distribution == "uniform" { "a < b" } else { "b > 0" };
        return Err(
            cell.err(format!("`{}`: a {distribution} one needs finite a;b with {rule}", cell.text))
        );
    }
    Ok(Some((distribution, a, b, on)))
}

fn unknown_entry(p: &Parameter) -> String {
    let mut s = format!("{{ guess = {}", toml_number(p.nominal));
    if p.lower.is_finite() {
        let _ = write!(s, ", min = {}", toml_number(p.lower));
    }
    if p.upper.is_finite() {
        let _ = write!(s, ", max = {}", toml_number(p.upper));
    }
    if p.log {
        s.push_str(", log = true");
    }
    if let Some((distribution, mean, sd, on)) = p.prior {
        let _ = write!(
            s,
            ", prior = {{ mean = {}, sd = {}, on = \"{on}\", distribution = \"{distribution}\" }}",
            toml_number(mean),
            toml_number(sd)
        );
    }
    if let Some((distribution, a, b, on)) = p.initialization {
        let _ = write!(
            s,
            ", initialization = {{ distribution = \"{distribution}\", a = {}, b = {}, on = \"{on}\" }}",
            toml_number(a),
            toml_number(b)
        );
    }
    s.push_str(" }");
    s
}
