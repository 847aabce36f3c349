//! The symmetric normal equations A δ = −U (Goodman 1966, eq. 14): solved by Cholesky
//! (faer) after Jacobi scaling, with the conditioning and, when A is singular, the unknowns
//! its null space involves.
//!
//! Jacobi scaling: Â = D^{-1/2} A D^{-1/2} with D = diag(A) has a unit diagonal and does not
//! depend on the units of the unknowns, so its condition number measures identifiability
//! rather than scaling. It is the condition number sysid reports.

use std::sync::{Arc, OnceLock};

use faer::linalg::solvers::Solve;
use faer::{MatMut, MatRef, Side};
use nalgebra::{DMatrix, DVector};

/// A normal matrix that cannot be solved: the unknowns with these indices cannot be told
/// apart by the data (or do not influence it at all).
#[derive(Clone, Debug, PartialEq)]
pub struct Singular {
    /// Indices of the unknowns involved in the (near) null space, in problem order.
    pub unknowns: Vec<usize>,
    /// Condition number of the scaled matrix (infinite when exactly singular).
    pub condition: f64,
    /// The coordinate change δz the matrix (nearly) does not see: the eigenvector of the
    /// smallest eigenvalue of the scaled matrix, unscaled, its largest component ±1 and its
    /// first significant component positive.
    pub direction: Vec<f64>,
}

impl Singular {
    /// Singular with every unknown in `unknowns` involved equally (an exact zero).
    fn along(k: usize, unknowns: Vec<usize>) -> Self {
        let mut direction = vec![0.0; k];
        for &i in &unknowns {
            direction[i] = 1.0;
        }
        Self { unknowns, condition: f64::INFINITY, direction }
    }
}

/// `v` scaled so that its largest component is ±1 and its first component above 1 % of
/// that is positive (a direction has no sign; this one reads "a − b", not "−a + b").
fn unit_max(mut v: Vec<f64>) -> Vec<f64> {
    let top = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if top > 0.0 && top.is_finite() {
        let first = v.iter().copied().find(|x| x.abs() >= 0.01 * top).unwrap_or(top);
        let scale = top.copysign(first);
        v.iter_mut().for_each(|x| *x /= scale);
    }
    v
}

/// A factorised, well-conditioned normal matrix.
pub struct NormalFactor {
    /// D^{-1/2}.
    inv_sqrt_diag: Vec<f64>,
    llt: faer::linalg::solvers::Llt<f64>,
    condition: Condition,
}

/// The condition number of a Jacobi-scaled normal matrix (the ratio of its extreme
/// eigenvalues), found when first asked for: a trust region's search for λ factorises tens of
/// matrices an iteration and reports one condition number. Clones share the value.
#[derive(Clone, Debug)]
pub struct Condition {
    value: Arc<OnceLock<f64>>,
    /// The scaled matrix, until its condition number is known.
    scaled: Option<Arc<faer::Mat<f64>>>,
}

impl Condition {
    /// A condition number already known.
    pub fn known(value: f64) -> Self {
        Self { value: Arc::new(OnceLock::from(value)), scaled: None }
    }

    fn of(scaled: faer::Mat<f64>) -> Self {
        Self { value: Arc::new(OnceLock::new()), scaled: Some(Arc::new(scaled)) }
    }

    /// The condition number.
    pub fn value(&self) -> f64 {
        *self.value.get_or_init(|| {
            let scaled = self.scaled.as_ref().expect("a matrix or a value");
            scaled.self_adjoint_eigenvalues(Side::Lower).map_or(f64::INFINITY, |s| ratio(&s))
        })
    }
}

impl PartialEq for Condition {
    fn eq(&self, other: &Self) -> bool {
        self.value().to_bits() == other.value().to_bits()
    }
}

/// The largest eigenvalue over the least, of eigenvalues in increasing order (infinite where
/// the least is not positive).
fn ratio(s: &[f64]) -> f64 {
    let (lo, hi) = (s[0], s[s.len() - 1]);
    if lo > 0.0 { hi / lo } else { f64::INFINITY }
}

/// An upper bound on the condition number of the positive definite `scaled` = L Lᵀ: the
/// largest eigenvalue is at most the largest absolute row sum (Gershgorin), and the least at
/// least 1 / trace(scaled⁻¹) = 1 / ‖L⁻¹‖²_F. It exceeds the condition number by a factor of at
/// most k (the unknowns' number) and costs a sixth of k³ multiplications, against the
/// several k³ of the eigenvalues.
fn condition_bound(scaled: &faer::Mat<f64>, l: MatRef<'_, f64>) -> f64 {
    let k = scaled.nrows();
    let largest =
        (0..k).map(|i| (0..k).map(|j| scaled[(i, j)].abs()).sum::<f64>()).fold(0.0, f64::max);
    // ‖L⁻¹‖²_F, column by column: L x = e_j by forward substitution, x_i = 0 for i < j.
    let mut trace = 0.0;
    let mut x = vec![0.0; k];
    for j in 0..k {
        for i in j..k {
            let mut v = if i == j { 1.0 } else { 0.0 };
            for (m, xm) in x.iter().enumerate().take(i).skip(j) {
                v -= l[(i, m)] * xm;
            }
            x[i] = v / l[(i, i)];
            trace += x[i] * x[i];
        }
    }
    largest * trace
}

/// How far below the limit on the condition number the bound must be to spare the
/// eigenvalues. A Cholesky factor in floating point is that of a matrix perturbed by about
/// k·u of its norm (u the unit roundoff), which moves its least eigenvalue by a relative
/// k·u·κ: near the limit (1e12 by default) that is percents, and a bound from the factor may
/// pass a matrix the eigenvalues refuse. A thousandth of the limit leaves 1e-5 for k ≤ 100,
/// and the decision to the eigenvalues wherever it is close (measured: with the bound at
/// the limit itself, 4 of Borghans' 100 random starts ended elsewhere).
const BOUND_MARGIN: f64 = 1e-3;

/// Share of a null vector's largest component above which an unknown is named as involved.
const INVOLVED: f64 = 0.1;

impl NormalFactor {
    /// Factorises A, or reports it singular when the condition number of the scaled matrix
    /// exceeds `max_condition`.
    pub fn new(a: &DMatrix<f64>, max_condition: f64) -> Result<Self, Singular> {
        let k = a.nrows();
        let diag: Vec<f64> = (0..k).map(|i| a[(i, i)]).collect();
        let dead: Vec<usize> =
            (0..k).filter(|&i| !(diag[i] > 0.0 && diag[i].is_finite())).collect();
        if !dead.is_empty() || a.iter().any(|v| !v.is_finite()) {
            return Err(Singular::along(k, dead));
        }
        let inv_sqrt_diag: Vec<f64> = diag.iter().map(|d| 1.0 / d.sqrt()).collect();
        let scaled =
            faer::Mat::from_fn(k, k, |i, j| a[(i, j)] * inv_sqrt_diag[i] * inv_sqrt_diag[j]);
        // Where the factor exists and a cheap bound on the condition number is within the
        // limit, the eigenvalues are left until the condition number is asked for (a
        // 46-unknown fit had spent a fifth of its time on them); otherwise they decide.
        let llt = scaled.llt(Side::Lower).ok();
        if llt
            .as_ref()
            .is_some_and(|l| condition_bound(&scaled, l.L()) <= BOUND_MARGIN * max_condition)
        {
            let llt = llt.expect("tested");
            return Ok(Self { inv_sqrt_diag, llt, condition: Condition::of(scaled) });
        }
        let eigen = scaled
            .self_adjoint_eigen(Side::Lower)
            .map_err(|_| Singular::along(k, (0..k).collect()))?;
        let s = eigen.S().column_vector();
        let s: Vec<f64> = (0..k).map(|i| s[i]).collect();
        let (hi, condition) = (s[k - 1], ratio(&s));
        if condition > max_condition {
            // Every eigenvector whose eigenvalue is below the threshold spans the null space.
            let u = eigen.U();
            let mut weight = vec![0.0f64; k];
            for c in (0..k).take_while(|&c| s[c] * max_condition < hi) {
                let col = u.col(c);
                let top = (0..k).map(|i| col[i].abs()).fold(0.0, f64::max);
                for (i, w) in weight.iter_mut().enumerate() {
                    if col[i].abs() >= INVOLVED * top {
                        *w = w.max(col[i].abs() / top);
                    }
                }
            }
            let unknowns: Vec<usize> = (0..k).filter(|&i| weight[i] > 0.0).collect();
            let smallest = u.col(0);
            let direction = unit_max((0..k).map(|i| smallest[i] * inv_sqrt_diag[i]).collect());
            return Err(Singular { unknowns, condition, direction });
        }
        let llt = llt.ok_or_else(|| Singular::along(k, (0..k).collect()))?;
        Ok(Self { inv_sqrt_diag, llt, condition: Condition::known(condition) })
    }

    /// Condition number of the scaled normal matrix.
    pub fn condition(&self) -> f64 {
        self.condition.value()
    }

    /// The same, found when first asked for.
    pub fn conditioning(&self) -> Condition {
        self.condition.clone()
    }

    /// Solves A x = b.
    pub fn solve(&self, b: &DVector<f64>) -> DVector<f64> {
        let d = &self.inv_sqrt_diag;
        let mut x = DVector::from_fn(b.len(), |i, _| b[i] * d[i]);
        let k = x.len();
        self.llt.solve_in_place(MatMut::from_column_major_slice_mut(x.as_mut_slice(), k, 1));
        x.iter_mut().zip(d).for_each(|(v, d)| *v *= d);
        x
    }

    /// A⁻¹, by solving against the identity.
    pub fn inverse(&self) -> DMatrix<f64> {
        let k = self.inv_sqrt_diag.len();
        let d = &self.inv_sqrt_diag;
        let mut x = DMatrix::from_fn(k, k, |i, j| if i == j { d[i] } else { 0.0 });
        self.llt.solve_in_place(MatMut::from_column_major_slice_mut(x.as_mut_slice(), k, k));
        DMatrix::from_fn(k, k, |i, j| x[(i, j)] * d[i])
    }
}

/// A view of a nalgebra matrix as a faer matrix (both column-major and contiguous).
pub fn as_faer(a: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols())
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_ode::testing::assert_close;

    #[test]
    fn solves_goodmans_table_three_system() {
        // Goodman 1966, Section IV: A δc = −U* with U* = (−1, −4, −6).
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 6.0, 7.0, 6.0, 14.0, 18.0, 7.0, 18.0, 24.5]);
        let f = NormalFactor::new(&a, 1e12).unwrap();
        let step = f.solve(&DVector::from_vec(vec![1.0, 4.0, 6.0]));
        for (s, e) in step.iter().zip([-0.25, -0.25, 0.5]) {
            assert_close(*s, e, 1e-13);
        }
        let inv = f.inverse();
        let id = &a * &inv;
        for i in 0..3 {
            for j in 0..3 {
                assert!((id[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn names_the_unknowns_of_the_null_space() {
        // Unknowns 1 and 2 enter only through their sum; unknown 0 is independent.
        let j = DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 2.0, 0.5, 1.0, 1.0, 2.0, 0.0, 0.0]);
        let a = j.transpose() * j;
        let err = NormalFactor::new(&a, 1e12).err().unwrap();
        assert_eq!(err.unknowns, vec![1, 2]);
        assert!(err.condition > 1e12);
        // J (0, 1, −1)ᵀ = 0: that is the direction the data do not see.
        let d = &err.direction;
        let sign = d[1].signum();
        for (d, e) in d.iter().zip([0.0, 1.0, -1.0]) {
            assert!((d - sign * e).abs() < 1e-8, "{:?}", err.direction);
        }
        // An unknown without influence.
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 0.0]);
        assert_eq!(NormalFactor::new(&a, 1e12).err().unwrap().unknowns, vec![1]);
    }

    #[test]
    fn condition_is_independent_of_units() {
        let a = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 2.0]);
        let s = DMatrix::from_diagonal(&DVector::from_vec(vec![1e6, 1e-6]));
        let c1 = NormalFactor::new(&a, 1e12).unwrap().condition();
        let c2 = NormalFactor::new(&(&s * &a * &s), 1e12).unwrap().condition();
        assert_close(c1, 3.0, 1e-14);
        assert_close(c2, 3.0, 1e-12);
    }

    /// The bound that spares the eigenvalues lies between the condition number and k times
    /// it; the limit is decided by the eigenvalues wherever the bound passes it, so a matrix
    /// is refused exactly where its condition number exceeds the limit, whatever the bound.
    #[test]
    fn the_condition_bound_holds_and_decides_nothing_alone() {
        // Hilbert-like matrices of growing condition, and a diagonal one (bound = condition).
        for k in [2usize, 5, 9] {
            let a = DMatrix::from_fn(k, k, |i, j| {
                1.0 / (i + j + 1) as f64 + if i == j { 1e-3 } else { 0.0 }
            });
            let d: Vec<f64> = (0..k).map(|i| 1.0 / a[(i, i)].sqrt()).collect();
            let scaled = faer::Mat::from_fn(k, k, |i, j| a[(i, j)] * d[i] * d[j]);
            let exact = ratio(&scaled.self_adjoint_eigenvalues(Side::Lower).unwrap());
            let llt = scaled.llt(Side::Lower).unwrap();
            let bound = condition_bound(&scaled, llt.L());
            assert!(
                exact <= bound * (1.0 + 1e-12) && bound <= k as f64 * exact * (1.0 + 1e-12),
                "k = {k}: condition {exact}, bound {bound}"
            );
            // A limit between the two: accepted, with the exact condition number.
            let between = (exact * bound).sqrt();
            let f = NormalFactor::new(&a, between).unwrap();
            assert_close(f.condition(), exact, 1e-10);
            // Lazily found, the same number.
            let f = NormalFactor::new(&a, 10.0 * bound).unwrap();
            assert_close(f.condition(), exact, 1e-10);
            // A limit just below it: refused.
            let e = NormalFactor::new(&a, exact * (1.0 - 1e-6)).err().unwrap();
            assert_close(e.condition, exact, 1e-10);
        }
        let a = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 4.0]));
        assert_close(NormalFactor::new(&a, 1e12).unwrap().condition(), 1.0, 1e-15);
    }
}
