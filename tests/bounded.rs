//! Bounded optima, every method: an optimal rate exactly 0 on its lower bound
//! (`rate-on-bound`), a two-sided bound active at the optimum (`two-sided-bound`), the
//! 23-unknown compartment chain with a rate on its bound and a residual norm of 1.5e3
//! (`compartment-chain`), and rates of order 1e-5 with data of order 1e2 (`slow-rates`).
//!
//! References: `tests/data/bounded_reference.json`, computed by scipy's bounded
//! trust-region least squares (`least_squares(method="trf")`, solve_ivp DOP853 at rtol 1e-12)
//! on the data this file's ignored test writes (`cargo test --test bounded -- --ignored`,
//! then `python3 scripts/reference/bounded.py`).

use std::path::PathBuf;

use serde_json::{Value, json};
use sysid::core::Samples;
use sysid::ode::System;
use sysid::registry::{Boxed, Registry, Settings};
use sysid::systems::{self, Case, Visit, stress};

const CASES: [&str; 4] = ["rate-on-bound", "two-sided-bound", "compartment-chain", "slow-rates"];

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

/// The case named `name`, from the catalogue or the stress cases.
fn visit<V: Visit>(name: &str, visitor: V) -> V::Output {
    let found = if systems::NAMES.contains(&name) {
        systems::visit(name, visitor)
    } else {
        stress::visit(name, visitor)
    };
    found.unwrap_or_else(|| panic!("no case {name}"))
}

/// The problem of a case as the reference script reads it: knowns, unknowns with bounds and
/// start, and the data (seed 1) with their weights.
struct Export;
impl Visit for Export {
    type Output = Value;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Value {
        let data = case.data(1).unwrap();
        let series: Vec<Value> = data
            .series
            .iter()
            .map(|s| match &s.samples {
                Samples::Points { times, values } => json!({
                    "name": s.name, "weight": s.weight, "times": times, "values": values,
                }),
                Samples::Function(_) => unreachable!("discrete data"),
            })
            .collect();
        let unknowns: Vec<Value> = case
            .unknowns
            .iter()
            .map(|u| json!({"name": u.name, "guess": u.guess, "min": u.min, "max": u.max, "log": u.log}))
            .collect();
        let signature = case.system.signature();
        json!({
            "name": case.name,
            "states": signature.states(),
            "parameters": signature.parameters(),
            "t0": case.t0,
            "known": case.known.iter().map(|(n, v)| (n.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "unknowns": unknowns,
            "series": series,
        })
    }
}

#[test]
#[ignore = "writes the reference script's input: run once, then scripts/reference/bounded.py"]
fn write_reference_data() {
    let cases: Vec<Value> = CASES.iter().map(|name| visit(name, Export)).collect();
    let path = data_dir().join("bounded/problems.json");
    std::fs::write(&path, serde_json::to_string_pretty(&cases).unwrap()).unwrap();
}

/// The laboratory's methods, from the registry, with the default settings.
fn methods<S: System>() -> Vec<Boxed<S>> {
    let settings = Settings::default();
    Registry::<S>::standard().build_all(&settings).into_iter().map(|(_, m)| m).collect()
}

/// Every method from the case's default start against the reference.
struct Check<'a>(&'a Value);
impl Visit for Check<'_> {
    /// The names of the methods that reached the bounded optimum.
    type Output = Vec<String>;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Vec<String> {
        let reference = self.0;
        let problem = case.problem(1).unwrap();
        let cost = reference["cost"].as_f64().unwrap();
        let mut reached = Vec::new();
        let mut costs = Vec::new();
        for method in methods::<S>() {
            let e = method.fit(&problem).unwrap();
            let label = format!("{} / {}", case.name, e.method);
            if !e.converged() {
                // Said honestly: not a result to compare.
                println!("{label}: did not converge ({})", e.termination);
                continue;
            }
            // Cost within 1e-6 relative; estimates to 4 significant digits (5e-4 relative;
            // against the unknown's starting magnitude for one on a bound of 0).
            assert!(
                (e.cost - cost).abs() <= 1e-6 * cost,
                "{label}: cost {} against the reference {cost} ({})",
                e.cost,
                e.verdict()
            );
            for (i, name) in e.names.iter().enumerate() {
                let want = reference["values"][name].as_f64().unwrap();
                let scale = if want == 0.0 { problem.guesses()[i].abs() } else { want.abs() };
                assert!(
                    (e.values[i] - want).abs() <= 5e-4 * scale,
                    "{label}: {name} = {} against the reference {want}",
                    e.values[i]
                );
            }
            // The bounds the reference found active, and no other.
            let active: Vec<(String, String)> = e
                .active_bounds()
                .iter()
                .map(|(n, b)| (n.to_string(), format!("{b:?}").to_lowercase()))
                .collect();
            let expected: Vec<(String, String)> = reference["active"]
                .as_object()
                .unwrap()
                .iter()
                .map(|(n, b)| (n.clone(), b.as_str().unwrap().to_string()))
                .collect();
            assert_eq!(active, expected, "{label}");
            costs.push(e.cost);
            reached.push(e.method.clone());
        }
        // The methods agree with each other at the bounded optimum.
        for c in &costs {
            assert!((c - costs[0]).abs() <= 1e-8 * costs[0], "{}: costs {costs:?}", case.name);
        }
        reached
    }
}

#[test]
fn every_method_reaches_the_bounded_optimum_or_says_it_did_not() {
    let text = std::fs::read_to_string(data_dir().join("bounded_reference.json")).unwrap();
    let references: Value = serde_json::from_str(&text).unwrap();
    for name in CASES {
        let reached = visit(name, Check(&references[name]));
        println!("{name}: reached by {}", reached.join(", "));
        // The step-halving Goodman, a quasilinearization, the line-search baseline and the
        // two globalised methods (Levenberg–Marquardt, multiple shooting) must
        // reach every one.
        for needed in
            ["goodman-halving", "gauss-newton-ls", "levenberg-marquardt", "multiple-shooting"]
        {
            assert!(reached.iter().any(|m| m == needed), "{name}: {needed} did not reach it");
        }
        assert!(reached.iter().any(|m| m.starts_with("quasilinearization")), "{name}: no QL");
    }
}
