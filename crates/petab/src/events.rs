//! SBML events: those that fire when time reaches a value and set what nothing else
//! changes, as switches in time; those that reset states, or fire on a condition of the
//! state, as the model file's `[[events]]`.

use sysid_model::ModelError;

use crate::Builder;
use crate::math::{Math, Rel};

/// An event that resets states: the model file's `[[events]]`.
pub(crate) struct StateEvent {
    /// The trigger: a comparison (<, ≤, >, ≥) of the dynamics' expressions.
    pub(crate) trigger: Math,
    /// (state, value) of each assignment.
    pub(crate) resets: Vec<(String, Math)>,
    /// The event's id and its line and column in the SBML file.
    pub(crate) id: String,
    pub(crate) at: (usize, usize),
}

/// One event's setting of a variable: when t reaches τ (`rel` is ≥ or >), the value; whether
/// its trigger counts as true before the start.
pub(crate) struct Firing {
    pub(crate) rel: Rel,
    pub(crate) tau: Math,
    pub(crate) value: Math,
    pub(crate) initially_true: bool,
}

impl Builder<'_> {
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
    pub(crate) fn resolve_events(&mut self) -> Result<(), ModelError> {
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
            if self.is_state_event(event) {
                let state_event = self.state_event(event).map_err(refuse)?;
                self.state_events.push(state_event);
                continue;
            }
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
}

impl Builder<'_> {
    /// Whether `event` is a state event: it resets a state (a species that reactions or a
    /// rate rule change, a parameter with a rate rule), or its trigger depends on one.
    fn is_state_event(&self, event: &crate::sbml::Event) -> bool {
        let trigger = self.ruled(&event.trigger);
        event.assignments.iter().any(|(v, _)| self.is_state(v))
            || trigger.names().iter().any(|n| self.is_state(n))
    }

    /// Whether `id` is a state that the integration changes: a species that reactions or a
    /// rate rule change, or a parameter with a rate rule.
    fn is_state(&self, id: &str) -> bool {
        let s = self.sbml;
        s.rate_rules.iter().any(|r| r.0 == id)
            || s.species.iter().any(|x| x.id == id && !x.fixed && !self.rules.contains_key(id))
    }

    /// `event` as a model file's `[[events]]` entry: its trigger a comparison, every
    /// assignment to a state; what else it would need is refused, with the reason.
    fn state_event(&self, event: &crate::sbml::Event) -> Result<StateEvent, String> {
        let trigger = self.dynamic(&event.trigger);
        if !matches!(trigger, Math::Compare(Rel::Lt | Rel::Le | Rel::Gt | Rel::Ge, _, _)) {
            return Err(
                "it resets states or depends on them, and its trigger is not one comparison (<, ≤, >, ≥), which is not supported".into(),
            );
        }
        if !event.initially_true {
            return Err(
                "its trigger has initialValue=\"false\" (it fires at the start where it holds there), which events that reset states do not support".into(),
            );
        }
        let mut resets = Vec::new();
        for (variable, value) in &event.assignments {
            if !self.is_state(variable) {
                return Err(format!(
                    "it sets `{variable}`, which is not a state, beside states or on a trigger of states: such an event may only reset states (species that reactions change, variables of rate rules)"
                ));
            }
            resets.push((variable.clone(), self.dynamic(value)));
        }
        Ok(StateEvent { trigger, resets, id: event.id.clone(), at: event.at })
    }
}
