//! The registry is the one place a method is added: a throwaway method of this test becomes
//! available by name, in lists, and fits like the others; every entry's name is the name its
//! method reports.

use sysid_core::{
    DriverOptions, Estimate, Failure, FitError, Method, Problem, Rule,
    method::{Advance, Evaluations, Iterate, Proposal, Step, drive},
};
use sysid_ode::System;
use sysid_registry::{ENTRIES, Registry, RegistryError, Role, Settings, parse_list};
use sysid_systems::falling_body::{FallingBody, falling_body};

/// A method that never moves: it proposes its start and finds no descent, so the driver
/// stops it where it began and the certificate judges the start.
struct Stay(DriverOptions);

struct StayStep;

impl<S: System> Step<S> for StayStep {
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        ev.linearize(&z).map(Iterate::linearized)
    }
    fn propose(&mut self, _: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        Ok(Proposal { z: current.z.clone(), condition: None, gradient_norm: None, stop: None })
    }
    fn advance(
        &mut self,
        _: &Evaluations<'_, S>,
        _: &Iterate,
        _: Proposal,
    ) -> Result<Advance, Failure> {
        Ok(Advance::Stop(Rule::NoDescent))
    }
}

impl<S: System> Method<S> for Stay {
    fn name(&self) -> &str {
        "stay"
    }
    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        drive(problem, "stay", &self.0, &mut StayStep, start)
    }
}

fn with_stay() -> Registry<FallingBody> {
    Registry::standard().with("stay", |s: &Settings| Box::new(Stay(s.driver)))
}

#[test]
fn a_method_added_to_the_registry_is_listed_built_and_fitted() {
    let registry = with_stay();
    assert_eq!(registry.names().last(), Some(&"stay"));
    assert_eq!(registry.parse_list("goodman, stay").unwrap(), ["goodman", "stay"]);
    let problem = falling_body().problem(1).unwrap();
    let stay = registry.build("stay", &Settings::default()).unwrap().fit(&problem).unwrap();
    // At the start (the default guess is not the minimum): not converged, and honest about it.
    assert_eq!(stay.method, "stay");
    assert_eq!(stay.iterations, 0);
    assert!(!stay.converged(), "{}", stay.termination);
    let goodman = registry.build("goodman", &Settings::default()).unwrap().fit(&problem).unwrap();
    assert!(goodman.converged());
    assert!(goodman.cost < stay.cost);
}

#[test]
fn unknown_names_and_empty_lists_are_refused_with_the_names_there_are() {
    let registry = Registry::<FallingBody>::standard();
    let Err(RegistryError::Unknown { name, known }) = registry.parse_list("goodman,newton") else {
        panic!("`newton` is not a method");
    };
    assert_eq!(name, "newton");
    assert!(known.starts_with("goodman, goodman-halving, gauss-newton"), "{known}");
    for bad in [" , ", "", "goodman,,goodman", "goodman,", "goodman,goodman"] {
        let Err(RegistryError::List(message)) = parse_list(bad) else {
            panic!("`{bad}` is not a list of methods");
        };
        assert!(
            message.contains("empty")
                || message.contains("twice")
                || message.contains("no methods"),
            "{message}"
        );
    }
    assert!(with_stay().parse_list("stay").is_ok() && registry.parse_list("stay").is_err());
}

#[test]
fn every_entry_builds_the_method_its_name_says() {
    let settings = Settings::default();
    for (name, method) in Registry::<FallingBody>::standard().build_all(&settings) {
        assert_eq!(method.name(), name);
    }
    let names: Vec<_> = ENTRIES.iter().map(|e| e.name).collect();
    assert_eq!(Registry::<FallingBody>::standard().names(), names);
    // One default method and one reference, each a method of the table.
    for role in [Role::Default, Role::Reference] {
        assert_eq!(role.methods().len(), 1, "{role:?}");
    }
    assert!(!Role::Study.methods().is_empty() && !Role::Report.methods().is_empty());
    let mut unique = names.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), names.len());
}
