//! The condition tables: what each condition sets, parameters, compartment sizes and
//! species' initial values.

use std::collections::HashMap;

use sysid_model::ModelError;
use sysid_model::expr::Expr;
use sysid_model::file::document::Value;

use crate::parts::{ConditionSettings, condition_row};
use crate::tsv::Cell;
use crate::{Builder, tsv};

impl Builder<'_> {
    /// Every condition is defined once over the condition tables: a second row with the
    /// same `conditionId` would be ignored (PEtab v1 requires the ids to be unique).
    pub(crate) fn check_conditions(&self) -> Result<(), ModelError> {
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

    /// Names the condition tables use as values.
    pub(crate) fn condition_values(&self) -> Vec<String> {
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
    pub(crate) fn condition_settings(
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
                        initial.push((self.name(target), self.setting_value(cell)?));
                        continue;
                    }
                    out.push((o.switch.clone(), Value::Number(1.0)));
                    out.push((o.value.clone(), self.setting_value(cell)?));
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
                out.push((self.name(target), self.setting_value(cell)?));
            }
        }
        Ok((out, initial))
    }

    /// A condition cell as the value of a `set` entry: a finite number, a parameter the
    /// parameter table fixes (its nominal value), or the name of an estimated or SBML
    /// parameter.
    pub(crate) fn setting_value(&self, cell: Cell<'_>) -> Result<Value, ModelError> {
        let name = || Value::Expr(Expr::Name(self.name(cell.text), 0));
        Ok(match tsv::parse_number(cell.text) {
            Some(v) if v.is_finite() => Value::Number(v),
            Some(v) => return Err(cell.err(format!("{v} is not a finite number"))),
            None => match self.parameters.get(cell.text) {
                Some((p, _)) if !p.estimate => Value::Number(p.nominal),
                Some(_) => name(),
                None if self.sbml.parameters.iter().any(|p| p.0 == cell.text) => name(),
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

/// Whether a condition table's column names the condition (`conditionId`, the optional
/// `conditionName`) rather than setting a parameter or species.
pub(crate) fn is_condition_label(column: &str) -> bool {
    column == "conditionId" || column == "conditionName"
}
