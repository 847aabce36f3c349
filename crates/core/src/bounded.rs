//! The small dense subproblem of a step, with bounds: minimise a convex quadratic
//!
//!   q(x) = ½ xᵀH x + cᵀx  over the box  lo ≤ x ≤ hi,
//!
//! given either as H and c (Goodman's A and U: x = δz) or as a linear least-squares problem
//! ½‖a + Bx‖² (quasilinearization's constants: H = BᵀB, c = Bᵀa, solved by QR on the free
//! columns, as Stark & Parker's BVLS does).
//!
//! The primal active-set method: from a feasible x, solve for the free variables with the
//! others held; if the solution leaves the box, move towards it until the first bound blocks
//! and hold that variable; once the free solution is feasible, release the held variable
//! whose multiplier (its component of ∇q) most wants it inside — one per round. For a
//! strictly convex q the objective falls strictly between the rounds that release, so no
//! active set repeats and the method ends after finitely many rounds; the set is decided by
//! the multipliers of this model, not by the sign of the gradient at the iterate, so a bound
//! is not entered and left on alternate iterations of the method that uses it. Without
//! finite bounds it is one unconstrained solve.

use faer::linalg::solvers::SolveLstsq;
use nalgebra::{DMatrix, DVector};

use crate::certificate::Bound;
use crate::linalg::{Condition, NormalFactor, Singular, as_faer};

/// A convex quadratic q(x) that can be minimised over a subset of its variables.
pub trait Subproblem {
    /// Number of variables.
    fn len(&self) -> usize;
    /// Whether there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Sets x's entries in `free` to the minimiser of q over them, the others held at their
    /// values in x; returns the condition number of the free block (Jacobi-scaled), or the
    /// free-block indices it cannot tell apart.
    fn solve_free(
        &self,
        free: &[usize],
        x: &mut [f64],
        max_condition: f64,
    ) -> Result<Condition, Singular>;
    /// ∇q at x.
    fn gradient(&self, x: &[f64]) -> DVector<f64>;
}

/// q(x) = ½ xᵀH x + cᵀx with H symmetric positive semi-definite (Goodman's A δ = −U).
pub struct Quadratic<'a> {
    /// H.
    pub h: &'a DMatrix<f64>,
    /// c.
    pub c: &'a DVector<f64>,
}

impl Subproblem for Quadratic<'_> {
    fn len(&self) -> usize {
        self.c.len()
    }

    fn solve_free(
        &self,
        free: &[usize],
        x: &mut [f64],
        max_condition: f64,
    ) -> Result<Condition, Singular> {
        let held: Vec<usize> = (0..x.len()).filter(|i| !free.contains(i)).collect();
        // H_FF x_F = −(c_F + H_FA x_A).
        let rhs = DVector::from_fn(free.len(), |r, _| {
            let i = free[r];
            -(self.c[i] + held.iter().map(|&j| self.h[(i, j)] * x[j]).sum::<f64>())
        });
        let block = self.h.select_rows(free).select_columns(free);
        let factor = NormalFactor::new(&block, max_condition)?;
        for (v, &i) in factor.solve(&rhs).iter().zip(free) {
            x[i] = *v;
        }
        Ok(factor.conditioning())
    }

    fn gradient(&self, x: &[f64]) -> DVector<f64> {
        self.h * DVector::from_column_slice(x) + self.c
    }
}

/// q(x) = ½‖a + Bx‖², solved by QR on the free columns of B.
pub struct LinearLeastSquares<'a> {
    /// B.
    pub b: &'a DMatrix<f64>,
    /// a.
    pub a: &'a DVector<f64>,
}

impl Subproblem for LinearLeastSquares<'_> {
    fn len(&self) -> usize {
        self.b.ncols()
    }

    fn solve_free(
        &self,
        free: &[usize],
        x: &mut [f64],
        max_condition: f64,
    ) -> Result<Condition, Singular> {
        let columns = self.b.select_columns(free);
        // The conditioning (and the unknowns a singular block involves) from the scaled
        // normal matrix; the solution from QR, which does not square it.
        let condition = NormalFactor::new(&columns.tr_mul(&columns), max_condition)?.conditioning();
        let mut target = -self.a.clone();
        for j in (0..x.len()).filter(|j| !free.contains(j)) {
            target.axpy(-x[j], &self.b.column(j), 1.0);
        }
        let rhs = faer::Mat::from_fn(target.len(), 1, |i, _| target[i]);
        let solution = as_faer(&columns).qr().solve_lstsq(rhs);
        for (r, &i) in free.iter().enumerate() {
            x[i] = solution[(r, 0)];
        }
        Ok(condition)
    }

    fn gradient(&self, x: &[f64]) -> DVector<f64> {
        self.b.tr_mul(&(self.a + self.b * DVector::from_column_slice(x)))
    }
}

/// The minimiser of a [`Subproblem`] over a box.
#[derive(Clone, Debug, PartialEq)]
pub struct BoxSolution {
    /// x.
    pub x: Vec<f64>,
    /// The bound each variable is held on.
    pub active: Vec<Option<Bound>>,
    /// Condition number of the last free block solved (1 when every variable is held).
    pub condition: Condition,
}

/// Minimises `q` over lo ≤ x ≤ hi from the feasible `x0` by the primal active-set method
/// (module docs). Variables on a bound of x0 whose gradient pushes outwards start held. A
/// singular free block is reported with indices into the whole variable vector.
pub fn minimise_in_box(
    q: &impl Subproblem,
    (lo, hi): (&[f64], &[f64]),
    x0: &[f64],
    max_condition: f64,
) -> Result<BoxSolution, Singular> {
    let k = q.len();
    let mut x: Vec<f64> =
        x0.iter().zip(lo.iter().zip(hi)).map(|(v, (l, h))| v.clamp(*l, *h)).collect();
    let g = q.gradient(&x);
    // A variable whose box is one point is held from the start and never released.
    let pinned = |i: usize| lo[i] >= hi[i];
    let mut held: Vec<Option<Bound>> = (0..k)
        .map(|i| {
            if pinned(i) || (x[i] <= lo[i] && g[i] > 0.0) {
                Some(Bound::Lower)
            } else if x[i] >= hi[i] && g[i] < 0.0 {
                Some(Bound::Upper)
            } else {
                None
            }
        })
        .collect();
    let mut condition = Condition::known(1.0);
    // A bound per round is entered or left; strict convexity bounds the rounds, this caps them.
    for _ in 0..4 * k + 10 {
        // Solve on the free set; step towards its solution until a bound blocks.
        loop {
            let free: Vec<usize> = (0..k).filter(|&i| held[i].is_none()).collect();
            if free.is_empty() {
                break;
            }
            let mut y = x.clone();
            condition = q.solve_free(&free, &mut y, max_condition).map_err(|s| Singular {
                unknowns: s.unknowns.iter().map(|&i| free[i]).collect(),
                condition: s.condition,
                direction: {
                    let mut d = vec![0.0; k];
                    for (v, &i) in s.direction.iter().zip(&free) {
                        d[i] = *v;
                    }
                    d
                },
            })?;
            // The largest fraction of the way to y that stays inside, and who blocks.
            let mut alpha = 1.0;
            let mut blocking = None;
            for &i in &free {
                let d = y[i] - x[i];
                let (limit, bound) =
                    if d < 0.0 { (lo[i], Bound::Lower) } else { (hi[i], Bound::Upper) };
                if d != 0.0 && limit.is_finite() {
                    let a = (limit - x[i]) / d;
                    if a < alpha {
                        alpha = a.max(0.0);
                        blocking = Some((i, bound));
                    }
                }
            }
            for &i in &free {
                x[i] += alpha * (y[i] - x[i]);
            }
            match blocking {
                None => break,
                Some((i, bound)) => {
                    x[i] = if bound == Bound::Lower { lo[i] } else { hi[i] };
                    held[i] = Some(bound);
                }
            }
        }
        // Release the held variable whose multiplier most wants it inside, if any.
        let g = q.gradient(&x);
        let inward = |i: usize| match held[i] {
            _ if pinned(i) => 0.0,
            Some(Bound::Lower) => -g[i],
            Some(Bound::Upper) => g[i],
            _ => 0.0,
        };
        let scale = g.amax().max(f64::MIN_POSITIVE);
        match (0..k)
            .filter(|&i| inward(i) > 1e-12 * scale)
            .max_by(|&a, &b| inward(a).total_cmp(&inward(b)))
        {
            Some(i) => held[i] = None,
            None => break,
        }
    }
    Ok(BoxSolution { x, active: held, condition })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Enumerates every active set of a small box QP and keeps the best feasible KKT point:
    /// an independent reference for the active-set method.
    fn brute_force(h: &DMatrix<f64>, c: &DVector<f64>, lo: &[f64], hi: &[f64]) -> Vec<f64> {
        let k = c.len();
        let mut best: Option<(f64, Vec<f64>)> = None;
        for code in 0..3usize.pow(k as u32) {
            let mut x = vec![0.0; k];
            let mut free = Vec::new();
            let mut m = code;
            for i in 0..k {
                match m % 3 {
                    0 => free.push(i),
                    1 => x[i] = lo[i],
                    _ => x[i] = hi[i],
                }
                m /= 3;
            }
            if x.iter().any(|v| !v.is_finite()) {
                continue;
            }
            if !free.is_empty() {
                let q = Quadratic { h, c };
                if q.solve_free(&free, &mut x, 1e14).is_err() {
                    continue;
                }
            }
            if x.iter().zip(lo.iter().zip(hi)).any(|(v, (l, u))| *v < l - 1e-12 || *v > u + 1e-12) {
                continue;
            }
            let xv = DVector::from_column_slice(&x);
            let value = 0.5 * xv.dot(&(h * &xv)) + c.dot(&xv);
            if best.as_ref().is_none_or(|b| value < b.0) {
                best = Some((value, x));
            }
        }
        best.unwrap().1
    }

    #[test]
    fn matches_an_enumeration_of_every_active_set() {
        // Random strictly convex problems in 4 variables, boxes around 0.
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let m = DMatrix::from_fn(6, 4, |_, _| next());
            let h = m.tr_mul(&m);
            let c = DVector::from_fn(4, |_, _| 3.0 * next());
            let lo: Vec<f64> = (0..4).map(|_| -0.5 - next().abs()).collect();
            let hi: Vec<f64> =
                (0..4).map(|i| if i == 3 { f64::INFINITY } else { 0.2 + next().abs() }).collect();
            let got =
                minimise_in_box(&Quadratic { h: &h, c: &c }, (&lo, &hi), &[0.0; 4], 1e14).unwrap();
            let want = brute_force(&h, &c, &lo, &hi);
            for (a, b) in got.x.iter().zip(&want) {
                assert!((a - b).abs() < 1e-9, "{:?} vs {want:?}", got.x);
            }
        }
    }

    #[test]
    fn least_squares_form_agrees_with_the_quadratic_form() {
        let b = DMatrix::from_row_slice(5, 2, &[1.0, 0.0, 1.0, 1.0, 1.0, 2.0, 1.0, 3.0, 1.0, 4.0]);
        let a = DVector::from_vec(vec![-1.0, -2.9, -5.1, -7.0, -8.8]);
        let (lo, hi) = ([-1.0, 2.5], [0.5, 10.0]);
        let ls =
            minimise_in_box(&LinearLeastSquares { b: &b, a: &a }, (&lo, &hi), &[0.3, 3.0], 1e14)
                .unwrap();
        let (h, c) = (b.tr_mul(&b), b.tr_mul(&a));
        let quad =
            minimise_in_box(&Quadratic { h: &h, c: &c }, (&lo, &hi), &[0.3, 3.0], 1e14).unwrap();
        for (x, y) in ls.x.iter().zip(&quad.x) {
            assert!((x - y).abs() < 1e-12, "{:?} {:?}", ls.x, quad.x);
        }
        // The unconstrained slope is about 1.96 < 2.5: the slope sits on its lower bound and
        // the intercept, free, is the mean of y − 2.5 t, −0.04.
        assert_eq!(ls.active, vec![None, Some(Bound::Lower)]);
        assert!((ls.x[0] + 0.04).abs() < 1e-12, "{:?}", ls.x);
    }

    #[test]
    fn without_bounds_it_is_one_solve() {
        let h = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 3.0]);
        let c = DVector::from_vec(vec![1.0, -2.0]);
        let inf = [f64::NEG_INFINITY, f64::NEG_INFINITY];
        let sup = [f64::INFINITY, f64::INFINITY];
        let got =
            minimise_in_box(&Quadratic { h: &h, c: &c }, (&inf, &sup), &[0.0, 0.0], 1e14).unwrap();
        let want = h.clone().lu().solve(&(-&c)).unwrap();
        assert!((got.x[0] - want[0]).abs() < 1e-14 && (got.x[1] - want[1]).abs() < 1e-14);
        assert_eq!(got.active, vec![None, None]);
    }
}
