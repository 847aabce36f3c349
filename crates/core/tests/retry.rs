//! `Estimate::retried`, the one fit made of two runs from the same start (the trust regions'
//! cautious retry): the certified run is reported over an uncertified one whatever their
//! objectives, else the lower objective; a point that could not be evaluated is never the
//! better; the first run's ending is kept beside the report, and the work and time are both
//! runs'.

mod walk;

use sysid_core::{DriverOptions, Estimate, Problem, Rule, Termination, method::drive};
use sysid_systems::FallingBody;
use walk::{dither, problem};

/// A certified run (dithering about the minimum) and an uncertified one (dithering 0.02
/// away, stopped by the progress rule), from starts beside the minimum.
fn runs(problem: &Problem<FallingBody>) -> (Estimate, Estimate) {
    let options = DriverOptions { max_iterations: 1000, ..Default::default() };
    let centre = 787.0 / 24.5;
    let certified = drive(problem, "dither", &options, &mut dither(centre), &[centre + 2e-6]);
    let stalled = drive(problem, "dither", &options, &mut dither(centre), &[centre + 0.02]);
    let (certified, stalled) = (certified.unwrap(), stalled.unwrap());
    assert_eq!(certified.termination, Termination::Converged(Rule::Settled));
    assert!(!stalled.converged(), "{}", stalled.termination);
    (certified, stalled)
}

/// `e` with its objective (the NLL, and ε with it) set to `objective`.
fn lowered(e: &Estimate, objective: f64) -> Estimate {
    let mut e = e.clone();
    let shift = objective - e.objective();
    e.nll = e.nll.map(|nll| nll + shift);
    e.cost += 2.0 * shift;
    assert!((e.objective() - objective).abs() <= 1e-9 * objective.abs());
    e
}

#[test]
fn the_certified_run_is_reported_and_the_first_is_kept_beside_it() {
    let problem = problem();
    let (certified, stalled) = runs(&problem);
    // The uncertified run's objective is the higher here; make it the lower, so that the
    // choice is the certificate's and not the objective's.
    let low = lowered(&stalled, certified.objective() - 1.0);
    assert!(low.objective() < certified.objective());

    let e = Estimate::retried(low.clone(), certified.clone());
    assert!(e.converged());
    assert_eq!(e.values, certified.values);
    let first = e.retry.as_ref().expect("the first run's ending");
    assert!(!first.reported);
    assert_eq!(first.termination, low.termination);
    assert_eq!((first.objective, first.iterations), (low.objective(), low.iterations));
    assert_eq!(e.counts.integrations, low.counts.integrations + certified.counts.integrations);
    assert_eq!(e.elapsed, low.elapsed + certified.elapsed);

    let e = Estimate::retried(certified.clone(), low.clone());
    assert!(e.converged());
    assert_eq!(e.values, certified.values);
    assert!(e.retry.as_ref().expect("the first run's ending").reported);
}

#[test]
fn between_uncertified_runs_the_lower_objective_is_reported() {
    let problem = problem();
    let (_, stalled) = runs(&problem);
    let mut lower = lowered(&stalled, stalled.objective() - 1.0);
    lower.values = vec![31.0];
    let e = Estimate::retried(stalled.clone(), lower.clone());
    assert_eq!(e.values, lower.values);
    assert!(!e.retry.as_ref().unwrap().reported);
    let e = Estimate::retried(lower.clone(), stalled.clone());
    assert_eq!(e.values, lower.values);
    assert!(e.retry.as_ref().unwrap().reported);
    // A point that could not be evaluated (ε NaN) is never the better, first or second.
    let failed =
        Estimate::panicked(&problem, "dither", &[30.0], "a defect".into(), stalled.elapsed);
    assert!(failed.objective().is_nan());
    assert_eq!(Estimate::retried(failed.clone(), stalled.clone()).values, stalled.values);
    assert_eq!(Estimate::retried(stalled.clone(), failed).values, stalled.values);
}
