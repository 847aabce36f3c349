//! The vocabulary between the driver and a method: the iterate, the method's proposal, how
//! it moved, and the [`Step`] trait a method implements (see [`drive`](crate::drive)).

use sysid_ode::System;

use crate::evaluate::Linearization;
use crate::evaluations::Evaluations;
use crate::termination::{Failure, Rule};

/// A point of the iteration: the unknowns' coordinates and what the method knows there.
#[derive(Clone, Debug)]
pub struct Iterate {
    /// Coordinates z.
    pub z: Vec<f64>,
    /// ε of the model at z, the measure every method reports (NaN where the method can go on
    /// without it, as quasilinearization can).
    pub cost: f64,
    /// |U| as the method sees it, for the history.
    pub gradient_norm: Option<f64>,
    /// The model's linearization at z, when the method computed it (Goodman, the
    /// Gauss–Newton baseline): the gradient rule and the certificate use it.
    pub linearization: Option<Linearization>,
    /// Quasilinearization: ε of the linear family whose optimum z is.
    pub linear_cost: Option<f64>,
    /// Multiple shooting: ‖d‖, the Euclidean norm of the matching defects at the iterate.
    pub defect: Option<f64>,
}

impl Iterate {
    /// An iterate from the model's linearization at it.
    pub fn linearized(lin: Linearization) -> Self {
        Self {
            z: lin.z.clone(),
            cost: lin.cost,
            gradient_norm: Some(lin.gradient.norm()),
            linearization: Some(lin),
            linear_cost: None,
            defect: None,
        }
    }
}

/// What a method proposes from an iterate.
#[derive(Clone, Debug)]
pub struct Proposal {
    /// The next coordinates, inside the bounds.
    pub z: Vec<f64>,
    /// Condition number of the matrix the proposal solved with, for the history.
    pub condition: Option<f64>,
    /// |U| at the current iterate as the proposal computed it, for the history where the
    /// iterate has none (quasilinearization: the linear family's).
    pub gradient_norm: Option<f64>,
    /// The method's own rule says stop here, before moving (Goodman's predicted decrease).
    pub stop: Option<Rule>,
}

/// How a method moved.
#[derive(Debug)]
pub enum Advance {
    /// To a new iterate.
    Moved(Iterate),
    /// To a new iterate, which the method's rule says to stop at (argmin's cost change).
    MovedThenStop(Iterate, Rule),
    /// Not at all: the rule that says so (step halving found no descent).
    Stop(Rule),
}

/// One iteration of a method, in its own terms.
pub trait Step<S: System> {
    /// Evaluates the start z (coordinates, inside the bounds). A failure here means the start
    /// cannot be used.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure>;

    /// Proposes the next point from `current`.
    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure>;

    /// Moves to (or towards) the proposal, evaluating the new iterate.
    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure>;
}
