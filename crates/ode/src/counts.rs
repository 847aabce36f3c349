//! The work an integration does, counted in one place so that methods compare by it and a
//! change in it shows up in review.

use serde::{Deserialize, Serialize};

/// Work done by one or more integrations: the counts to compare methods by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Accepted steps.
    pub steps: u64,
    /// Rejected steps.
    pub rejected_steps: u64,
    /// Evaluations of the (possibly augmented) right-hand side f(t, x).
    pub rhs_evaluations: u64,
    /// Integrations started.
    pub integrations: u64,
    /// Jacobians evaluated and LU-factorised (implicit steps).
    pub jacobians: u64,
}

impl std::ops::AddAssign for Counts {
    fn add_assign(&mut self, o: Self) {
        self.steps += o.steps;
        self.rejected_steps += o.rejected_steps;
        self.rhs_evaluations += o.rhs_evaluations;
        self.integrations += o.integrations;
        self.jacobians += o.jacobians;
    }
}
