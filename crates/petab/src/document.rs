//! The model file's document, built from what the tables and the SBML give: its expressions
//! as trees, each key and value with the place in the problem's files it came from, so that
//! an error the model file's reader finds in it names the user's file, line and cell.

use std::path::Path;

use sysid_model::ModelError;
use sysid_model::expr::Expr;
use sysid_model::file::document::{Document, Node, Table, Value};

use crate::Builder;
use crate::math::Math;
use crate::parameters::unknown_entry;
use crate::parts::{Dynamics, Measured, OWN, Sigma};

impl Builder<'_> {
    /// The model file's document.
    pub(crate) fn document(
        &self,
        d: &Dynamics,
        m: &Measured,
        (parameters, extras): (&[String], &[String]),
        output_names: &[String],
        experiment_names: &[String],
    ) -> Result<Document, ModelError> {
        // Position 0: what the importer itself wrote, with no place in the user's files.
        let mut doc = Document::built(ModelError::file(
            &self.yaml.display().to_string(),
            "the model file made of this PEtab problem is refused, which is a bug of the importer: ",
        ));
        let mut at = |origin: Option<ModelError>| origin.map_or(0, |o| doc.origin(o));
        let names = |list: &[String]| {
            Value::Array(list.iter().map(|n| Node::new(Value::String(self.name(n)), 0)).collect())
        };
        let mut root = Table::new();
        root.push("states", names(&d.states), 0);
        root.push("parameters", names(parameters), 0);

        let mut equations = Table::new();
        for (x, e) in &d.equations {
            equations.push(self.name(x), Value::Expr(self.expr(e)), at(self.sbml_origin(x)));
        }
        let mut initial = Table::new();
        for (x, e) in &d.initial {
            let value = e.number().map_or_else(|| Value::Expr(self.expr(e)), Value::Number);
            initial.push(self.name(x), value, at(self.sbml_origin(x)));
        }
        let mut known = Table::new();
        let mut unknowns = Vec::new();
        for p in parameters {
            match self.parameters.get(p) {
                Some((q, _)) if q.estimate => unknowns.push((p, q)),
                _ => {
                    let origin = self.parameter_origin(p).or_else(|| self.sbml_origin(p));
                    known.push(self.name(p), Value::Number(self.known_value(p)?), at(origin));
                }
            }
        }
        unknowns.extend(extras.iter().map(|x| (x, &self.parameters[x].0)));

        let mut outputs = Table::new();
        for (o, name) in m.outputs.iter().zip(output_names) {
            let observable = self.observables.get(&o.observable);
            let formula_at = at(observable.map(|b| b.formula_at.clone()));
            let noise_at = at(observable.map(|b| b.noise_at.clone()));
            let mut entry = Table::new();
            entry.push("value", Value::Expr(self.expr(&o.value)), formula_at);
            let sigma = match &o.sigma {
                Sigma::Number(v) => Value::Number(*v),
                Sigma::Expression(e) => {
                    Value::Expr(e.expr(&|n| if n == OWN { name.clone() } else { self.name(n) }))
                }
            };
            entry.push("sigma", sigma, noise_at);
            entry.push("transform", Value::String(o.transform.into()), formula_at);
            if o.distribution != "normal" {
                entry.push("distribution", Value::String(o.distribution.into()), noise_at);
            }
            outputs.push(name.clone(), Value::Table(entry), formula_at);
        }
        let mut unknown_table = Table::new();
        for (p, q) in unknowns {
            let origin = at(self.parameter_origin(p));
            unknown_table.push(self.name(p), unknown_entry(q, origin), origin);
        }
        root.push("equations", Value::Table(equations), 0);
        root.push("initial", Value::Table(initial), 0);
        root.push("known", Value::Table(known), 0);
        root.push("outputs", Value::Table(outputs), 0);
        root.push("unknowns", Value::Table(unknown_table), 0);

        let measurement_file = Path::new(&self.tables.measurements[0].file)
            .file_name()
            .map_or("measurements".into(), |f| f.to_string_lossy().to_string());
        let settings = |list: &[(String, Value)], at: usize| {
            let mut t = Table::new();
            for (name, value) in list {
                t.push(name.clone(), value.clone(), at);
            }
            Value::Table(t)
        };
        let mut experiments = Vec::new();
        for ((simulation, name), (key, _)) in
            m.simulations.iter().zip(experiment_names).zip(&m.experiments)
        {
            let condition = at(self.condition_origin(&key.sim));
            let mut e = Table::new();
            e.push("name", Value::String(name.clone()), condition);
            if !simulation.also.is_empty() {
                // The conditions that set the same values: one simulation, their names too.
                let also =
                    simulation.also.iter().map(|o| Node::new(Value::String(o.clone()), condition));
                e.push("also", Value::Array(also.collect()), condition);
            }
            e.push("file", Value::String(format!("{measurement_file}#{name}")), condition);
            let (set, initial) = &simulation.settings;
            if !set.is_empty() {
                e.push("set", settings(set, condition), condition);
            }
            if let Some(pre) = &simulation.preequilibrate {
                let origin = at(key.pre.as_deref().and_then(|p| self.condition_origin(p)));
                e.push("preequilibrate", settings(pre, origin), origin);
            }
            if !initial.is_empty() {
                e.push("initial", settings(initial, condition), condition);
            }
            if simulation.steady {
                e.push("steady", Value::Bool(true), condition);
            }
            experiments.push(Node::new(Value::Table(e), condition));
        }
        root.push("experiments", Value::Array(experiments), 0);

        let mut integrator = Table::new();
        integrator.push("method", Value::String("auto".into()), 0);
        integrator.push("rtol", Value::Number(1e-8), 0);
        integrator.push("atol", Value::Number(1e-12), 0);
        integrator.push("max_steps", Value::Number(200_000.0), 0);
        root.push("integrator", Value::Table(integrator), 0);

        let mut events = Vec::new();
        for event in &self.state_events {
            let origin = at(Some(ModelError {
                file: self.sbml_file.clone(),
                line: Some(event.at.0),
                column: Some(event.at.1),
                message: format!("event `{}`: ", event.id),
            }));
            let mut resets = Table::new();
            for (x, v) in &event.resets {
                resets.push(self.name(x), Value::Expr(self.expr(v)), origin);
            }
            let mut e = Table::new();
            e.push("trigger", Value::Expr(self.expr(&event.trigger)), origin);
            e.push("set", Value::Table(resets), origin);
            events.push(Node::new(Value::Table(e), origin));
        }
        if !events.is_empty() {
            root.push("events", Value::Array(events), 0);
        }
        doc.root = root;
        Ok(doc)
    }

    /// The model file's expression of `m`, its identifiers named as the model file names
    /// them.
    pub(crate) fn expr(&self, m: &Math) -> Expr {
        m.expr(&|n| self.name(n))
    }
}
