//! Dense LU with partial pivoting, factorised in place into preallocated storage: the
//! implicit integrator factorises once per step without allocating.

/// Why an implicit step cannot proceed with a right-hand side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FactorError {
    /// The right-hand side provides no Jacobian (implicit methods cannot be used).
    Unsupported,
    /// E = I/(γh) − ∂f/∂x is singular (a shorter step usually cures it).
    Singular,
}

/// An n × n matrix and its LU factors.
///
/// The factorisation is a plain right-looking elimination with partial pivoting, and the
/// solves plain forward and back substitution. For the small systems of implicit steps (n of
/// a few to a few dozen) faer's general factorisation and solve spent more time in
/// recursion, permutation and copying than in arithmetic (Isensee, n = 25: a fifth of an
/// adjoint gradient in faer's factorisation). The substitution is column-oriented: once x_j is known it is
/// eliminated from every later (earlier, going back) equation at once, so the chain of
/// dependent operations is one multiply-add per unknown rather than a dot product per
/// unknown; an n × k block is solved the same way with its rows as the unknowns, the k
/// columns in the inner loop.
pub struct Lu {
    n: usize,
    /// P A = L U: row i of P A is row fwd[i] of A.
    fwd: Vec<usize>,
    /// L (unit diagonal, strictly below) and U (above the diagonal), column by column, with
    /// the reciprocals of U's diagonal on the diagonal: back substitution multiplies instead
    /// of dividing.
    factors: Vec<f64>,
    /// The permuted right-hand side.
    work: Vec<f64>,
}

impl Lu {
    /// Storage for n × n, and for solves with up to `columns` right-hand sides at once.
    pub fn new(n: usize, columns: usize) -> Self {
        Self { n, fwd: vec![0; n], factors: vec![0.0; n * n], work: vec![0.0; n * columns.max(1)] }
    }

    /// n, for n × n.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Fills the matrix with `entry(i, j)` and factorises it.
    pub fn factor(&mut self, entry: impl Fn(usize, usize) -> f64) -> Result<(), FactorError> {
        let n = self.n;
        let a = &mut self.factors[..n * n];
        for j in 0..n {
            for (i, v) in a[j * n..(j + 1) * n].iter_mut().enumerate() {
                *v = entry(i, j);
            }
        }
        if a.iter().any(|v| !v.is_finite()) {
            return Err(FactorError::Singular);
        }
        for (i, p) in self.fwd.iter_mut().enumerate() {
            *p = i;
        }
        // Right-looking elimination, column by column: the pivot is the column's largest
        // entry on or below the diagonal; its row is swapped up across the whole matrix, the
        // column below it becomes L's, and the rest of the matrix takes the rank-one update
        // one column at a time (contiguous, so the inner loop vectorises).
        for k in 0..n {
            let column = &a[k * n..(k + 1) * n];
            let (mut p, mut largest) = (k, column[k].abs());
            for (i, v) in column.iter().enumerate().skip(k + 1) {
                if v.abs() > largest {
                    (p, largest) = (i, v.abs());
                }
            }
            // A zero or non-finite pivot: singular (to working precision).
            if !(largest > 0.0 && largest.is_finite()) {
                return Err(FactorError::Singular);
            }
            if p != k {
                self.fwd.swap(k, p);
                for j in 0..n {
                    a.swap(j * n + k, j * n + p);
                }
            }
            let inverse_pivot = 1.0 / a[k * n + k];
            let (left, right) = a.split_at_mut((k + 1) * n);
            let multipliers = &mut left[k * n + k + 1..];
            for l in multipliers.iter_mut() {
                *l *= inverse_pivot;
            }
            for column in right.chunks_exact_mut(n) {
                let akj = column[k];
                if akj != 0.0 {
                    for (v, &l) in column[k + 1..].iter_mut().zip(multipliers.iter()) {
                        *v -= l * akj;
                    }
                }
            }
            a[k * n + k] = inverse_pivot;
        }
        Ok(())
    }

    /// Overwrites r (length n) with A⁻¹ r.
    pub fn solve(&mut self, r: &mut [f64]) {
        // With n known at compile time the substitutions' loops are unrolled: the state's
        // solve of every Rosenbrock stage is a chain of a few dozen multiply-adds (Boehm's
        // and Brannmark's 8 and 9 states: 1.09× and 1.11× their NLL + gradient). At 25
        // states (Bachmann, Isensee) the unrolled solve was 2 % slower than the loop.
        match self.n {
            1..=16 => by_width!(self.n, N => self.solve_n::<N>(r)),
            _ => self.solve_n::<0>(r),
        }
    }

    /// [`solve`](Self::solve) with n = N, or n = self.n for N = 0.
    fn solve_n<const N: usize>(&mut self, r: &mut [f64]) {
        let n = if N == 0 { self.n } else { N };
        let (lu, x, r) = (&self.factors[..n * n], &mut self.work[..n], &mut r[..n]);
        for (xi, &from) in x.iter_mut().zip(&self.fwd[..n]) {
            *xi = r[from];
        }
        // L y = P r, unit diagonal: y_j leaves the equations below it.
        for j in 0..n {
            let (done, rest) = x.split_at_mut(j + 1);
            let yj = done[j];
            if yj != 0.0 {
                for (v, l) in rest.iter_mut().zip(&lu[j * n + j + 1..(j + 1) * n]) {
                    *v -= l * yj;
                }
            }
        }
        // U x = y: x_j leaves the equations above it.
        for j in (0..n).rev() {
            let (rest, done) = x.split_at_mut(j);
            let xj = done[0] * lu[j * n + j];
            done[0] = xj;
            if xj != 0.0 {
                for (v, u) in rest.iter_mut().zip(&lu[j * n..j * n + j]) {
                    *v -= u * xj;
                }
            }
        }
        r.copy_from_slice(x);
    }

    /// Overwrites the n × k matrix R, stored row by row in r, with A⁻¹ R (k at most the
    /// `columns` given to [`new`](Self::new)).
    pub fn solve_rows(&mut self, r: &mut [f64], k: usize) {
        // The k columns are the inner loop: with k known at compile time, a row is a few
        // vector operations instead of a loop, and its copies fixed moves (SalazarCavazos' 75
        // states and 6 columns: 31 % of an NLL + gradient in this solve before; Elowitz's 18
        // columns, 1.18× its NLL + gradient once 18 was a width of its own). Wider rows are
        // long enough for a run-time loop to vectorise well.
        match k {
            0 => {}
            1..=PANEL => by_width!(k, K => self.solve_block::<K>(r, K)),
            _ => self.solve_block::<0>(r, k),
        }
    }

    /// [`solve_rows`](Self::solve_rows) with rows of K = `k` columns, or of `k` columns in a
    /// run-time loop for K = 0 (more than [`PANEL`]: long enough to vectorise well; solved in
    /// panels of compile-time width instead, Raimundez's NLL + gradient took 16 % in this
    /// solve against 6 %, each panel going over all the factors again).
    fn solve_block<const K: usize>(&mut self, r: &mut [f64], k: usize) {
        let n = self.n;
        let (lu, x, r) = (&self.factors[..n * n], &mut self.work[..n * k], &mut r[..n * k]);
        // P A = L U: row i of P R is row fwd[i] of R.
        for (i, &from) in self.fwd.iter().enumerate() {
            x[i * k..(i + 1) * k].copy_from_slice(&r[from * k..(from + 1) * k]);
        }
        // L Y = P R, unit diagonal: row j of Y leaves the rows below it.
        for j in 0..n {
            let (done, rest) = x.split_at_mut((j + 1) * k);
            let solved = &done[j * k..];
            for (row, &l) in rest.chunks_exact_mut(k).zip(&lu[j * n + j + 1..(j + 1) * n]) {
                if l != 0.0 {
                    eliminate::<K>(row, solved, l);
                }
            }
        }
        // U X = Y: row j of X leaves the rows above it.
        for j in (0..n).rev() {
            let (rest, done) = x.split_at_mut(j * k);
            let solved = &mut done[..k];
            let inverse_pivot = lu[j * n + j];
            for v in solved.iter_mut() {
                *v *= inverse_pivot;
            }
            for (row, &u) in rest.chunks_exact_mut(k).zip(&lu[j * n..j * n + j]) {
                if u != 0.0 {
                    eliminate::<K>(row, solved, u);
                }
            }
        }
        r.copy_from_slice(x);
    }

    /// Overwrites r (length n) with A⁻ᵀ r: from P A = L U, Uᵀ z = r, Lᵀ v = z and x = Pᵀ v, each
    /// row of Uᵀ and Lᵀ a column of the factors, contiguous.
    pub fn solve_transposed(&mut self, r: &mut [f64]) {
        let n = self.n;
        let (lu, x) = (&self.factors[..n * n], &mut self.work[..n]);
        // Uᵀ z = r: z_i = (r_i − Σ_{j<i} U_ji z_j) / U_ii.
        for i in 0..n {
            let dot = dot(&lu[i * n..i * n + i], &x[..i]);
            x[i] = (r[i] - dot) * lu[i * n + i];
        }
        // Lᵀ v = z, unit diagonal: v_i = z_i − Σ_{j>i} L_ji v_j.
        for i in (0..n).rev() {
            let dot = dot(&lu[i * n + i + 1..(i + 1) * n], &x[i + 1..]);
            x[i] -= dot;
        }
        for (&to, v) in self.fwd.iter().zip(x.iter()) {
            r[to] = *v;
        }
    }
}

/// Σ a_i b_i over the shorter of a and b; from [`LANES_FROM`] entries in four partial sums
/// (entry i into sum i mod 4): a sum in one chain waits on every addition before it, and does
/// not vectorise (the adjoint's transposed solves on SalazarCavazos' 75 states took 2.5 times
/// as long as the plain solves, whose updates are independent).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let len = a.len().min(b.len());
    if len < LANES_FROM {
        return a[..len].iter().zip(&b[..len]).map(|(a, b)| a * b).sum();
    }
    let (a4, a_rest) = a[..len].as_chunks::<4>();
    let (b4, b_rest) = b[..len].as_chunks::<4>();
    let mut sum = [0.0; 4];
    for (a, b) in a4.iter().zip(b4) {
        for lane in 0..4 {
            sum[lane] += a[lane] * b[lane];
        }
    }
    for (lane, (a, b)) in a_rest.iter().zip(b_rest).enumerate() {
        sum[lane] += a * b;
    }
    (sum[0] + sum[1]) + (sum[2] + sum[3])
}

/// The length from which [`dot`] sums in four lanes: below it the lanes' set-up costs more
/// than the chain (Fujita's 9 states, Elowitz's 8, Schwen's 11 and Weber's 7 were 3–7 %
/// slower by adjoint with four lanes at every length; SalazarCavazos' 75 states 8 % faster).
const LANES_FROM: usize = 32;

/// The widest block of columns whose width is known at compile time ([`by_width`]).
pub(crate) const PANEL: usize = 32;

/// k columns as the fewest panels (first column, width) of at most [`PANEL`] columns, their
/// widths as equal as can be (33 as 17 and 16, not 32 and a pass for one column).
pub(crate) fn panels(k: usize) -> impl Iterator<Item = (usize, usize)> {
    let count = k.div_ceil(PANEL);
    let (width, wider) = (k / count.max(1), k % count.max(1));
    (0..count).map(move |p| (p * width + p.min(wider), width + usize::from(p < wider)))
}

/// `$body` with the const `$K` set to `$k`, which must be 1 to [`PANEL`]: a block's width
/// known at compile time (see [`Lu::solve_rows`] and [`panels`]).
macro_rules! by_width {
    ($k:expr, $K:ident => $body:expr) => {
        match $k {
            1 => {
                const $K: usize = 1;
                $body
            }
            2 => {
                const $K: usize = 2;
                $body
            }
            3 => {
                const $K: usize = 3;
                $body
            }
            4 => {
                const $K: usize = 4;
                $body
            }
            5 => {
                const $K: usize = 5;
                $body
            }
            6 => {
                const $K: usize = 6;
                $body
            }
            7 => {
                const $K: usize = 7;
                $body
            }
            8 => {
                const $K: usize = 8;
                $body
            }
            9 => {
                const $K: usize = 9;
                $body
            }
            10 => {
                const $K: usize = 10;
                $body
            }
            11 => {
                const $K: usize = 11;
                $body
            }
            12 => {
                const $K: usize = 12;
                $body
            }
            13 => {
                const $K: usize = 13;
                $body
            }
            14 => {
                const $K: usize = 14;
                $body
            }
            15 => {
                const $K: usize = 15;
                $body
            }
            16 => {
                const $K: usize = 16;
                $body
            }
            17 => {
                const $K: usize = 17;
                $body
            }
            18 => {
                const $K: usize = 18;
                $body
            }
            19 => {
                const $K: usize = 19;
                $body
            }
            20 => {
                const $K: usize = 20;
                $body
            }
            21 => {
                const $K: usize = 21;
                $body
            }
            22 => {
                const $K: usize = 22;
                $body
            }
            23 => {
                const $K: usize = 23;
                $body
            }
            24 => {
                const $K: usize = 24;
                $body
            }
            25 => {
                const $K: usize = 25;
                $body
            }
            26 => {
                const $K: usize = 26;
                $body
            }
            27 => {
                const $K: usize = 27;
                $body
            }
            28 => {
                const $K: usize = 28;
                $body
            }
            29 => {
                const $K: usize = 29;
                $body
            }
            30 => {
                const $K: usize = 30;
                $body
            }
            31 => {
                const $K: usize = 31;
                $body
            }
            32 => {
                const $K: usize = 32;
                $body
            }
            width => unreachable!("a panel of 1 to 32 columns, not {width}"),
        }
    };
}
pub(crate) use by_width;

/// row −= factor · solved, over K columns (K known at compile time), or over every column
/// of the row for K = 0.
#[inline(always)]
pub(crate) fn eliminate<const K: usize>(row: &mut [f64], solved: &[f64], factor: f64) {
    if K == 0 {
        for (v, y) in row.iter_mut().zip(solved) {
            *v -= factor * y;
        }
        return;
    }
    let (row, solved): (&mut [f64; K], &[f64; K]) = (
        (&mut row[..K]).try_into().expect("K columns"),
        (&solved[..K]).try_into().expect("K columns"),
    );
    for c in 0..K {
        row[c] -= factor * solved[c];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_close_abs;

    /// Aᵀ x = r against A's entries, with the pivoting the factorisation chose.
    #[test]
    fn transposed_solves_invert_the_transpose() {
        let mut lu = Lu::new(4, 1);
        let a = [
            [0.0, 2.0, 1.0, 0.5],
            [1.0, 1.0, 0.0, -2.0],
            [3.0, 0.0, 4.0, 1.0],
            [0.2, -1.0, 0.0, 2.0],
        ];
        lu.factor(|i, j| a[i][j]).unwrap();
        let r = [1.0, -2.0, 0.5, 3.0];
        let mut x = r;
        lu.solve_transposed(&mut x);
        for (j, rj) in r.iter().enumerate() {
            let back: f64 = (0..4).map(|i| a[i][j] * x[i]).sum();
            assert_close_abs(back, *rj, 1e-13);
        }
    }

    /// The same at 75 unknowns, where the substitutions' sums run in four lanes from 32
    /// terms, and the lanes' sum against the sum in one chain for every length to 40.
    #[test]
    fn transposed_solves_in_lanes_invert_the_transpose() {
        let n = 75;
        let a = |i: usize, j: usize| {
            let off = ((i * 7 + j * 3) % 11) as f64 / 11.0 - 0.5;
            if i == j { 4.0 + off } else { off / 3.0 }
        };
        let mut lu = Lu::new(n, 1);
        lu.factor(a).unwrap();
        let r: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut x = r.clone();
        lu.solve_transposed(&mut x);
        for (j, rj) in r.iter().enumerate() {
            let back: f64 = (0..n).map(|i| a(i, j) * x[i]).sum();
            assert_close_abs(back, *rj, 1e-12);
        }
        for len in 0..40 {
            let u: Vec<f64> = (0..len).map(|i| (i as f64 * 0.9).cos()).collect();
            let v: Vec<f64> = (0..len + 3).map(|i| 1.0 / (1.0 + i as f64)).collect();
            let chain: f64 = u.iter().zip(&v).map(|(a, b)| a * b).sum();
            assert_close_abs(dot(&u, &v), chain, 1e-14);
        }
    }

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
        // A larger matrix with pivoting on every column, three right-hand sides at once,
        // against nalgebra's LU.
        let n = 9;
        let entry = |i: usize, j: usize| {
            ((i * 7 + j * 3) % 11) as f64 - 5.0 + if i == j { 0.5 } else { 0.0 }
        };
        let mut big = Lu::new(n, 3);
        big.factor(entry).unwrap();
        let a = nalgebra::DMatrix::from_fn(n, n, entry);
        let b = nalgebra::DMatrix::from_fn(n, 3, |i, j| (i as f64 - 2.0 * j as f64).sin());
        let x = a.clone().lu().solve(&b).unwrap();
        let mut rows: Vec<f64> =
            (0..n).flat_map(|i| (0..3).map(move |j| (i, j))).map(|(i, j)| b[(i, j)]).collect();
        big.solve_rows(&mut rows, 3);
        for i in 0..n {
            for j in 0..3 {
                assert_close_abs(rows[i * 3 + j], x[(i, j)], 1e-12 * x.amax());
            }
        }
        // Rank 2: the third row is the sum of the first two.
        let singular = [[1.0, 2.0, 3.0], [0.0, 1.0, 1.0], [1.0, 3.0, 4.0]];
        assert_eq!(lu.factor(|i, j| singular[i][j]), Err(FactorError::Singular));
    }

    /// Every width of block, known at compile time (1–32) or wider in a run-time loop (33,
    /// 40, 72), gives each column what the single solve gives it, to the last bit.
    #[test]
    fn block_solves_of_every_width_are_the_column_solves() {
        let n = 11;
        let entry = |i: usize, j: usize| {
            ((i * 5 + j * 7) % 13) as f64 - 6.0 + if i == j { 0.25 } else { 0.0 }
        };
        for k in [1, 2, 3, 4, 5, 6, 7, 8, 9, 12, 16, 17, 18, 20, 31, 32, 33, 40, 72] {
            let mut lu = Lu::new(n, k);
            lu.factor(entry).unwrap();
            let b = |i: usize, j: usize| (i as f64 * 0.7 - j as f64 * 1.3).cos();
            let mut rows: Vec<f64> = (0..n).flat_map(|i| (0..k).map(move |j| b(i, j))).collect();
            lu.solve_rows(&mut rows, k);
            for j in 0..k {
                let mut column: Vec<f64> = (0..n).map(|i| b(i, j)).collect();
                lu.solve(&mut column);
                for i in 0..n {
                    assert_eq!(rows[i * k + j].to_bits(), column[i].to_bits(), "k = {k}");
                }
            }
        }
    }

    /// The panels cover the k columns in order without gap or overlap, each 1 to PANEL wide,
    /// as few as can be, their widths at most one apart.
    #[test]
    fn panels_cover_the_columns_evenly() {
        assert_eq!(panels(0).count(), 0);
        assert_eq!(panels(33).collect::<Vec<_>>(), [(0, 17), (17, 16)]);
        assert_eq!(panels(72).collect::<Vec<_>>(), [(0, 24), (24, 24), (48, 24)]);
        for k in 1..=200 {
            let all: Vec<(usize, usize)> = panels(k).collect();
            assert_eq!(all.len(), k.div_ceil(PANEL), "k = {k}");
            let mut next = 0;
            for &(first, width) in &all {
                assert_eq!(first, next, "k = {k}");
                assert!((1..=PANEL).contains(&width), "k = {k}");
                next += width;
            }
            assert_eq!(next, k);
            let widths = all.iter().map(|p| p.1);
            assert!(widths.clone().max().unwrap() - widths.min().unwrap() <= 1, "k = {k}");
        }
    }

    /// The single solve with n known at compile time (n ≤ 16) is the run-time loop's to the
    /// bit, and solves the system.
    #[test]
    fn single_solves_of_every_size_are_the_run_time_loops() {
        for n in [1, 2, 3, 5, 8, 9, 14, 16, 17, 25] {
            let entry = |i: usize, j: usize| {
                ((i * 5 + j * 7) % 13) as f64 - 6.0 + if i == j { 0.25 } else { 0.0 }
            };
            let mut lu = Lu::new(n, 1);
            lu.factor(entry).unwrap();
            let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).cos()).collect();
            let (mut fixed, mut looped) = (b.clone(), b.clone());
            lu.solve(&mut fixed);
            lu.solve_n::<0>(&mut looped);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fixed), bits(&looped), "n = {n}");
            for (i, &bi) in b.iter().enumerate() {
                let ax: f64 = (0..n).map(|j| entry(i, j) * fixed[j]).sum();
                assert_close_abs(ax, bi, 1e-12);
            }
        }
    }
}
