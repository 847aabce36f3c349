//! Functions that come with their own sparse Jacobian.
//!
//! A system that can differentiate itself symbolically (a model file) evaluates f(t, y, α, u)
//! together with the nonzero entries of [∂f/∂y | ∂f/∂α] in one pass over f64 and hands them
//! out through [`System::sparse_jacobian`](crate::System::sparse_jacobian). Jacobian products
//! J_y V_y + J_α V_α then cost one multiply-add per nonzero entry and direction
//! ([`JacobianProducts`](crate::JacobianProducts)), instead of a dual-number evaluation of the
//! whole model per chunk of directions.

pub use crate::sparse_lu::PlanCell;

/// A function f(t, y, α, u) of m values evaluated with the nonzero entries of its Jacobian.
///
/// The contract: [`eval`](Self::eval) fills a work space from which f_i is read at
/// `work[values()[i]]` and the e-th entry of [`pattern`](Self::pattern) at
/// `work[entries()[e]]`; every entry not listed is zero at every point. The values are those
/// of the system's [`rhs`](crate::System::rhs) (or [`outputs`](crate::System::outputs)) and
/// the entries its exact derivatives, equal to a dual-number evaluation to rounding.
pub trait SparseJacobian: Send + Sync {
    /// The nonzero entries as (row, column): row i < m is f_i; column c < n is state c and
    /// column n + q is parameter q.
    fn pattern(&self) -> &[(u32, u32)];

    /// Where [`eval`](Self::eval) leaves the m function values in the work space.
    fn values(&self) -> &[u32];

    /// Where [`eval`](Self::eval) leaves the pattern's entries in the work space.
    fn entries(&self) -> &[u32];

    /// A work space for [`eval`](Self::eval), set up for it (allocate once, reuse).
    fn workspace(&self) -> Vec<f64>;

    /// How many arithmetic operations one [`eval`](Self::eval) does, for the estimate of
    /// work ([`Costs`](crate::Costs)). Default: four per value and entry.
    fn operations(&self) -> usize {
        4 * (self.values().len() + self.pattern().len())
    }

    /// Evaluates f(t, y, α, u) and the Jacobian's entries into `work`.
    fn eval(&self, t: f64, y: &[f64], p: &[f64], u: &[f64], work: &mut [f64]);

    /// The Jacobian's entries (in pattern order) as functions in their own right, with
    /// their sparse Jacobian with respect to the states (its columns are states only): the
    /// second derivatives that couple the sensitivities into an implicit step. Default:
    /// none (the implicit solver then uses hyper-dual numbers).
    fn curvature(&self) -> Option<&dyn SparseJacobian> {
        None
    }

    /// The same functions with no Jacobian (an empty pattern), where the system has them
    /// as a cheaper program: for evaluations that read f alone. Their values are those of
    /// [`eval`](Self::eval) to the bit. Default: none ([`eval`](Self::eval) is read).
    fn values_alone(&self) -> Option<&dyn SparseJacobian> {
        None
    }

    /// The same functions with the Jacobian's state columns alone (the pattern's entries
    /// whose column is below n, in the same order), where the system has them as a cheaper
    /// program: for an implicit step's matrix. Values and entries are those of
    /// [`eval`](Self::eval) to the bit. Default: none ([`eval`](Self::eval) is read).
    fn state_columns(&self) -> Option<&dyn SparseJacobian> {
        None
    }

    /// Where the sparse LU of an implicit step keeps the order and fill of this pattern, so
    /// that they are found once for the system rather than at every integration (each
    /// condition, each backward part of an adjoint, each evaluation of a fit). Default:
    /// none (found again at every integration).
    fn lu_plan(&self) -> Option<&PlanCell> {
        None
    }
}

impl dyn SparseJacobian + '_ {
    /// The program that evaluates f alone: [`values_alone`](SparseJacobian::values_alone)
    /// where there is one, else this one.
    pub fn for_values(&self) -> &dyn SparseJacobian {
        self.values_alone().unwrap_or(self)
    }

    /// The program that evaluates f with ∂f/∂y:
    /// [`state_columns`](SparseJacobian::state_columns) where there is one, else this one.
    pub fn for_state_columns(&self) -> &dyn SparseJacobian {
        self.state_columns().unwrap_or(self)
    }
}
