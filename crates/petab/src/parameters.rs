//! The parameter table: each parameter's scale, bounds, nominal value, prior and where
//! multistart draws it; which of them the model file knows and which it estimates.

use sysid_model::ModelError;
use sysid_model::file::document::{Table, Value};

use crate::math::Math;
use crate::parts::{Dynamics, Measured, Sigma, scale_of};
use crate::tsv::Tsv;
use crate::{Builder, tsv};

/// A row of the parameter table.
#[derive(Clone, Debug)]
pub(crate) struct Parameter {
    pub(crate) nominal: f64,
    pub(crate) estimate: bool,
    pub(crate) lower: f64,
    pub(crate) upper: f64,
    pub(crate) log: bool,
    /// A prior: distribution, mean or location, sd or scale, and the scale it is on.
    pub(crate) prior: Option<PriorEntry>,
    /// Where multistart draws its starts: distribution, its two parameters, and the scale
    /// it is on (none: uniform on its scale within its bounds).
    pub(crate) initialization: Option<(&'static str, f64, f64, &'static str)>,
}

/// A prior as the parameter table gives it: (distribution, mean or location, sd or scale,
/// the scale it is on).
pub(crate) type PriorEntry = (&'static str, f64, f64, &'static str);

impl Builder<'_> {
    /// The parameter table. PEtab v1 requires `parameterScale` in every row and both
    /// bounds of an estimated parameter (a number: `inf` and `-inf` are numbers, an empty
    /// cell or `nan` is not); a table without them is refused where the value is missing.
    pub(crate) fn read_parameters(&mut self) -> Result<(), ModelError> {
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
                // The bounds' own cells, for their errors (they were reported at the nominal
                // value's).
                let lower_cell = lower.map_or(c, |l| t.cell(row, l));
                if !p.nominal.is_finite() {
                    return Err(c.err(format!(
                        "nominal value {} of `{}` is not a finite number",
                        p.nominal, pid.text
                    )));
                }
                if p.lower >= p.upper {
                    // Equal bounds were refused only later, by the problem, after a warning
                    // that the nominal value lay outside them.
                    return Err(lower_cell.err(format!(
                        "`{}` has its lower bound {} {} its upper bound {}: an estimated parameter needs room between them (estimate 0 holds it at its nominal value)",
                        pid.text,
                        p.lower,
                        if p.lower > p.upper { "above" } else { "equal to" },
                        p.upper
                    )));
                }
                // PEtab does not require the nominal value within the bounds (Lang's
                // kDpApc_1: 0 on a log scale bounded by 1e-24): the fits start from the
                // nearest bound, and the import says so. A negative one on a log scale is no
                // value there (it was taken at the bound, with a warning).
                if log && p.nominal < 0.0 {
                    return Err(c.err(format!(
                        "nominal value {} of `{}` is negative, and `{}` is estimated on a log scale",
                        p.nominal, pid.text, pid.text
                    )));
                }
                if log && p.lower > f64::NEG_INFINITY && p.lower <= 0.0 {
                    return Err(lower_cell.err(format!(
                        "`{}` is estimated on a log scale, so its bounds and nominal value must be positive",
                        pid.text
                    )));
                }
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

    /// The model's parameters (the SBML's parameters and compartments that are no rule or
    /// state, and the estimated PEtab parameters an output uses) and the unknowns of their
    /// own (estimated PEtab parameters only σ and settings use). A PEtab parameter that is
    /// not estimated is its nominal value wherever it appears.
    ///
    /// A row of the parameter table that names no parameter is refused at its line, as
    /// PEtab's linter refuses it: a state of the model (a species, or a rate rule's
    /// variable), whose row gave the outputs a constant where the equations kept the state;
    /// the variable of an assignment rule, which the rule gives; and an estimated id that
    /// nothing uses (the model, an observable's formula or noise formula, measured or not, a
    /// measurement's parameters, a condition), which the data cannot determine.
    pub(crate) fn split_parameters(
        &self,
        d: &Dynamics,
        m: &Measured,
    ) -> Result<(Vec<String>, Vec<String>), ModelError> {
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
        let named = |m: &Math| m.names().into_iter().map(|n| self.name(&n)).collect::<Vec<_>>();
        let in_outputs: Vec<String> = m.outputs.iter().flat_map(|o| named(&o.value)).collect();
        let elsewhere: Vec<String> = m
            .outputs
            .iter()
            .filter_map(|o| match &o.sigma {
                Sigma::Expression(e) => Some(named(e)),
                Sigma::Number(_) => None,
            })
            .flatten()
            .chain(self.condition_values())
            .chain(d.initial.iter().flat_map(|(_, m)| m.names()).map(|n| self.name(&n)))
            .chain(d.equations.iter().flat_map(|(_, m)| m.names()).map(|n| self.name(&n)))
            .collect();
        let mut extras = Vec::new();
        for (id, (p, _)) in &self.parameters {
            let refuse = |message: String| {
                let mut e = self.parameter_origin(id).expect("a row of the parameter table");
                e.message = message;
                e
            };
            if d.states.contains(&self.name(id)) {
                return Err(refuse(format!(
                    "`{id}` is a state of the model (a species, or a rate rule's variable), not a parameter: the parameter table lists parameters, and a condition table's column of `{id}` sets its initial value"
                )));
            }
            if s.assignment_rules.iter().any(|(variable, _)| variable == id) {
                return Err(refuse(format!(
                    "`{id}` is the variable of an assignment rule of the model, which gives its value: it is not a parameter the table can set"
                )));
            }
            if sbml_id(id) || !p.estimate {
                continue;
            }
            let n = self.name(id);
            // An observable that no measurement uses still names its parameters, and PEtab
            // requires them in the table: such a one stays a parameter of the model, which
            // the data do not determine.
            let unmeasured = || {
                self.observables
                    .values()
                    .flat_map(|o| o.formula.names().into_iter().chain(o.noise.names()))
                    .any(|name| self.name(&name) == n)
            };
            if in_outputs.contains(&n) {
                parameters.push(id.clone());
            } else if elsewhere.contains(&n) {
                extras.push(id.clone());
            } else if unmeasured() {
                parameters.push(id.clone());
            } else {
                return Err(refuse(format!(
                    "`{id}` is estimated but used nowhere (not in the model, an observable's or noise formula, a measurement's parameters or a condition): the data cannot determine it"
                )));
            }
        }
        Ok((parameters, extras))
    }

    /// The known value of a model parameter that the parameter table does not estimate:
    /// its nominal value there, else its SBML value or size.
    pub(crate) fn known_value(&self, p: &str) -> Result<f64, ModelError> {
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
                .filter(|v| v.is_finite())
                .or_else(|| s.compartments.iter().find(|c| c.0 == p).map(|c| c.1))
                // A value given only by an initial assignment of numbers (one that the
                // condition table overrides, so that its rules were left out).
                .or_else(|| {
                    let (_, m) = s.initial_assignments.iter().find(|a| a.0 == p)?;
                    constant_value(&self.ruled(m))
                })
                .unwrap_or(f64::NAN),
        };
        // A compartment's size divides the amounts of its species into their
        // concentrations: 0 made them non-finite at the first integration, named by a
        // species (perhaps one in another compartment) rather than by the size.
        if s.compartments.iter().any(|c| c.0 == p)
            && !(value.is_finite() && value > 0.0)
            && !self.set_by_conditions(p)
        {
            let within: Vec<&str> = s
                .species
                .iter()
                .filter(|x| x.compartment == p && !x.amount)
                .map(|x| x.id.as_str())
                .collect();
            if !within.is_empty() || !value.is_finite() {
                // The parameter table's row where it gives the size, else the element.
                let origin =
                    self.parameter_origin(p).unwrap_or_else(|| self.sbml_origin_or_file(p));
                let species = match within.len() {
                    0 => String::new(),
                    1 => format!(
                        ": the concentration of its species `{}` is its amount divided by it",
                        within[0]
                    ),
                    _ => format!(
                        ": the concentrations of its species ({}) are their amounts divided by it",
                        within.join(", ")
                    ),
                };
                return Err(crate::at(
                    &origin,
                    format!(
                        "compartment `{p}` has size {value}, where a size must be a positive number{species}"
                    ),
                ));
            }
        }
        match value.is_finite() {
            true => Ok(value),
            false => Err(ModelError::file(
                &self.sbml_file,
                format!("parameter `{p}` has no value, and the parameter table does not give one"),
            )),
        }
    }
}

/// The value of an expression of numbers alone.
fn constant_value(m: &Math) -> Option<f64> {
    let program =
        sysid_model::expr::Program::compile(&m.expr(&|n| n.to_string()), &|_| None).ok()?;
    program.is_constant().then(|| program.eval::<f64>(0.0, &[], &[], &[]))
}

/// The objective prior of row `row` of the parameter table, (distribution, mean or
/// location, sd or scale, scale it is on): a normal or Laplace one on the value (`normal`,
/// `laplace`) or on the parameter's scale (`parameterScaleNormal`,
/// `parameterScaleLaplace`); a uniform one adds a constant within the bounds and leaves the
/// objective's minimum where it is, so it is not added; `logNormal` and `logLaplace`, whose
/// density in θ has a term ln θ besides the residual, are refused by name.
pub(crate) fn prior(
    t: &Tsv,
    row: usize,
    scale: &'static str,
) -> Result<Option<PriorEntry>, ModelError> {
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
pub(crate) fn numbers(cell: &tsv::Cell<'_>) -> Result<Vec<f64>, ModelError> {
    cell.text
        .split(';')
        .map(|v| tsv::parse_number(v).ok_or_else(|| cell.err(format!("`{v}` is not a number"))))
        .collect()
}

/// Where multistart draws the starts of row `row` (PEtab's `initializationPriorType` and
/// `initializationPriorParameters`, the latter defaulting to the bounds for the uniform
/// types): `None` for the default, uniform on the parameter's scale within its bounds.
pub(crate) fn initialization(
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

/// The `[unknowns]` entry of an estimated parameter: its guess, bounds, scale, prior and
/// where multistart draws it, each at position `at`.
pub(crate) fn unknown_entry(p: &Parameter, at: usize) -> Value {
    let mut t = Table::new();
    t.push("guess", Value::Number(p.nominal), at);
    if p.lower.is_finite() {
        t.push("min", Value::Number(p.lower), at);
    }
    if p.upper.is_finite() {
        t.push("max", Value::Number(p.upper), at);
    }
    if p.log {
        t.push("log", Value::Bool(true), at);
    }
    let string = |s: &str| Value::String(s.to_string());
    if let Some((distribution, mean, sd, on)) = p.prior {
        let mut prior = Table::new();
        prior.push("mean", Value::Number(mean), at);
        prior.push("sd", Value::Number(sd), at);
        prior.push("on", string(on), at);
        prior.push("distribution", string(distribution), at);
        t.push("prior", Value::Table(prior), at);
    }
    if let Some((distribution, a, b, on)) = p.initialization {
        let mut init = Table::new();
        init.push("distribution", string(distribution), at);
        init.push("a", Value::Number(a), at);
        init.push("b", Value::Number(b), at);
        init.push("on", string(on), at);
        t.push("initialization", Value::Table(init), at);
    }
    Value::Table(t)
}
