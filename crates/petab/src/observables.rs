//! The observable table: each observable's formula, noise formula and transformation,
//! with a measurement row's parameters in place of its placeholders.

use sysid_model::ModelError;

use crate::math::{Math, parse_formula};
use crate::parts::{OWN, Output, scale_of};
use crate::tsv::{Cell, Tsv};
use crate::{Builder, tsv};

/// An observable of the observable table.
pub(crate) struct Observable {
    pub(crate) formula: Math,
    pub(crate) noise: Math,
    pub(crate) transform: &'static str,
    /// Its noise distribution: "normal" or "laplace" (σ is then the Laplace scale b).
    pub(crate) distribution: &'static str,
    /// Where its formula and its noise formula are written, as errors there begin.
    pub(crate) formula_at: ModelError,
    pub(crate) noise_at: ModelError,
}

impl Builder<'_> {
    pub(crate) fn read_observables(&mut self) -> Result<(), ModelError> {
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
                let distribution = match t.cell_named(row, "noiseDistribution") {
                    None => "normal",
                    Some(c) => match c.text {
                        "" | "normal" => "normal",
                        "laplace" => "laplace",
                        other => {
                            return Err(c.err(format!(
                                "`{other}`: the noise distribution is normal or laplace"
                            )));
                        }
                    },
                };
                let observable = Observable {
                    formula: parse(t.cell(row, formula))?,
                    noise: parse(t.cell(row, noise))?,
                    transform,
                    distribution,
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

    /// Each output's name: its observable's, numbered (`__1`, `__2`, …) where the
    /// observable has several outputs, and kept apart from every other name.
    pub(crate) fn output_names(
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

    /// Checks every name of an observable's expression is something the model has, after
    /// putting the nominal value in place of a PEtab parameter that is not estimated.
    /// `written` says where an unknown name was written, so that its error is there: the
    /// formula as the observable table has it and where, then the measurement row's parameter
    /// cells that filled its placeholders (the error was at the row's observableId).
    pub(crate) fn resolve_names(
        &self,
        m: &Math,
        at: Cell<'_>,
        states: &[String],
        own: Option<&str>,
        written: (&Math, &ModelError, &[Cell<'_>]),
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
            if !self.known(&n, states) {
                let message = undefined(at.text, &n);
                let (formula, formula_at, cells) = written;
                let given = |c: &&Cell<'_>| c.text.split(';').any(|v| v.trim() == n);
                return Err(match (formula.names().contains(&n), cells.iter().find(given)) {
                    (true, _) => crate::at(formula_at, message),
                    (false, Some(cell)) => cell.err(message),
                    (false, None) => at.err(message),
                });
            }
        }
        Ok(m)
    }

    /// Whether `n` is something an observable's expression may name: its own value (in a
    /// noise formula), a state, a parameter of the table or of the model, a compartment.
    fn known(&self, n: &str, states: &[String]) -> bool {
        let s = self.sbml;
        n == OWN
            || states.iter().any(|x| x == n)
            || self.parameters.contains_key(n)
            || s.parameters.iter().any(|p| p.0 == n)
            || s.compartments.iter().any(|c| c.0 == n)
    }

    /// Checks the names of the observables no measurement uses, as a used one's are checked
    /// row by row: a name the model does not have is an error in the file whether or not a
    /// row measures it (a misspelt formula would otherwise wait for the first row that
    /// does). Their placeholders, which only a row fills, are taken as given.
    pub(crate) fn check_unused_observables(
        &self,
        used: &[&str],
        states: &[String],
    ) -> Result<(), ModelError> {
        let mut unused: Vec<(&String, &Observable)> =
            self.observables.iter().filter(|(id, _)| !used.contains(&id.as_str())).collect();
        unused.sort_by_key(|(id, _)| *id);
        for (id, o) in unused {
            let placeholder = |n: &str| {
                ["observable", "noise"].iter().any(|kind| placeholder_index(n, kind, id).is_some())
            };
            for (m, at, own) in
                [(&o.formula, &o.formula_at, None), (&o.noise, &o.noise_at, Some(id))]
            {
                let dynamic = self.dynamic(m);
                let unknown = dynamic
                    .names()
                    .into_iter()
                    .find(|n| own != Some(n) && !placeholder(n) && !self.known(n, states));
                if let Some(n) = unknown {
                    return Err(crate::at(at, undefined(id, &n)));
                }
            }
        }
        Ok(())
    }
}

/// The error of observable `id` naming `n`, which the model does not have.
fn undefined(id: &str, n: &str) -> String {
    format!(
        "observable `{id}` uses `{n}`, which is no species, parameter or compartment of the model and not in the parameter table"
    )
}

/// `formulas` with row `row`'s observable or noise parameters (`kind`) in place of their
/// `{kind}Parameter{n}_{observableId}`: numbers or parameter ids, `;`-separated in the row's
/// `{kind}Parameters` cell. One left without a value is an error at that cell. The
/// observable's parameters replace their placeholders in its noise formula too (`formulas`
/// is then the observable and the noise formula: Raia's σ = a + b · (the observable) repeats
/// the observable's scaling); the noise parameters are the noise formula's alone.
pub(crate) fn placeholders<const N: usize>(
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
    let index = |n: &str| placeholder_index(n, kind, observable.text);
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

/// n, where `name` is observable `id`'s `{kind}Parameter{n}_{id}` (`kind` "observable" or
/// "noise").
fn placeholder_index(name: &str, kind: &str, id: &str) -> Option<usize> {
    let rest = name.strip_prefix(kind)?.strip_prefix("Parameter")?;
    rest.strip_suffix(id)?.strip_suffix('_')?.parse().ok()
}

/// `text` as an error quotes it: at most 60 characters, the rest replaced by `…`.
pub(crate) fn abbreviated(text: &str) -> String {
    match text.char_indices().nth(60) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_string(),
    }
}
