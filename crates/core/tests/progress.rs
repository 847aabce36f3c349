//! The driver's progress rule: a method that crawls (here a step of 1e-6 in g's coordinate
//! along the descent, whatever the gradient) is stopped once ε fell by less than 1e-6 of
//! itself over 100 iterations, not at the iteration limit, and the termination names the
//! unknown still moving; a method that makes progress is not stopped by it. The settled rule:
//! a method that dithers about the minimum, its measure within gtol, is stopped as converged
//! after 10 iterations; dithering further out, it is not.

mod walk;

use sysid_core::{
    DriverOptions, Rule, Termination,
    method::{PROGRESS_WINDOW, SETTLE_WINDOW, drive},
};
use walk::{crawl, dither, problem};

#[test]
fn a_crawl_is_stopped_and_names_what_moves() {
    let problem = problem();
    let options = DriverOptions { max_iterations: 1000, ..Default::default() };
    let e = drive(&problem, "crawl", &options, &mut crawl(1e-6), &[30.0]).unwrap();
    assert!(!e.converged());
    match &e.termination {
        Termination::Stalled { rule: Rule::Progress, moving, iteration, .. } => {
            assert_eq!(moving, &["g"]);
            // The first iteration the window allows, and the 3 steps any rule at an
            // uncertified point is allowed past it.
            assert_eq!(*iteration, PROGRESS_WINDOW + 3);
        }
        other => panic!("{other}"),
    }
    assert!(e.termination.to_string().contains("g still moves"), "{}", e.termination);
    assert_eq!(e.termination.code(), "stalled_progress");
    // Steps of 1e-2 lower ε by more than 1e-6 of itself per 100 iterations: the rule lets
    // them walk the 213 steps to the minimum, g = 787/24.5 (least squares of b on t²/2).
    let e = drive(&problem, "walk", &options, &mut crawl(1e-2), &[30.0]).unwrap();
    assert!(e.iterations > 2 * PROGRESS_WINDOW, "{} iterations", e.iterations);
    assert!((e.values[0] - 787.0 / 24.5).abs() <= 0.02, "g = {}", e.values[0]);
    // The module docs and the termination text speak of 100 iterations and 1e-6.
    assert_eq!((PROGRESS_WINDOW, sysid_core::method::PROGRESS), (100, 1e-6));
}

#[test]
fn a_certified_run_that_no_longer_gains_is_settled() {
    let problem = problem();
    let options = DriverOptions { max_iterations: 1000, ..Default::default() };
    // The minimum g* = 787/24.5; the measure at g* ± δ is √a·δ/‖r‖ with a = Σ(t²/2)² = 24.5
    // and ‖r‖ ≈ 1000: 1e-8 at δ = 2e-6 (within gtol = 1e-6, above the gradient rule's 1e-10).
    let centre = 787.0 / 24.5;
    let measure = |delta: f64| 24.5_f64.sqrt() * delta / 1000.0;
    let delta = 2e-6;
    assert!(measure(delta) > 1e-10 && measure(delta) < 1e-6, "{}", measure(delta));
    let e = drive(&problem, "dither", &options, &mut dither(centre), &[centre + delta]).unwrap();
    assert!(e.converged(), "{}", e.termination);
    assert_eq!(e.termination, Termination::Converged(Rule::Settled));
    assert_eq!(e.termination.code(), "converged_settled");
    // The first iteration whose window of 10 is complete.
    assert_eq!(e.iterations, SETTLE_WINDOW);
    assert!(e.certificate.optimality <= 1e-6, "{}", e.certificate.optimality);
    // Dithering at a measure of 1e-4, above gtol, ε does not move either, but the point is
    // not a minimum: only the progress rule stops it, uncertified.
    let delta = 0.02;
    assert!(measure(delta) > 1e-5, "{}", measure(delta));
    let e = drive(&problem, "dither", &options, &mut dither(centre), &[centre + delta]).unwrap();
    assert!(!e.converged());
    assert_eq!(e.termination.code(), "stalled_progress");
    // The module docs and the termination text speak of 10 iterations and 1e-8.
    assert_eq!((SETTLE_WINDOW, sysid_core::method::SETTLE), (10, 1e-8));
}

#[test]
fn the_iteration_limit_says_what_the_cost_still_gained_and_what_moved() {
    // Steps of 1e-2 from g = 30 need 213 to reach the minimum; a limit of 150 stops them
    // at g = 31.5 while ε still falls. Over the last 100 iterations (g from 30.5 to 31.5) ε
    // fell by ε(30.5) − ε(31.5), with ε(g) = Σ (b − g t²/2)² in closed form.
    let problem = problem();
    let options = DriverOptions { max_iterations: 150, ..Default::default() };
    let e = drive(&problem, "walk", &options, &mut crawl(1e-2), &[30.0]).unwrap();
    let epsilon = |g: f64| {
        [(0.0, 1000.0), (1.0, 17.0), (2.0, 63.0), (3.0, 145.0)]
            .iter()
            .map(|(t, b): &(f64, f64)| (b - g * t * t / 2.0).powi(2))
            .sum::<f64>()
    };
    let expected = epsilon(30.5) - epsilon(31.5);
    match &e.termination {
        Termination::MaxIterations { fell: Some(fell), moving, .. } => {
            assert!((fell - expected).abs() <= 1e-9 * expected, "{fell} against {expected}");
            assert_eq!(moving, &["g"]);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(e.termination.code(), "max_iterations");
    let text = e.termination.to_string();
    assert!(text.contains(&format!("by {expected:.3e}")) && text.contains("along g"), "{text}");
    // Ten iterations are too few for the window: the limit says only that.
    let options = DriverOptions { max_iterations: 10, ..Default::default() };
    let e = drive(&problem, "walk", &options, &mut crawl(1e-2), &[30.0]).unwrap();
    assert_eq!(
        e.termination,
        Termination::MaxIterations { fell: None, moving: vec![], unresolved_gradient: None }
    );
    assert_eq!(e.termination.to_string(), "iteration limit reached");
}
