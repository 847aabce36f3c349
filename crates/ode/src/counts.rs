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
    /// The arithmetic these did, estimated: every evaluation, factorisation and solve
    /// charged what its right-hand side says one costs ([`Rhs::costs`](crate::Rhs::costs)).
    /// Not a measurement but a deterministic measure of work, by which
    /// `--sensitivities auto` compares forward sensitivities with the adjoint; not in the
    /// JSON.
    #[serde(skip)]
    pub operations: u64,
}

/// What one call of a right-hand side's functions costs, in arithmetic operations (an
/// operation of a compiled program, a multiply–add of a product, a step of an
/// elimination), estimated from its structure: the unit of [`Counts::operations`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Costs {
    /// One evaluation f(t, x).
    pub eval: u64,
    /// One factorisation of an implicit step's matrix, the Jacobian's evaluation included.
    pub factor: u64,
    /// One solve with that matrix.
    pub solve: u64,
}

impl Costs {
    /// A right-hand side of dimension n that tells nothing of itself: a dense Jacobian, f
    /// as dear as n² operations, factorised and solved by dense LU.
    pub fn dense(n: usize) -> Self {
        let n = n as u64;
        let (factor, solve) = dense_lu(n);
        Self { eval: n * n, factor: n * n + factor, solve }
    }
}

/// A dense LU of order n: its factorisation (2n³/3 operations) and a forward and back
/// substitution with it (2n²).
pub(crate) fn dense_lu(n: u64) -> (u64, u64) {
    (2 * n * n * n / 3, 2 * n * n)
}

impl std::ops::AddAssign for Counts {
    fn add_assign(&mut self, o: Self) {
        self.steps += o.steps;
        self.rejected_steps += o.rejected_steps;
        self.rhs_evaluations += o.rhs_evaluations;
        self.integrations += o.integrations;
        self.jacobians += o.jacobians;
        self.operations += o.operations;
    }
}
