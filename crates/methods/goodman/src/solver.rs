//! Goodman's method as a [`Step`] of the shared driver: the Newton step of eq. (14) and, as
//! an option, step halving.

use nalgebra::DVector;
use sysid_core::{
    Advance, Estimate, Evaluations, Failure, FitError, Iterate, Method, Problem, Proposal, Rule,
    Step, drive,
};
use sysid_ode::System;

use crate::options::GoodmanOptions;
use crate::step::newton_step;

/// Goodman's method with its options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Goodman {
    /// The options.
    pub options: GoodmanOptions,
}

impl Goodman {
    /// The method with these options.
    pub fn new(options: GoodmanOptions) -> Self {
        Self { options }
    }
}

impl<S: System> Method<S> for Goodman {
    fn name(&self) -> &str {
        if self.options.step_halving { "goodman-halving" } else { "goodman" }
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.options.validate()?;
        let name = <Self as Method<S>>::name(self);
        let mut step = Newton { options: &self.options, delta: DVector::zeros(0) };
        drive(problem, name, &self.options.driver, &mut step, start)
    }
}

/// The state of Goodman's iteration between proposing and taking a step.
struct Newton<'o> {
    options: &'o GoodmanOptions,
    /// The Newton step of the last proposal (inside the bounds).
    delta: DVector<f64>,
}

impl<S: System> Step<S> for Newton<'_> {
    /// Integrates the model and its variational equations at the start: U* and A.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        ev.linearize(&z).map(Iterate::linearized)
    }

    /// Solves A δc = −U* (eq. 14) for the unknowns not held on a bound; the proposal is
    /// c* + δc projected on the bounds.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        let problem = ev.problem();
        let lin = current.linearization.as_ref().expect("Goodman's iterates are linearized");
        let (lo, hi) = problem.unknowns().step_box(&current.z);
        let step = newton_step(lin, (&lo, &hi), self.options.driver.max_condition)
            .map_err(|s| Failure::singular(&s, &problem.names()))?;
        // The decrease the quadratic model predicts, ε − ε_lin(z + δ) = −(2Uᵀδ + δᵀAδ)
        // (δᵀAδ for the unbounded Newton step).
        let predicted =
            -(2.0 * lin.gradient.dot(&step.delta) + step.delta.dot(&(&lin.normal * &step.delta)));
        let cost_tolerance = self.options.cost_tolerance;
        let stop = (cost_tolerance > 0.0 && predicted <= cost_tolerance * lin.cost)
            .then_some(Rule::PredictedDecrease);
        let z = problem.unknowns().moved(&current.z, step.delta.as_slice(), 1.0);
        self.delta = step.delta;
        Ok(Proposal { z, condition: Some(step.condition), gradient_norm: None, stop })
    }

    /// c ← c* + δc, then integrate again from the new initial vector. With step halving, δc
    /// is halved while the cost does not fall (beyond ε's accuracy, near the minimum) or the
    /// integration fails, at most `max_halvings` times; the box is convex, so every
    /// shortened step stays inside it.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure> {
        if !self.options.step_halving {
            return ev.linearize(&proposal.z).map(|l| Advance::Moved(Iterate::linearized(l)));
        }
        let problem = ev.problem();
        let lin = current.linearization.as_ref().expect("Goodman's iterates are linearized");
        let z = &current.z;
        let step_tolerance = problem.resolvable_step(self.options.driver.step_tolerance);
        let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
        let negligible = step_tolerance * (z_norm + step_tolerance);
        let resolution = problem.integrator().rtol * lin.cost;
        // The decrease of ε the quadratic model predicts for a move to `trial`.
        let predicted = |trial: &[f64]| {
            let d = DVector::from_iterator(trial.len(), trial.iter().zip(z).map(|(a, b)| a - b));
            -(2.0 * lin.gradient.dot(&d) + d.dot(&(&lin.normal * &d)))
        };
        let mut scale = 1.0;
        for _ in 0..=self.options.max_halvings {
            if scale < 1.0 && scale * self.delta.norm() <= negligible {
                // Shrunk below the step tolerance without reducing the cost.
                return Ok(Advance::Stop(Rule::Step));
            }
            let trial = problem.unknowns().moved(z, self.delta.as_slice(), scale);
            match ev.linearize(&trial) {
                // A step is taken on an actual decrease of the cost; or, where the model
                // itself expects a change below ε's accuracy (about rtol relative: the
                // minimum's noise floor), on a change within that accuracy, so that the
                // iteration can refine the point rather than halve to nothing.
                Ok(l)
                    if l.cost < lin.cost
                        || (l.cost <= lin.cost + resolution && predicted(&trial) <= resolution) =>
                {
                    return Ok(Advance::Moved(Iterate::linearized(l)));
                }
                Ok(_) => {}
                Err(budget @ Failure::Budget { .. }) => return Err(budget),
                Err(_) => {}
            }
            scale *= 0.5;
        }
        Ok(Advance::Stop(Rule::NoDescent))
    }
}
