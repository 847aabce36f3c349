//! A scripted method for the driver's tests: g's coordinate of a falling body moves as a
//! closure says, and the driver judges it. Each test crate uses part of it.
#![allow(dead_code)]

use sysid_core::{
    Data, Failure, Problem,
    method::{Advance, Evaluations, Iterate, Proposal, Step},
};
use sysid_systems::FallingBody;

/// Moves g's coordinate to `next(z, ∂ε/∂z)` at every iteration.
pub struct Walk<F: Fn(f64, f64) -> f64> {
    pub next: F,
}

/// A crawl: g's coordinate moves by `size` along the descent direction, whatever the gradient.
pub fn crawl(size: f64) -> Walk<impl Fn(f64, f64) -> f64> {
    Walk { next: move |z: f64, g: f64| z - size * g.signum() }
}

/// A dither: g's coordinate is reflected about `centre`, where ε stays as it is.
pub fn dither(centre: f64) -> Walk<impl Fn(f64, f64) -> f64> {
    Walk { next: move |z: f64, _: f64| 2.0 * centre - z }
}

impl<F: Fn(f64, f64) -> f64> Step<FallingBody> for Walk<F> {
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
        let z = vec![(self.next)(current.z[0], lin.gradient[0])];
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

pub fn problem() -> Problem<FallingBody> {
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
