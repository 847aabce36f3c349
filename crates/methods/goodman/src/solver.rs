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
    /// The Newton step of the last proposal (before projection on the bounds).
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
        let held = problem.unknowns().active(&current.z, lin.gradient.as_slice());
        let step = newton_step(lin, self.options.driver.max_condition, &held)
            .map_err(|s| Failure::singular(&s, &problem.names()))?;
        // The decrease the step predicts: ε − ε_lin(z + δ) = δᵀAδ for the Newton step.
        let predicted = step.delta.dot(&(&lin.normal * &step.delta));
        let cost_tolerance = self.options.cost_tolerance;
        let stop = (cost_tolerance > 0.0 && predicted <= cost_tolerance * lin.cost)
            .then_some(Rule::PredictedDecrease);
        let mut z: Vec<f64> = current.z.iter().zip(&step.delta).map(|(z, d)| z + d).collect();
        problem.unknowns().project(&mut z);
        self.delta = step.delta;
        Ok(Proposal { z, condition: Some(step.condition), gradient_norm: None, stop })
    }

    /// c ← c* + δc, then integrate again from the new initial vector. With step halving, δc
    /// is halved while the cost rises or the integration fails, at most `max_halvings` times.
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
        let mut scale = 1.0;
        for _ in 0..=self.options.max_halvings {
            if scale < 1.0 && scale * self.delta.norm() <= negligible {
                // Shrunk below the step tolerance without reducing the cost.
                return Ok(Advance::Stop(Rule::Step));
            }
            let mut trial: Vec<f64> =
                z.iter().zip(&self.delta).map(|(z, d)| z + scale * d).collect();
            problem.unknowns().project(&mut trial);
            match ev.linearize(&trial) {
                // A rise within ε's accuracy (about rtol relative) says nothing: such a step
                // is judged by the iteration's tests, not by comparing two costs that agree
                // to their accuracy. A larger rise is rejected, however small the decrease
                // the linearization predicted.
                Ok(l) if l.cost <= lin.cost + resolution => {
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
