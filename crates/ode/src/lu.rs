//! Dense LU with partial pivoting (faer), factorised in place into preallocated storage:
//! the implicit integrator factorises once per step without allocating.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::perm::PermRef;
use faer::{Mat, MatMut, Par};

/// Why an implicit step cannot proceed with a right-hand side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FactorError {
    /// The right-hand side provides no Jacobian (implicit methods cannot be used).
    Unsupported,
    /// E = I/(γh) − ∂f/∂x is singular (a shorter step usually cures it).
    Singular,
}

/// An n × n matrix and its LU factors.
pub struct Lu {
    n: usize,
    a: Mat<f64>,
    fwd: Vec<usize>,
    inv: Vec<usize>,
    mem: MemBuffer,
}

impl Lu {
    /// Storage for n × n, and for solves with up to `columns` right-hand sides at once.
    pub fn new(n: usize, columns: usize) -> Self {
        let scratch = StackReq::any_of(&[
            factor::lu_in_place_scratch::<usize, f64>(n, n, Par::Seq, Default::default()),
            solve::solve_in_place_scratch::<usize, f64>(n, columns.max(1), Par::Seq),
        ]);
        Self {
            n,
            a: Mat::zeros(n, n),
            fwd: vec![0; n],
            inv: vec![0; n],
            mem: MemBuffer::new(scratch),
        }
    }

    /// Fills the matrix with `entry(i, j)` and factorises it.
    pub fn factor(&mut self, entry: impl Fn(usize, usize) -> f64) -> Result<(), FactorError> {
        let n = self.n;
        for j in 0..n {
            for i in 0..n {
                self.a[(i, j)] = entry(i, j);
            }
        }
        if (0..n).any(|j| (0..n).any(|i| !self.a[(i, j)].is_finite())) {
            return Err(FactorError::Singular);
        }
        factor::lu_in_place(
            self.a.as_mut(),
            &mut self.fwd,
            &mut self.inv,
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        );
        // A zero or non-finite pivot: singular (to working precision).
        if (0..n).any(|i| !(self.a[(i, i)].abs() > 0.0 && self.a[(i, i)].is_finite())) {
            return Err(FactorError::Singular);
        }
        Ok(())
    }

    /// Overwrites r (length n) with A⁻¹ r.
    pub fn solve(&mut self, r: &mut [f64]) {
        let n = self.n;
        self.solve_mat(MatMut::from_column_major_slice_mut(r, n, 1));
    }

    /// Overwrites the n × k matrix R, stored row by row in r, with A⁻¹ R (k at most the
    /// `columns` given to [`new`](Self::new)).
    pub fn solve_rows(&mut self, r: &mut [f64], k: usize) {
        let n = self.n;
        self.solve_mat(MatMut::from_row_major_slice_mut(r, n, k));
    }

    fn solve_mat(&mut self, r: MatMut<'_, f64>) {
        let perm = PermRef::new_checked(&self.fwd, &self.inv, self.n);
        // The combined factor holds L (unit diagonal, below) and U (on and above).
        solve::solve_in_place(
            self.a.as_ref(),
            self.a.as_ref(),
            perm,
            r,
            Par::Seq,
            MemStack::new(&mut self.mem),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_close_abs;

    #[test]
    fn solves_with_pivoting_and_reports_singular() {
        let mut lu = Lu::new(3, 2);
        // A leading zero forces a pivot.
        let a = [[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 4.0]];
        lu.factor(|i, j| a[i][j]).unwrap();
        let times = |x: &[f64; 3]| -> Vec<f64> {
            (0..3).map(|i| (0..3).map(|j| a[i][j] * x[j]).sum()).collect()
        };
        let (x, x2) = ([1.0, -2.0, 0.5], [0.25, 3.0, -1.0]);
        let mut r = times(&x);
        lu.solve(&mut r);
        for (ri, xi) in r.iter().zip(x) {
            assert_close_abs(*ri, xi, 1e-15);
        }
        // Two right-hand sides as the columns of a 3 × 2 matrix stored row by row.
        let (b, b2) = (times(&x), times(&x2));
        let mut rows: Vec<f64> = (0..3).flat_map(|i| [b[i], b2[i]]).collect();
        lu.solve_rows(&mut rows, 2);
        for i in 0..3 {
            assert_close_abs(rows[2 * i], x[i], 1e-15);
            assert_close_abs(rows[2 * i + 1], x2[i], 1e-15);
        }
        // Rank 2: the third row is the sum of the first two.
        let singular = [[1.0, 2.0, 3.0], [0.0, 1.0, 1.0], [1.0, 3.0, 4.0]];
        assert_eq!(lu.factor(|i, j| singular[i][j]), Err(FactorError::Singular));
    }
}
