//! The SBML model's dynamics: assignment rules resolved into each other, and the states
//! with their equations (from the reactions or rate rules) and initial values.

use std::collections::HashMap;

use sysid_model::ModelError;

use crate::math::Math;
use crate::parts::Dynamics;
use crate::sbml::Initial;
use crate::{Builder, math, sbml};

/// The longest chain of assignment rules, each using the next, that is resolved: the
/// resolution recurses along it.
pub(crate) const MAX_CHAIN: usize = 1_000;

/// Why a rule could not be resolved.
pub(crate) enum Unresolved {
    /// Rules that use each other in a cycle, in order.
    Cycle(Vec<String>),
    /// A chain longer than [`MAX_CHAIN`], from this rule.
    Chain(String),
    /// The rule's expression, resolved, would exceed the composed limits: which, and why.
    Composed(String, String),
}

impl Builder<'_> {
    /// Assignment rules, and initial assignments of parameters and compartments (which the
    /// parameter table does not set), substituted into each other.
    pub(crate) fn resolve_rules(&mut self) -> Result<(), ModelError> {
        let s = self.sbml;
        let species = |n: &str| s.species.iter().any(|x| x.id == n);
        // A parameter's initial assignment gives way to the parameter table and to the
        // condition table where they set it (PEtab: their values override the model's).
        let mut raw: HashMap<String, Math> = HashMap::new();
        for (v, m) in &s.initial_assignments {
            if !species(v)
                && !self.parameters.contains_key(v)
                && !s.rate_rules.iter().any(|r| &r.0 == v)
                && !self.set_by_conditions(v)
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
    pub(crate) fn ruled(&self, m: &Math) -> Math {
        m.substitute(&|n| self.rules.get(n).cloned())
    }

    /// An expression of the dynamics (an equation, an observable, a σ): the rules
    /// substituted, and each variable that events set replaced by its switch in time.
    pub(crate) fn dynamic(&self, m: &Math) -> Math {
        self.ruled(m).substitute(&|n| self.events.get(n).cloned())
    }

    /// The states (the species no assignment rule gives, and the parameters with rate
    /// rules), their equations and their initial values.
    pub(crate) fn dynamics(&self) -> Result<Dynamics, ModelError> {
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
    pub(crate) fn reaction_equation(&self, x: &sbml::Species) -> Math {
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
    pub(crate) fn species_initial(&self, x: &sbml::Species) -> Result<Math, ModelError> {
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
}

pub(crate) fn resolve(
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
pub(crate) fn substitute_deep(m: &Math, with: &HashMap<String, Math>, depth: usize) -> Math {
    let mut out = m.clone();
    for _ in 0..depth {
        if !out.names().iter().any(|n| with.contains_key(n)) {
            break;
        }
        out = out.substitute(&|n| with.get(n).cloned());
    }
    out
}
