//! Goodman's method as a [`Step`] of the shared driver: the Newton step of eq. (14) and, as
//! an option, step halving.

use nalgebra::DVector;
use sysid_core::{
    Estimate, Failure, FitError, Method, Problem, Rule,
    method::{Advance, Curve, Evaluations, Iterate, Proposal, Step, drive, halve_along_curve},
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
        let mut step =
            Newton { options: &self.options, delta: DVector::zeros(0), curve: Curve::default() };
        drive(problem, name, &self.options.driver, &mut step, start)
    }
}

/// The state of Goodman's iteration between proposing and taking a step.
struct Newton<'o> {
    options: &'o GoodmanOptions,
    /// The Newton step of the last proposal (inside the bounds).
    delta: DVector<f64>,
    /// The Levenberg curve along which step halving shortens a step (its scaling kept
    /// from iterate to iterate).
    curve: Curve,
}

impl<S: System> Step<S> for Newton<'_> {
    /// Integrates the model and its variational equations at the start: U* and A.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        ev.linearize(&z).map(Iterate::linearized)
    }

    /// With step halving, a trial whose integration fails is halved.
    fn retreats(&self) -> bool {
        self.options.step_halving
    }

    /// Solves A δc = −U* (eq. 14) for the unknowns not held on a bound; the proposal is
    /// c* + δc projected on the bounds.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        let problem = ev.problem();
        let lin = current.linearization.as_ref().expect("Goodman's iterates are linearized");
        let (lo, hi) = problem.unknowns().step_box(&current.z, lin.gradient.as_slice());
        // On a Laplace prior's kink, the gradient the step sees is the one-sided one.
        let one_sided = sysid_core::method::one_sided(problem, lin);
        let lin = one_sided.as_ref().unwrap_or(lin);
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

    /// c ← c* + δc, then integrate again from the new initial vector. With step halving, a
    /// step that does not lower the cost (or whose integration fails) is halved, at most
    /// `max_halvings` times: its scaled length ‖Dδ‖ is halved along the Levenberg curve
    /// ([`Curve`]), the step the quadratic model prefers at that length, which shortens a
    /// direction where the Newton step overshoots before the others (halving along the line
    /// shortens all alike, and crawls on a sloppy problem). Below ε's accuracy the decrease
    /// is measured from the gradients at both ends ([`actual_decrease`]). Every step stays in
    /// the box.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure> {
        if !self.options.step_halving {
            return ev.linearize(&proposal.z).map(|l| Advance::Moved(Iterate::linearized(l)));
        }
        let lin = current.linearization.as_ref().expect("Goodman's iterates are linearized");
        let first = self.curve.first(lin, self.delta.clone());
        let driver = &self.options.driver;
        halve_along_curve(
            ev,
            lin,
            &mut self.curve,
            (first, proposal.z),
            self.options.max_halvings,
            0.0,
            driver.step_tolerance,
            driver.max_condition,
        )
    }
}
