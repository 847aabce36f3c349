//! Sparse LU of an implicit step's matrix E = I/(γh) − ∂g/∂y, for large systems whose
//! Jacobian has few entries per row (a reaction network: Chen's 500 species).
//!
//! E's pattern is the Jacobian's and the diagonal, the same at every step, so the work that
//! depends on the pattern alone is done once, not per step: a fill-reducing symmetric order
//! (approximate minimum degree on E + Eᵀ, faer's AMD) and the pattern of the factors in that
//! order, a [`Plan`], found once per system where the system keeps it ([`PlanCell`]), else
//! once per integration. Each step then refills the values and eliminates along the pattern
//! with the diagonal as pivots, and the solves (k right-hand sides stored row by row, the
//! sensitivities' layout) cost one multiply-add per entry of the factors and column, the
//! columns contiguous in the inner loop.
//!
//! Diagonal pivots are safe where E is diagonally dominant, as it is for short steps; they
//! are checked as threshold partial pivoting would (KLU's threshold, 10⁻³): a multiplier
//! larger than 10³ in magnitude, or a zero or non-finite pivot, and the step's matrix is
//! factorised dense with partial pivoting instead ([`Lu`]), as are the next few steps'
//! ([`MAX_SKIP`]).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::SymbolicSparseColMatRef;
use faer::sparse::linalg::amd;

use crate::lu::{FactorError, Lu, PANEL, by_width, eliminate};

/// The largest multiplier accepted from diagonal pivots: 1/τ for threshold partial pivoting
/// with τ = 10⁻³.
const MAX_MULTIPLIER: f64 = 1e3;

/// What the factors' work depends on that the pattern alone fixes: the fill-reducing order
/// and the factors' pattern in it. Found once per system ([`PlanCell`]) and shared by every
/// integration's [`SparseLu`].
#[derive(Debug)]
pub struct Plan {
    n: usize,
    /// The order: row and column `order[i]` of E is row and column i of the factored matrix.
    order: Vec<usize>,
    /// Row i of the factors (in the order) is `columns[starts[i]..starts[i + 1]]`, ascending:
    /// L's entries left of the diagonal, then U's from the diagonal on.
    starts: Vec<usize>,
    columns: Vec<usize>,
    /// Where each row's diagonal entry is.
    diagonal: Vec<usize>,
    /// E's own entries: (where in the factors' values, index i·n + j of the dense Jacobian,
    /// on the diagonal).
    entries: Vec<(usize, usize, bool)>,
}

/// A system's [`Plan`], found at its first sparse factorisation and kept for every later
/// integration (its conditions, its adjoint's backward parts, the fits' evaluations):
/// [`SparseJacobian::lu_plan`](crate::SparseJacobian::lu_plan). Empty until then.
#[derive(Clone, Debug, Default)]
pub struct PlanCell(std::sync::OnceLock<Option<std::sync::Arc<Plan>>>);

impl PlanCell {
    /// The plan of n × n matrices with the entries `pattern` off the diagonal (columns n and
    /// beyond ignored), found on the first call; `None` where the order cannot be computed.
    /// Every call must give the same pattern (a cell belongs to one system's Jacobian).
    pub fn get_or_find(&self, n: usize, pattern: &[(u32, u32)]) -> Option<std::sync::Arc<Plan>> {
        let plan = self.0.get_or_init(|| Plan::new(n, pattern).map(std::sync::Arc::new)).clone();
        debug_assert!(plan.as_ref().is_none_or(|p| p.n == n), "a plan of another order");
        plan
    }
}

/// E's factors along a shared [`Plan`], and the dense fallback.
pub struct SparseLu {
    plan: std::sync::Arc<Plan>,
    /// The factors: L's multipliers, U's entries, and the reciprocal of U's diagonal.
    values: Vec<f64>,
    /// A row of the matrix being eliminated, dense.
    row: Vec<f64>,
    /// The right-hand sides in the order, row by row.
    work: Vec<f64>,
    /// The dense factorisation of the steps where the diagonal pivots are refused, formed
    /// at the first refusal (n² values that most integrations never touch), and J made
    /// dense for it where it is given by its entries.
    dense: Option<Lu>,
    spread: Vec<f64>,
    /// The most right-hand sides solved at once.
    width: usize,
    use_dense: bool,
    /// Factorisations still to go dense without trying the diagonal pivots, and how many
    /// the next refusal skips ([`MAX_SKIP`]).
    skip: u32,
    backoff: u32,
}

/// The most factorisations that go dense, untried, after the diagonal pivots were refused:
/// after a refusal the next 1, then 2, 4, … up to this many skip the attempt, which costs an
/// elimination cut short where the matrix needs pivoting (Bachmann refuses them at most of
/// its steps); a success starts the count again.
const MAX_SKIP: u32 = 64;

impl Plan {
    /// For n × n matrices whose entries off the diagonal are among `pattern` (row, column;
    /// columns n and beyond are ignored: the Jacobian's parameter columns); `None` where the
    /// order cannot be computed.
    pub fn new(n: usize, pattern: &[(u32, u32)]) -> Option<Self> {
        let mut entries: Vec<(usize, usize)> = pattern
            .iter()
            .map(|&(i, j)| (i as usize, j as usize))
            .filter(|&(i, j)| i < n && j < n)
            .chain((0..n).map(|i| (i, i)))
            .collect();
        entries.sort_unstable_by_key(|&(i, j)| (j, i));
        entries.dedup();
        let order = minimum_degree(n, &entries)?;
        let mut position = vec![0; n];
        for (new, &old) in order.iter().enumerate() {
            position[old] = new;
        }
        let rows = fill(n, entries.iter().map(|&(i, j)| (position[i], position[j])));
        let mut starts = vec![0];
        let mut all = Vec::new();
        let mut diagonal = Vec::with_capacity(n);
        for (i, row) in rows.iter().enumerate() {
            diagonal.push(all.len() + row.iter().position(|&j| j == i).expect("the diagonal"));
            all.extend_from_slice(row);
            starts.push(all.len());
        }
        let slot = |i: usize, j: usize| {
            let row = &all[starts[i]..starts[i + 1]];
            starts[i] + row.binary_search(&j).expect("E's entries are in the fill")
        };
        let entries = entries
            .iter()
            .map(|&(i, j)| (slot(position[i], position[j]), i * n + j, i == j))
            .collect();
        Some(Self { n, order, columns: all, starts, diagonal, entries })
    }

    /// The entries of the factors L and U (the diagonal once).
    pub fn entries_of_factors(&self) -> usize {
        self.columns.len()
    }

    /// E's entries: J's pattern (columns below n) and the diagonal, each once.
    pub fn entries(&self) -> usize {
        self.entries.len()
    }

    /// J row by row from its values in the plan's places.
    pub fn spread(&self, placed: &[f64]) -> Vec<f64> {
        let mut jac = vec![0.0; self.n * self.n];
        self.spread_into(placed, &mut jac);
        jac
    }

    /// Puts J's values in the plan's places into `jac` (n × n, row by row), leaving its
    /// other entries as they are.
    fn spread_into(&self, placed: &[f64], jac: &mut [f64]) {
        for (&(_, at, _), &v) in self.entries.iter().zip(placed) {
            jac[at] = v;
        }
    }

    /// Where J's entry (i, j) is among the plan's entries ([`SparseLu::factor`]): `None`
    /// for a place outside the pattern the plan was made for.
    pub fn place(&self, i: usize, j: usize) -> Option<usize> {
        let n = self.n;
        // The entries are in column order, rows ascending within a column: at = i·n + j.
        let key = |e: &(usize, usize, bool)| (e.1 % n, e.1 / n);
        self.entries.binary_search_by_key(&(j, i), key).ok()
    }
}

impl SparseLu {
    /// For n × n matrices whose entries off the diagonal are among `pattern` (row, column;
    /// columns n and beyond are ignored: the Jacobian's parameter columns), with solves of
    /// up to `columns` right-hand sides at once; `None` where the order cannot be computed.
    #[cfg(test)]
    pub fn new(n: usize, pattern: &[(u32, u32)], columns: usize) -> Option<Self> {
        Some(Self::with_plan(std::sync::Arc::new(Plan::new(n, pattern)?), columns))
    }

    /// Along a plan found before, with solves of up to `columns` right-hand sides at once.
    pub fn with_plan(plan: std::sync::Arc<Plan>, columns: usize) -> Self {
        let n = plan.n;
        Self {
            values: vec![0.0; plan.columns.len()],
            row: vec![0.0; n],
            work: vec![0.0; n * columns.max(1)],
            plan,
            dense: None,
            spread: Vec::new(),
            width: columns,
            use_dense: false,
            skip: 0,
            backoff: 0,
        }
    }

    /// The entries of the factors L and U (the diagonal once).
    pub fn entries_of_factors(&self) -> usize {
        self.plan.entries_of_factors()
    }

    /// The order n.
    pub fn dim(&self) -> usize {
        self.plan.n
    }

    /// The plan the factors follow.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// Whether the last factorisation fell back to the dense LU.
    pub fn fell_back(&self) -> bool {
        self.use_dense
    }

    /// Factorises E = I·`inv_gamma_h` − J, J given by its values in the plan's places
    /// ([`Plan::place`]; a place of the plan's that J lacks, on the diagonal, holds 0): along
    /// the pattern with diagonal pivots, or dense where they are refused, or were refused
    /// lately ([`MAX_SKIP`]). J is never held as n² values but there (a system of 20 000
    /// states held 3.2 GB of them, nearly all zero, where its factors are sparse).
    pub fn factor(&mut self, inv_gamma_h: f64, jac: &[f64]) -> Result<(), FactorError> {
        self.use_dense = false;
        if self.skip > 0 {
            self.skip -= 1;
        } else if self.factor_along_pattern(inv_gamma_h, jac)? {
            self.backoff = 0;
            return Ok(());
        } else {
            self.backoff = (2 * self.backoff).clamp(1, MAX_SKIP);
            self.skip = self.backoff;
        }
        self.use_dense = true;
        let (n, width) = (self.plan.n, self.width);
        // The places outside the plan are never written: they stay 0.
        self.spread.resize(n * n, 0.0);
        self.plan.spread_into(jac, &mut self.spread);
        let (dense, jac) = (self.dense.get_or_insert_with(|| Lu::new(n, width)), &self.spread);
        dense.factor(|i, j| if i == j { inv_gamma_h } else { 0.0 } - jac[i * n + j])
    }

    /// E's entries put in the factors' pattern and eliminated with diagonal pivots: whether
    /// the pivots were accepted ([`eliminate`](Self::eliminate)).
    fn factor_along_pattern(&mut self, inv_gamma_h: f64, jac: &[f64]) -> Result<bool, FactorError> {
        self.values.fill(0.0);
        for (&(slot, _, diagonal), &j) in self.plan.entries.iter().zip(jac) {
            self.values[slot] = if diagonal { inv_gamma_h } else { 0.0 } - j;
        }
        if self.values.iter().any(|v| !v.is_finite()) {
            return Err(FactorError::Singular);
        }
        Ok(self.eliminate())
    }

    /// Gaussian elimination along the pattern, row by row, with the diagonal as pivots;
    /// false where a pivot is zero or not finite or a multiplier exceeds [`MAX_MULTIPLIER`].
    fn eliminate(&mut self) -> bool {
        let Self { plan, values, row, .. } = self;
        let Plan { starts, columns, diagonal, .. } = &**plan;
        for i in 0..plan.n {
            let own = starts[i]..starts[i + 1];
            for p in own.clone() {
                row[columns[p]] = values[p];
            }
            for p in starts[i]..diagonal[i] {
                let k = columns[p];
                let multiplier = row[k] * values[diagonal[k]];
                if multiplier.is_nan() || multiplier.abs() > MAX_MULTIPLIER {
                    return false;
                }
                row[k] = multiplier;
                if multiplier != 0.0 {
                    for q in diagonal[k] + 1..starts[k + 1] {
                        row[columns[q]] -= multiplier * values[q];
                    }
                }
            }
            for p in own {
                values[p] = row[columns[p]];
            }
            let pivot = values[diagonal[i]];
            if !(pivot != 0.0 && pivot.is_finite()) {
                return false;
            }
            values[diagonal[i]] = 1.0 / pivot;
        }
        true
    }

    /// Overwrites r (length n) with E⁻¹ r: the block solve at K = 1, its row's sum in a
    /// register.
    pub fn solve(&mut self, r: &mut [f64]) {
        self.solve_rows(r, 1);
    }

    /// Overwrites the n × k matrix R, stored row by row in r, with E⁻¹ R (k at most the
    /// `columns` given to [`new`](Self::new)).
    pub fn solve_rows(&mut self, r: &mut [f64], k: usize) {
        if let Some(dense) = self.dense.as_mut().filter(|_| self.use_dense) {
            return match k {
                1 => dense.solve(r),
                _ => dense.solve_rows(r, k),
            };
        }
        match k {
            0 => {}
            1..=PANEL => by_width!(k, K => self.solve_block::<K>(r, K)),
            _ => self.solve_block::<0>(r, k),
        }
    }

    /// [`solve_rows`](Self::solve_rows) with rows of k columns: K = k, a width known at
    /// compile time, each row's K values in registers until the row is done, or K = 0 for
    /// more than [`PANEL`] columns, each row's columns in one run-time loop, as the dense
    /// solve does. The two do the same operations in the same order.
    fn solve_block<const K: usize>(&mut self, r: &mut [f64], k: usize) {
        let plan = &*self.plan;
        let x = &mut self.work[..plan.n * k];
        for (i, &from) in plan.order.iter().enumerate() {
            x[i * k..(i + 1) * k].copy_from_slice(&r[from * k..(from + 1) * k]);
        }
        let factors = (&plan.starts[..], &plan.diagonal[..], &plan.columns[..], &self.values[..]);
        match K {
            0 => substitute_in_place(factors, x, k),
            _ => substitute_in_registers::<K>(factors, x),
        }
        for (i, &to) in plan.order.iter().enumerate() {
            r[to * k..(to + 1) * k].copy_from_slice(&x[i * k..(i + 1) * k]);
        }
    }

    /// Overwrites r (length n) with E⁻ᵀ r: with the order P, P E Pᵀ = L U, so Eᵀ x = r is
    /// Uᵀ z = P r, Lᵀ w = z, x = Pᵀ w; U's and L's rows are scattered as the columns of Uᵀ
    /// and Lᵀ.
    pub fn solve_transposed(&mut self, r: &mut [f64]) {
        if let Some(dense) = self.dense.as_mut().filter(|_| self.use_dense) {
            return dense.solve_transposed(r);
        }
        let plan = &*self.plan;
        let n = plan.n;
        let x = &mut self.work[..n];
        for (i, &from) in plan.order.iter().enumerate() {
            x[i] = r[from];
        }
        let (starts, columns, values) = (&plan.starts, &plan.columns, &self.values);
        // Uᵀ z = P r: z_i is final once the rows before it are scattered; then row i of U
        // leaves it from the equations after it.
        for i in 0..n {
            let d = plan.diagonal[i];
            let zi = x[i] * values[d];
            x[i] = zi;
            if zi != 0.0 {
                for p in d + 1..starts[i + 1] {
                    x[columns[p]] -= values[p] * zi;
                }
            }
        }
        // Lᵀ w = z, unit diagonal, from the last row back: row i of L leaves w_i from the
        // equations before it.
        for i in (0..n).rev() {
            let wi = x[i];
            if wi != 0.0 {
                for p in starts[i]..plan.diagonal[i] {
                    x[columns[p]] -= values[p] * wi;
                }
            }
        }
        for (i, &to) in plan.order.iter().enumerate() {
            r[to] = x[i];
        }
    }
}

/// A row of the factors: where each row's entries start, where its diagonal is, and the
/// entries' columns and values ([`SparseLu`]'s fields).
type Rows<'a> = (&'a [usize], &'a [usize], &'a [usize], &'a [f64]);

/// L Y = X, then U X = Y, in place on n rows of K columns in x (in the factors' order), each
/// row's K values in registers until the row is done.
fn substitute_in_registers<const K: usize>(
    (starts, diagonal, columns, values): Rows<'_>,
    x: &mut [f64],
) {
    let row =
        |x: &[f64], i: usize| -> [f64; K] { x[i * K..(i + 1) * K].try_into().expect("K columns") };
    // L Y = X: row i less its multipliers times the rows before it.
    for (i, (&start, &d)) in starts.iter().zip(diagonal).enumerate() {
        let mut v = row(x, i);
        for (&j, &l) in columns[start..d].iter().zip(&values[start..d]) {
            if l != 0.0 {
                let solved = row(x, j);
                for c in 0..K {
                    v[c] -= l * solved[c];
                }
            }
        }
        x[i * K..(i + 1) * K].copy_from_slice(&v);
    }
    // U X = Y: row i less U's entries times the rows after it, over the pivot.
    for i in (0..diagonal.len()).rev() {
        let (d, end) = (diagonal[i], starts[i + 1]);
        let mut v = row(x, i);
        for (&j, &u) in columns[d + 1..end].iter().zip(&values[d + 1..end]) {
            if u != 0.0 {
                let solved = row(x, j);
                for c in 0..K {
                    v[c] -= u * solved[c];
                }
            }
        }
        let inverse_pivot = values[d];
        v.iter_mut().for_each(|v| *v *= inverse_pivot);
        x[i * K..(i + 1) * K].copy_from_slice(&v);
    }
}

/// [`substitute_in_registers`] for k columns known at run time, each row updated in memory.
fn substitute_in_place((starts, diagonal, columns, values): Rows<'_>, x: &mut [f64], k: usize) {
    for (i, (&start, &d)) in starts.iter().zip(diagonal).enumerate() {
        let (done, rest) = x.split_at_mut(i * k);
        let target = &mut rest[..k];
        for (&j, &l) in columns[start..d].iter().zip(&values[start..d]) {
            if l != 0.0 {
                eliminate::<0>(target, &done[j * k..(j + 1) * k], l);
            }
        }
    }
    for i in (0..diagonal.len()).rev() {
        let (head, done) = x.split_at_mut((i + 1) * k);
        let target = &mut head[i * k..(i + 1) * k];
        let (d, end) = (diagonal[i], starts[i + 1]);
        for (&j, &u) in columns[d + 1..end].iter().zip(&values[d + 1..end]) {
            if u != 0.0 {
                eliminate::<0>(target, &done[(j - i - 1) * k..(j - i) * k], u);
            }
        }
        let inverse_pivot = values[d];
        target.iter_mut().for_each(|v| *v *= inverse_pivot);
    }
}

/// The approximate minimum degree order of the pattern of E + Eᵀ (faer's AMD), as
/// `order[new] = old`; `entries` is E's pattern column by column, rows ascending.
fn minimum_degree(n: usize, entries: &[(usize, usize)]) -> Option<Vec<usize>> {
    let mut starts = vec![0usize; n + 1];
    for &(_, j) in entries {
        starts[j + 1] += 1;
    }
    for j in 0..n {
        starts[j + 1] += starts[j];
    }
    let rows: Vec<usize> = entries.iter().map(|e| e.0).collect();
    let structure = SymbolicSparseColMatRef::new_checked(n, n, &starts, None, &rows);
    let mut mem = MemBuffer::try_new(amd::order_scratch::<usize>(n, entries.len())).ok()?;
    let (mut order, mut inverse) = (vec![0usize; n], vec![0usize; n]);
    amd::order(&mut order, &mut inverse, structure, Default::default(), MemStack::new(&mut mem))
        .ok()?;
    Some(order)
}

/// The pattern of the LU factors without pivoting of a matrix with the pattern `entries`
/// (row, column; the diagonal among them): row by row, each row's columns ascending. Row i
/// gains the entries right of the diagonal of every row k < i that its own entries left of
/// the diagonal reach, taken in ascending k, as elimination produces them.
fn fill(n: usize, entries: impl Iterator<Item = (usize, usize)>) -> Vec<Vec<usize>> {
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (i, j) in entries {
        rows[i].push(j);
    }
    let mut marked = vec![usize::MAX; n];
    for i in 0..n {
        let mut row = std::mem::take(&mut rows[i]);
        for &j in &row {
            marked[j] = i;
        }
        // Ascending k below i: a min-heap of the columns left of the diagonal still to visit.
        let mut pending: std::collections::BinaryHeap<std::cmp::Reverse<usize>> =
            row.iter().copied().filter(|&j| j < i).map(std::cmp::Reverse).collect();
        while let Some(std::cmp::Reverse(k)) = pending.pop() {
            for &j in rows[k].iter().filter(|&&j| j > k) {
                if marked[j] != i {
                    marked[j] = i;
                    row.push(j);
                    if j < i {
                        pending.push(std::cmp::Reverse(j));
                    }
                }
            }
        }
        row.sort_unstable();
        rows[i] = row;
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_close_abs;

    /// A chain with a coupling back from the last state to the first (so elimination fills
    /// in) and an entry of the Jacobian outside the pattern, which is never read.
    fn chain(n: usize) -> (Vec<(u32, u32)>, Vec<f64>) {
        let mut pattern = Vec::new();
        let mut jac = vec![0.0; n * n];
        for i in 1..n {
            pattern.push((i as u32, (i - 1) as u32));
            jac[i * n + i - 1] = 1.0 + 0.1 * i as f64;
            pattern.push((i as u32, i as u32));
            jac[i * n + i] = -2.0 - (i % 3) as f64;
        }
        pattern.push((0, (n - 1) as u32));
        jac[n - 1] = 3.0;
        jac[5 * n + 30] = f64::NAN;
        (pattern, jac)
    }

    fn dense_of(n: usize, jac: &[f64], inv_gamma_h: f64) -> Lu {
        let mut dense = Lu::new(n, 3);
        dense
            .factor(|i, j| {
                let jij = if (i, j) == (5, 30) { 0.0 } else { jac[i * n + j] };
                (if i == j { inv_gamma_h } else { 0.0 }) - jij
            })
            .expect("regular");
        dense
    }

    fn agree(sparse: &mut SparseLu, dense: &mut Lu, n: usize) {
        let r: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let (mut a, mut b) = (r.clone(), r.clone());
        sparse.solve(&mut a);
        dense.solve(&mut b);
        for (x, y) in a.iter().zip(&b) {
            assert_close_abs(*x, *y, 1e-12);
        }
        // One right-hand side is the block's k = 1, to the bit.
        let mut c = r.clone();
        sparse.solve_rows(&mut c, 1);
        assert_eq!(a, c);
        let (mut a, mut b) = (r.clone(), r.clone());
        sparse.solve_transposed(&mut a);
        dense.solve_transposed(&mut b);
        for (x, y) in a.iter().zip(&b) {
            assert_close_abs(*x, *y, 1e-12);
        }
        let block: Vec<f64> = (0..n * 3).map(|i| (i as f64 * 0.11).cos()).collect();
        let (mut a, mut b) = (block.clone(), block.clone());
        sparse.solve_rows(&mut a, 3);
        dense.solve_rows(&mut b, 3);
        for (x, y) in a.iter().zip(&b) {
            assert_close_abs(*x, *y, 1e-12);
        }
    }

    /// The sparse solves agree with the dense LU's, for one right-hand side and for a block
    /// stored row by row, with E dominated by its diagonal (a short step), where the
    /// diagonal pivots hold.
    #[test]
    fn sparse_solves_agree_with_the_dense_lu() {
        let n = 40;
        let (pattern, jac) = chain(n);
        let mut sparse = SparseLu::new(n, &pattern, 3).expect("ordered");
        // The cycle fills in: more than E's 2n entries, far fewer than n².
        assert!(sparse.entries_of_factors() > 2 * n, "{}", sparse.entries_of_factors());
        assert!(sparse.entries_of_factors() < 4 * n, "{}", sparse.entries_of_factors());
        sparse.factor(10.0, &placed(&sparse, &jac)).expect("regular");
        assert!(!sparse.fell_back());
        agree(&mut sparse, &mut dense_of(n, &jac, 10.0), n);
    }

    /// The dense J's values in the plan's places, as the factors read J.
    fn placed(lu: &SparseLu, jac: &[f64]) -> Vec<f64> {
        lu.plan().entries.iter().map(|&(_, at, _)| jac[at]).collect()
    }

    /// Every entry of the pattern has its place, and J spread from its places is J, but
    /// for the entry outside the pattern, which has none; and the fallback to dense
    /// factors solves with the J spread (1/(γh) = 1e-3: the first pivot is 1e-3, J₀₀
    /// being 0, and row 1's multiplier 1.1e3 is refused).
    #[test]
    fn the_places_hold_the_pattern() {
        let n = 40;
        let (pattern, jac) = chain(n);
        let mut lu = SparseLu::new(n, &pattern, 3).expect("ordered");
        let mut values = vec![0.0; lu.plan().entries()];
        for &(i, j) in &pattern {
            let (i, j) = (i as usize, j as usize);
            values[lu.plan().place(i, j).expect("in the pattern")] = jac[i * n + j];
        }
        assert_eq!(values, placed(&lu, &jac));
        assert_eq!(lu.plan().place(5, 30), None);
        let spread = lu.plan().spread(&values);
        for (at, (&a, &b)) in spread.iter().zip(&jac).enumerate() {
            let outside = at == 5 * n + 30;
            assert_eq!(a.to_bits(), if outside { 0.0 } else { b }.to_bits(), "entry {at}");
        }
        lu.factor(1e-3, &values).expect("regular");
        assert!(lu.fell_back());
        agree(&mut lu, &mut dense_of(n, &jac, 1e-3), n);
    }

    /// A system's plan is found once: every later call of its cell hands out the same one,
    /// and factors along it solve as factors along a plan of their own do, to the bit (two
    /// integrations of one system, each with factors of its own, on one plan).
    #[test]
    fn a_plan_is_found_once_and_shared() {
        let n = 40;
        let (pattern, jac) = chain(n);
        let cell = PlanCell::default();
        let first = cell.get_or_find(n, &pattern).expect("ordered");
        let again = cell.get_or_find(n, &pattern).expect("ordered");
        assert!(std::sync::Arc::ptr_eq(&first, &again));
        let (mut one, mut other) = (SparseLu::with_plan(first, 3), SparseLu::with_plan(again, 3));
        let mut own = SparseLu::new(n, &pattern, 3).expect("ordered");
        for (lu, h) in [(&mut one, 10.0), (&mut other, 20.0), (&mut own, 10.0)] {
            lu.factor(h, &placed(lu, &jac)).expect("regular");
        }
        let r: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let solved = |lu: &mut SparseLu| {
            let mut x = r.clone();
            lu.solve(&mut x);
            x
        };
        assert_eq!(solved(&mut one), solved(&mut own));
        // The other integration's factors are its own, at its own step.
        assert_ne!(solved(&mut other), solved(&mut own));
        agree(&mut other, &mut dense_of(n, &jac, 20.0), n);
    }

    /// A block of any width, known at compile time (up to 32 columns) or wider in a
    /// run-time loop, gives each column what the single solve gives it, to the last bit.
    #[test]
    fn sparse_block_solves_of_every_width_are_the_column_solves() {
        let n = 40;
        let (pattern, jac) = chain(n);
        for k in [1, 2, 7, 16, 17, 32, 33, 70] {
            let mut sparse = SparseLu::new(n, &pattern, k).expect("ordered");
            sparse.factor(10.0, &placed(&sparse, &jac)).expect("regular");
            assert!(!sparse.fell_back());
            let b = |i: usize, j: usize| (i as f64 * 0.7 - j as f64 * 1.3).cos();
            let mut rows: Vec<f64> = (0..n).flat_map(|i| (0..k).map(move |j| b(i, j))).collect();
            sparse.solve_rows(&mut rows, k);
            for j in 0..k {
                let mut column: Vec<f64> = (0..n).map(|i| b(i, j)).collect();
                sparse.solve(&mut column);
                for i in 0..n {
                    assert_eq!(rows[i * k + j].to_bits(), column[i].to_bits(), "k = {k}");
                }
            }
        }
    }

    /// Where a diagonal pivot is 0, or its multiplier beyond 10³, the step's matrix is
    /// factorised dense with partial pivoting, and the solves are still E's.
    #[test]
    fn refused_pivots_fall_back_to_the_dense_lu() {
        let n = 2;
        let pattern = [(0, 1), (1, 0)];
        for (diagonal, falls_back) in [(0.0, true), (1e-6, true), (1e-2, false)] {
            // E = [[d, 1], [1, d]]: J = −E off the diagonal, and d on it with 1/(γh) = 2d.
            let jac = [-diagonal, -1.0, -1.0, -diagonal];
            let mut sparse = SparseLu::new(n, &pattern, 3).expect("ordered");
            sparse.factor(0.0, &placed(&sparse, &jac)).expect("regular");
            assert_eq!(sparse.fell_back(), falls_back, "d = {diagonal}");
            let mut dense = Lu::new(n, 3);
            dense.factor(|i, j| -jac[i * n + j]).expect("regular");
            agree(&mut sparse, &mut dense, n);
        }
    }

    /// After a refusal the next factorisations go dense untried, 1, then 2 after a second
    /// refusal in a row; a success starts again from 1. Every one solves as the dense LU.
    #[test]
    fn refusals_skip_the_diagonal_pivots_for_a_while() {
        let n = 2;
        let pattern = [(0, 1), (1, 0)];
        let mut sparse = SparseLu::new(n, &pattern, 3).expect("ordered");
        // d = 0 is refused, d = 1e-2 accepted when tried.
        let steps = [
            (0.0, true),
            (1e-2, true),
            (0.0, true),
            (1e-2, true),
            (1e-2, true),
            (1e-2, false),
            (0.0, true),
            (1e-2, true),
            (1e-2, false),
        ];
        for (step, (diagonal, falls_back)) in steps.into_iter().enumerate() {
            let jac = [-diagonal, -1.0, -1.0, -diagonal];
            sparse.factor(0.0, &placed(&sparse, &jac)).expect("regular");
            assert_eq!(sparse.fell_back(), falls_back, "step {step}");
            let mut dense = Lu::new(n, 3);
            dense.factor(|i, j| -jac[i * n + j]).expect("regular");
            agree(&mut sparse, &mut dense, n);
        }
    }

    /// A non-finite entry of the pattern is refused as a singular matrix, as the dense LU
    /// refuses it.
    #[test]
    fn a_non_finite_entry_is_singular() {
        let n = 40;
        let (pattern, mut jac) = chain(n);
        let mut sparse = SparseLu::new(n, &pattern, 3).expect("ordered");
        jac[n - 1] = f64::INFINITY;
        assert_eq!(sparse.factor(1.0, &placed(&sparse, &jac)), Err(FactorError::Singular));
    }

    /// The fill of an arrow matrix: eliminating the hub first fills everything, last fills
    /// nothing; the pattern computed for the natural order is the dense one, and the
    /// minimum degree order puts the hub last.
    #[test]
    fn the_fill_of_an_arrow_depends_on_the_order() {
        let n = 6;
        let arrow: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| [(i, i), (0, i), (i, 0)])
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let rows = fill(n, arrow.iter().copied());
        assert!(rows.iter().all(|r| r.len() == n), "{rows:?}");
        let mut by_column = arrow.clone();
        by_column.sort_unstable_by_key(|&(i, j)| (j, i));
        let order = minimum_degree(n, &by_column).expect("ordered");
        assert_eq!(order[n - 1], 0, "{order:?}");
    }
}
