//! The model file's text, written from what the tables and the SBML give, with a source
//! map from each of its lines back to the file, line and cell it came from.

use std::fmt::Write as _;
use std::path::Path;

use sysid_model::{ModelError, SourceMap};

use crate::Builder;
use crate::math::Math;
use crate::parameters::unknown_entry;
use crate::parts::{Dynamics, Measured, OWN, Sigma, toml_number};

impl Builder<'_> {
    /// The model file's text.
    pub(crate) fn model_text(
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
            let distribution = match o.distribution {
                "normal" => String::new(),
                other => format!(", distribution = \"{other}\""),
            };
            let entry = format!(
                "{name} = {{ value = \"{}\", sigma = {sigma}, transform = \"{}\"{distribution} }}",
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
            "[integrator]\nmethod = \"auto\"\nrtol = 1e-8\natol = 1e-12\nmax_steps = 200000"
        );
        for event in &self.state_events {
            let origin = ModelError {
                file: self.sbml_file.clone(),
                line: Some(event.at.0),
                column: Some(event.at.1),
                message: format!("event `{}`: ", event.id),
            };
            let _ = writeln!(text, "\n[[events]]");
            map.record(line(&text), 1, origin.clone());
            let _ = writeln!(text, "trigger = \"{}\"", self.render(&event.trigger));
            let resets: Vec<String> = event
                .resets
                .iter()
                .map(|(x, v)| format!("{} = \"{}\"", self.name(x), self.render(v)))
                .collect();
            map.record(line(&text), 1, origin);
            let _ = writeln!(text, "set = {{ {} }}", resets.join(", "));
        }
        Ok((text, map))
    }

    pub(crate) fn render(&self, m: &Math) -> String {
        m.render(&|n| self.name(n))
    }
}
