//! The vocabulary between the driver and a method: the iterate, the method's proposal, how
//! it moved, and the [`Step`] trait a method implements (see [`drive`](crate::method::drive)).

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
    /// What the method measures at the iterate besides ε, in its own terms: the method's
    /// hook into the history. The driver copies it into the iteration's row unread.
    pub diagnostics: Diagnostics,
}

impl Iterate {
    /// An iterate at z with cost ε and nothing else known there.
    pub fn new(z: Vec<f64>, cost: f64) -> Self {
        Self {
            z,
            cost,
            gradient_norm: None,
            linearization: None,
            diagnostics: Diagnostics::default(),
        }
    }

    /// An iterate from the model's linearization at it.
    pub fn linearized(lin: Linearization) -> Self {
        Self {
            gradient_norm: Some(lin.gradient.norm()),
            ..Self::new(lin.z.clone(), lin.cost).with_linearization(lin)
        }
    }

    fn with_linearization(self, lin: Linearization) -> Self {
        Self { linearization: Some(lin), ..self }
    }

    /// ε at the iterate: its linearization's where it has one (under hierarchical
    /// optimisation the iterate's `cost` is the profile's, twice the NLL up to a constant,
    /// whose size says nothing; relative rules measure against this), else its cost.
    pub fn epsilon(&self) -> f64 {
        self.linearization.as_ref().map_or(self.cost, |l| l.cost)
    }

    /// The same iterate with one more named value in its diagnostics.
    pub fn with(mut self, name: &'static str, value: f64) -> Self {
        self.diagnostics.push(name, value);
        self
    }
}

/// Named values a method attaches to an iterate (quasilinearization's `linear_cost`, multiple
/// shooting's `defect`): recorded in the history row of the iterate and written into its
/// JSON under their names (docs/json.md). The driver treats them alike for every method.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Diagnostics(Vec<(&'static str, f64)>);

impl Diagnostics {
    /// Adds (or replaces) `name`.
    pub fn push(&mut self, name: &'static str, value: f64) {
        match self.0.iter_mut().find(|(n, _)| *n == name) {
            Some(entry) => entry.1 = value,
            None => self.0.push((name, value)),
        }
    }
    /// The value called `name`, if the method attached one.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| *n == name).map(|e| e.1)
    }
    /// The names and values, in the order they were attached.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.0.iter().copied()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
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

    /// Evaluates `current` again after the driver refined the integration
    /// ([`Evaluations::refine`]), keeping what the method has learnt (a trust region's
    /// radius); by default, a fresh [`start`](Self::start) there.
    fn restart(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Iterate, Failure> {
        self.start(ev, current.z.clone())
    }

    /// Whether the driver may set the noise scales to their closed form at every iterate
    /// (hierarchical optimisation), re-weighting the iterate's linearization: true for a
    /// method that judges each trial against the current linearization's ε (both evaluated
    /// at the same scales) and reads no other ε of an iterate. Otherwise the driver fits in
    /// rounds between closed-form updates.
    fn profiles(&self) -> bool {
        false
    }

    /// Whether a trial whose integration fails is, to the method, a rejected trial that it
    /// retreats from (a shorter step), not the end of the run: the driver then
    /// [paces](crate::evaluations) its integrations while it proposes and moves, so that a
    /// trial the model needs far more steps at than at the iterate fails early.
    fn retreats(&self) -> bool {
        false
    }

    /// Whether the run integrates coarsely first: at [`COARSE_RTOL`](crate::method::COARSE_RTOL)
    /// ([`coarser`](crate::method::coarser)) until the optimality measure is within the gtol
    /// that tolerance supports, or a stopping rule fires, then at the problem's own tolerances
    /// from the point reached ([`restart`](Self::restart)), where the certificate judges it.
    /// For a method whose steps need only the model's shape, not the last digits, far from a
    /// minimum (a trust region's).
    fn coarse_first(&self) -> bool {
        false
    }

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
