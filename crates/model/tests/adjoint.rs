//! The NLL's gradient by adjoints against the forward sensitivities' Jᵀr, on a model that uses
//! every kind of row and column the likelihood has: unknown rates on a log scale, an unknown
//! initial value, a setting that is an expression of unknowns, a noise function of the state
//! and of an unknown, a noise scale set in closed form, log10 and Laplace residuals, a prior,
//! a switch that moves with an unknown, three experiments (one preequilibrated, one with
//! samples at t0, rows of several outputs at each time), and a model with a state event,
//! which the adjoint goes back through by its jump conditions.

use std::path::{Path, PathBuf};

use sysid_core::Sensitivities;
use sysid_model::Model;

const MODEL: &str = "states = [\"A\", \"B\"]
parameters = [\"k1\", \"k2\", \"dose\", \"scale\", \"ton\", \"feed\"]
[equations]
A = \"-k1 * A + feed * if(lt(t, ton), 1, 0)\"
B = \"k1 * A - k2 * B * B\"
[initial]
A = \"dose\"
B = 0.1
[known]
scale = 1.0
feed = 0.0
[outputs]
Bm = { value = \"scale * B\", sigma = \"0.02 + sB * B\" }
Am = { value = \"A\", sigma = \"s_A\", transform = \"log10\" }
Bl = { value = \"B + A\", sigma = 0.05, distribution = \"laplace\" }
[unknowns]
k1 = { guess = 0.7, min = 1e-3, max = 1e3, log = true }
k2 = { guess = 0.4, min = 1e-3, max = 1e3, log = true, prior = { mean = -1.0, sd = 1.0, on = \"log\" } }
A0 = { guess = 1.2 }
ratio = { guess = 2.5, log = true }
sB = { guess = 0.1, log = true }
s_A = { guess = 0.1, log = true }
sc = { guess = 1.3, log = true }
ton = { guess = 1.7 }
[[experiments]]
name = \"low\"
file = \"low.csv\"
set = { dose = \"A0\" }
[[experiments]]
name = \"high\"
file = \"high.csv\"
set = { dose = \"A0 * ratio\", scale = \"sc\", feed = 0.8 }
[[experiments]]
name = \"settled\"
file = \"settled.csv\"
preequilibrate = { feed = 0.5, dose = 0.0 }
set = { dose = 0.0, feed = 0.0 }
[integrator]
method = \"rodas5p\"
rtol = 1e-10
atol = 1e-13
";

const LOW: &str = "t,Bm,Am,Bl\n0,0.11,1.15,1.3\n0.5,0.35,0.8,1.2\n1,0.5,0.6,1.1\n2,0.62,0.3,0.95\n4,0.55,0.07,0.6\n";
const HIGH: &str = "t,Bm,Am\n0.25,0.6,2.5\n1,1.3,2.0\n1.7,1.5,1.7\n3,1.55,0.9\n6,1.2,0.2\n";
const SETTLED: &str = "t,Bm,Bl\n0.5,0.9,1.5\n2,0.8,1.2\n5,0.55,0.8\n";

fn scratch(name: &str, model: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sysid-adjoint-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (file, text) in [("low.csv", LOW), ("high.csv", HIGH), ("settled.csv", SETTLED)] {
        std::fs::write(dir.join(file), text).unwrap();
    }
    std::fs::write(dir.join("m.toml"), model).unwrap();
    dir
}

/// Forward, adjoint and the automatic choice between them at the guess and at a second
/// point: the NLL to 1e-9 relative (two integrations of the states at rtol 1e-10), every
/// gradient component to 1e-7 of the largest. `fell_back`: whether every experiment is
/// expected to have run forward, or none.
fn compare(dir: &Path, fell_back: bool) {
    let problem = Model::load(&dir.join("m.toml")).unwrap().problem(None).unwrap();
    assert!(!problem.scales().is_empty(), "the test needs a noise scale in closed form");
    let guess = problem.unknowns().coordinates(&problem.guesses());
    let moved: Vec<f64> =
        guess.iter().enumerate().map(|(i, z)| z + 0.05 * (i as f64 - 3.0)).collect();
    // The experiments `auto` chose the adjoint for, at its first gradient.
    let mut chosen: Option<Vec<usize>> = None;
    for z in [guess, moved] {
        let forward = problem.nll_gradient(&z, Sensitivities::Forward).unwrap().unwrap();
        let adjoint = problem.nll_gradient(&z, Sensitivities::Adjoint).unwrap().unwrap();
        // `auto`: each experiment's part by one of the two ways, so the same gradient; its
        // choice made at the first point holds at the second, and in a clone at other noise
        // scales; an experiment with events is never by adjoint.
        let auto = problem.nll_gradient(&z, Sensitivities::Auto).unwrap().unwrap();
        let chose = chosen.get_or_insert_with(|| auto.by_adjoint.clone()).clone();
        assert_eq!(auto.by_adjoint, chose, "auto's choice is kept");
        assert_eq!(auto.fell_back, adjoint.fell_back, "auto falls back where the adjoint does");
        if fell_back {
            assert!(auto.by_adjoint.is_empty());
        }
        let again = problem.nll_gradient(&z, Sensitivities::Auto).unwrap().unwrap();
        assert_eq!(again.by_adjoint, chose);
        let other = problem
            .with_scales(&problem.scale_values().iter().map(|s| 1.5 * s).collect::<Vec<_>>());
        assert_eq!(other.nll_gradient(&z, Sensitivities::Auto).unwrap().unwrap().by_adjoint, chose);
        assert!(
            (forward.nll - adjoint.nll).abs() <= 1e-9 * forward.nll.abs().max(1.0),
            "NLL {} against {}",
            adjoint.nll,
            forward.nll
        );
        assert_eq!(forward.gradient.len(), problem.parameters().len());
        assert!(forward.fell_back.is_empty(), "forward sensitivities never fall back");
        let all: Vec<usize> = (0..problem.experiments().len()).collect();
        let expected = if fell_back { all } else { Vec::new() };
        assert_eq!(adjoint.fell_back, expected, "experiments run forward");
        let size = forward.gradient.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        // The priors' gradient on its own (what Python's adjoint and auto add for the
        // objective) is the linearization's objective gradient less the NLL's.
        let lin = problem.linearize(&z).unwrap();
        let (with, without) =
            (problem.objective_gradient(&lin, true), problem.objective_gradient(&lin, false));
        let prior = problem.prior_gradient_at(&z);
        assert!(prior.iter().any(|p| *p != 0.0), "the model has a prior");
        for (i, (w, wo)) in with.iter().zip(&without).enumerate() {
            let p = prior.get(i).copied().unwrap_or(0.0);
            assert!(
                (w - wo - p).abs() <= 1e-12 * size.max(1.0),
                "prior's ∂/∂z{i}: {p} vs {}",
                w - wo
            );
        }
        for (way, e) in [("adjoint", &adjoint), ("auto", &auto), ("auto again", &again)] {
            assert!((e.nll - forward.nll).abs() <= 1e-9 * forward.nll.abs().max(1.0), "{way}");
            for (i, (a, f)) in e.gradient.iter().zip(&forward.gradient).enumerate() {
                assert!(
                    (a - f).abs() <= 1e-7 * size,
                    "∂NLL/∂{}: {way} {a:e}, forward {f:e} (largest {size:e})",
                    problem.parameters()[i].name
                );
            }
        }
    }
}

#[test]
fn adjoint_gradient_agrees_with_forward_sensitivities() {
    compare(&scratch("plain", MODEL), false);
}

/// The model with an event (B reset when A falls below 0.2).
fn with_event() -> String {
    MODEL.replace("preequilibrate = { feed = 0.5, dose = 0.0 }\n", "").replace(
        "[integrator]",
        "[[events]]\ntrigger = \"lt(A, 0.2)\"\nset = { B = \"0.5 * B\" }\n[integrator]",
    )
}

/// The same model with an event: the adjoint goes back through it by its jump conditions,
/// none falls back, and the two agree.
#[test]
fn experiments_with_events_go_by_adjoint_through_their_jumps() {
    compare(&scratch("events", &with_event()), false);
}

/// The event halves B and leaves A, its condition's state, alone: it fires once in the
/// experiment "high" (t ≈ 4.8), by every integrator, with and without sensitivities. The
/// step landed on the event with the condition a hair above 0, and the event fired again
/// soon after (B quartered) by DOPRI5 always and by Rosenbrock steps at some values of `ton`:
/// the NLL was 137.13 or 53.86 by the way it was integrated (found by the adjoint's
/// comparison above).
#[test]
fn an_event_fires_once_whichever_way_the_model_is_integrated() {
    let dir = scratch("fires-once", &with_event());
    let mut nlls = Vec::new();
    for method in ["rodas5p", "dopri5", "dop853", "rodas4"] {
        let text = with_event().replace("method = \"rodas5p\"", &format!("method = \"{method}\""));
        std::fs::write(dir.join("m.toml"), text).unwrap();
        let problem = Model::load(&dir.join("m.toml")).unwrap().problem(None).unwrap();
        let z = problem.unknowns().coordinates(&problem.guesses());
        nlls.push(problem.nll_at(&z).unwrap().unwrap());
        nlls.push(problem.nll_gradient(&z, Sensitivities::Forward).unwrap().unwrap().nll);
    }
    for nll in &nlls {
        assert!((nll - nlls[0]).abs() <= 1e-7 * nlls[0].abs(), "{nlls:?}");
    }
}

/// The automatic choice is made once per problem and integrator, which the work of a
/// gradient shows: the first one integrates each experiment both ways, a later one each
/// experiment one way. A copy at other noise scales keeps the choice; a copy with another
/// integrator (its scheme and tolerances decide which way does less) counts again.
#[test]
fn auto_measures_once_per_integrator() {
    let dir = scratch("auto", MODEL);
    let problem = Model::load(&dir.join("m.toml")).unwrap().problem(None).unwrap();
    let z = problem.unknowns().coordinates(&problem.guesses());
    let work = |p: &sysid_core::Problem<_>| {
        p.nll_gradient(&z, Sensitivities::Auto).unwrap().unwrap().counts.integrations
    };
    let (measuring, chosen) = (work(&problem), work(&problem));
    assert!(measuring > chosen, "the measuring gradient {measuring}, a later one {chosen}");
    assert_eq!(work(&problem), chosen, "the choice is kept");
    let scales: Vec<f64> = problem.scale_values().iter().map(|s| 1.5 * s).collect();
    assert_eq!(work(&problem.with_scales(&scales)), chosen, "a copy at other scales keeps it");
    let tighter = sysid_ode::Integrator { rtol: 1e-11, ..*problem.integrator() };
    let other = problem.clone().with_integrator(tighter).unwrap();
    let (again, then) = (work(&other), work(&other));
    assert!(again > then, "another integrator measures again: {again}, then {then}");
    assert_eq!(work(&problem), chosen, "and leaves the original's choice");
}

/// A model of n states coupled through their sum, x_i' = −k_i x_i + c_i Σ x / n, with the 2n
/// rates unknown and one experiment, one output (the sum) at four times: its Jacobian is
/// dense, so the forward sensitivities' products cost n² for each of the 2n columns, and the
/// adjoint's n² in all.
fn coupled(n: usize) -> (String, String) {
    let names: Vec<String> = (1..=n).map(|i| format!("x{i}")).collect();
    let sum = names.join(" + ");
    let mut text = format!(
        "states = [{}]\nparameters = [{}]\n[equations]\n",
        names.iter().map(|x| format!("\"{x}\"")).collect::<Vec<_>>().join(", "),
        (1..=n)
            .flat_map(|i| [format!("\"k{i}\""), format!("\"c{i}\"")])
            .collect::<Vec<_>>()
            .join(", ")
    );
    for i in 1..=n {
        text += &format!("x{i} = \"-k{i} * x{i} + c{i} * ({sum}) / {n}\"\n");
    }
    text += "[initial]\n";
    for i in 1..=n {
        text += &format!("x{i} = {}\n", 1.0 / i as f64);
    }
    text += &format!("[outputs]\ny = {{ value = \"{sum}\", sigma = 0.05 }}\n[unknowns]\n");
    for i in 1..=n {
        let k = 0.5 + 0.1 * i as f64;
        text += &format!("k{i} = {{ guess = {k}, min = 1e-3, max = 1e3, log = true }}\n");
        text += &format!("c{i} = {{ guess = 0.3, min = 1e-3, max = 1e3, log = true }}\n");
    }
    text += "[data]\nfile = \"y.csv\"\n";
    let total: f64 = (1..=n).map(|i| 1.0 / i as f64).sum();
    let data = (1..=4).fold("t,y\n".to_string(), |d, m| {
        d + &format!("{},{}\n", m, total * (-0.4 * m as f64).exp())
    });
    (text, data)
}

/// `auto` takes the adjoint exactly where the adjoint's counted operations, weighted by
/// `ADJOINT_OPERATION_COST`, are fewer than the forward sensitivities' — on a model of 2
/// states, where forward does less, and of 24, where the adjoint does — and its choice is the
/// same on every run: its first gradient does both ways' work, to the operation, and returns
/// the chosen way's gradient to the last bit, as a second, fresh problem does again.
#[test]
fn auto_takes_the_way_with_fewer_counted_operations() {
    let mut ways = Vec::new();
    for n in [2, 24] {
        let dir =
            std::env::temp_dir().join(format!("sysid-adjoint-counted-{n}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (text, data) = coupled(n);
        std::fs::write(dir.join("m.toml"), text).unwrap();
        std::fs::write(dir.join("y.csv"), data).unwrap();
        let load = || Model::load(&dir.join("m.toml")).unwrap().problem(None).unwrap();
        let problem = load();
        let z = problem.unknowns().coordinates(&problem.guesses());
        let gradient = |p: &sysid_core::Problem<_>, how| p.nll_gradient(&z, how).unwrap().unwrap();
        let forward = gradient(&problem, Sensitivities::Forward);
        let adjoint = gradient(&problem, Sensitivities::Adjoint);
        assert!(adjoint.fell_back.is_empty() && adjoint.by_adjoint == [0]);
        let weighted = sysid_core::ADJOINT_OPERATION_COST * adjoint.counts.operations as f64;
        let by_adjoint = weighted < forward.counts.operations as f64;
        let chosen = if by_adjoint { &adjoint } else { &forward };
        for run in 0..2 {
            let problem = load();
            let first = gradient(&problem, Sensitivities::Auto);
            assert_eq!(first.by_adjoint.is_empty(), !by_adjoint, "n = {n}, run {run}");
            let mut both = forward.counts;
            both += adjoint.counts;
            assert_eq!(first.counts, both, "n = {n}: the first gradient does both ways' work");
            assert_eq!(first.gradient, chosen.gradient, "n = {n}, run {run}");
            let later = gradient(&problem, Sensitivities::Auto);
            assert_eq!(later.counts.operations, chosen.counts.operations, "n = {n}");
            assert_eq!(later.gradient, chosen.gradient, "n = {n}");
        }
        ways.push(by_adjoint);
    }
    assert_eq!(ways, [false, true], "the test needs a model each way goes");
}
