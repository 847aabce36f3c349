//! The driver's progress rule: a method that crawls (here a step of 1e-6 in g's coordinate
//! along the descent, whatever the gradient) is stopped once ε fell by less than 1e-6 of
//! itself over 100 iterations, not at the iteration limit, and the termination names the
//! unknown still moving; a method that makes progress is not stopped by it.

use sysid_core::{
    Data, DriverOptions, Failure, Problem, Rule, Termination,
    method::{Advance, Evaluations, Iterate, PROGRESS_WINDOW, Proposal, Step, drive},
};
use sysid_systems::FallingBody;

/// Moves g's coordinate by `size` along the descent direction at every iteration (a crawl).
struct Crawl {
    size: f64,
}

impl Step<FallingBody> for Crawl {
    fn start(
        &mut self,
        ev: &Evaluations<'_, FallingBody>,
        z: Vec<f64>,
    ) -> Result<Iterate, Failure> {
        ev.linearize(&z).map(Iterate::linearized)
    }

    fn propose(
        &mut self,
        _: &Evaluations<'_, FallingBody>,
        current: &Iterate,
    ) -> Result<Proposal, Failure> {
        let lin = current.linearization.as_ref().expect("linearized");
        let z = vec![current.z[0] - self.size * lin.gradient[0].signum()];
        Ok(Proposal { z, condition: None, gradient_norm: None, stop: None })
    }

    fn advance(
        &mut self,
        ev: &Evaluations<'_, FallingBody>,
        _: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure> {
        ev.linearize(&proposal.z).map(|l| Advance::Moved(Iterate::linearized(l)))
    }
}

fn problem() -> Problem<FallingBody> {
    // y = g t²/2 against data of g ≈ 32, and a point at t = 0 no g can fit: ε ≈ 1e6 with a
    // gradient of about 50, so a crawl lowers ε by far less than 1e-6 of itself.
    Problem::builder(FallingBody::default())
        .known("y", 0.0)
        .known("v", 0.0)
        .unknown("g", 30.0)
        .data(Data::discrete().series("y", &[0.0, 1.0, 2.0, 3.0], &[1000.0, 17.0, 63.0, 145.0]))
        .build()
        .unwrap()
}

#[test]
fn a_crawl_is_stopped_and_names_what_moves() {
    let problem = problem();
    let options = DriverOptions { max_iterations: 1000, ..Default::default() };
    let e = drive(&problem, "crawl", &options, &mut Crawl { size: 1e-6 }, &[30.0]).unwrap();
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
    let e = drive(&problem, "walk", &options, &mut Crawl { size: 1e-2 }, &[30.0]).unwrap();
    assert!(e.iterations > 2 * PROGRESS_WINDOW, "{} iterations", e.iterations);
    assert!((e.values[0] - 787.0 / 24.5).abs() <= 0.02, "g = {}", e.values[0]);
    // The module docs and the termination text speak of 100 iterations and 1e-6.
    assert_eq!((PROGRESS_WINDOW, sysid_core::method::PROGRESS), (100, 1e-6));
}
