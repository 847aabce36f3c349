//! Goodman's method as a [`Step`] of the shared driver: the Newton step of eq. (14) and, as
//! an option, step halving.

use nalgebra::DVector;
use sysid_core::{
    Advance, Curve, CurveStep, Estimate, Evaluations, Failure, FitError, Iterate, Method, Problem,
    Proposal, Rule, Step, actual_decrease, drive,
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
        let problem = ev.problem();
        let lin = current.linearization.as_ref().expect("Goodman's iterates are linearized");
        let z = &current.z;
        let step_tolerance = problem.resolvable_step(self.options.driver.step_tolerance);
        let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
        let negligible = step_tolerance * (z_norm + step_tolerance);
        let resolution = problem.integrator().rtol * lin.cost;
        self.curve.rescale(lin);
        self.curve.lambda = 0.0;
        let predicted =
            -(2.0 * lin.gradient.dot(&self.delta) + self.delta.dot(&(&lin.normal * &self.delta)));
        let mut step = CurveStep {
            scaled_norm: self.curve.scaled_norm(self.delta.as_slice()),
            delta: self.delta.clone(),
            predicted,
            lambda: 0.0,
            condition: f64::NAN,
        };
        let mut trial = proposal.z;
        for halving in 0..=self.options.max_halvings {
            if halving > 0 && step.delta.norm() <= negligible {
                // Shrunk below the step tolerance without reducing the cost.
                return Ok(Advance::Stop(Rule::Step));
            }
            match ev.linearize(&trial) {
                Ok(l) if actual_decrease(lin, &l, step.predicted, resolution) > 0.0 => {
                    return Ok(Advance::Moved(Iterate::linearized(l)));
                }
                Ok(_) => {}
                Err(budget @ Failure::Budget { .. }) => return Err(budget),
                Err(_) => {}
            }
            let radius = 0.5 * step.scaled_norm;
            step = match self.curve.within(problem, lin, radius, self.options.driver.max_condition)
            {
                Ok(shorter) => shorter,
                Err(_) => return Ok(Advance::Stop(Rule::NoDescent)),
            };
            trial = problem.unknowns().moved(z, step.delta.as_slice(), 1.0);
        }
        Ok(Advance::Stop(Rule::NoDescent))
    }
}
