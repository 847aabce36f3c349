//! The linear algebra of implicit steps for a [`System`]: the exact Jacobian ∂g/∂y from the
//! system's sparse Jacobian (else by dual numbers, or the system's analytic one), E =
//! I/(γh) − ∂g/∂y factorised by LU (dense, or sparse where its factors fill little), and, for
//! the variational equations, the second-derivative coupling that makes the augmented system's
//! iteration matrix block lower triangular with E on the diagonal.

use std::sync::Arc;

use nalgebra::DMatrix;
use num_dual::HyperDual64;

use crate::counts::dense_lu;
use crate::jacobian::{JacobianProducts, ProductPlan};
use crate::lu::{FactorError, Lu};
use crate::sparse::SparseJacobian;
use crate::sparse_lu::{Plan, PlanCell, SparseLu};
use crate::system::{Function, System};
use crate::wrt::{Wrt, parameter_seeds};

/// E = I/(γh) − ∂g/∂y at one point, factorised, for a system at fixed parameters.
pub struct IterationMatrix {
    n: usize,
    lu: Factors,
    /// ∂g/∂y: row by row, or, for sparse factors, its entries in their places
    /// ([`Factors::places`]): never n² values where the factors are sparse.
    jac: Vec<f64>,
    /// Where each entry of a state column of the system's sparse Jacobian goes in `jac`
    /// (its index in the Jacobian's work space, the place), where it has one.
    places: Vec<(usize, usize)>,
    /// Dual numbers seeded with the identity: the Jacobian in one evaluation per chunk.
    products: JacobianProducts,
    identity: Vec<f64>,
    value: Vec<f64>,
    /// For systems with hand-written Jacobians.
    analytic: Option<(DMatrix<f64>, DMatrix<f64>)>,
    /// The work space of the system's sparse Jacobian, where it has one.
    entries: Vec<f64>,
}

impl IterationMatrix {
    /// For `sys` at parameters `p`; solves with up to `columns` right-hand sides at once.
    pub fn new<S: System>(sys: &S, p: &[f64], columns: usize) -> Self {
        let sig = sys.signature();
        let (n, np) = (sig.n_states(), sig.n_parameters());
        let analytic = sys.analytic_jacobians();
        let sparse = sys.sparse_jacobian(Function::Rhs).filter(|_| !analytic);
        let lu = Factors::of(n, sparse, columns);
        // The system's sparse Jacobian gives J's entries for either factors; products with
        // the identity (n dual directions) give it where the system has none.
        let entries = sparse.map(|j| j.for_state_columns().workspace()).unwrap_or_default();
        let places = match sparse.map(|j| j.for_state_columns()) {
            Some(jacobian) => lu.places(
                (jacobian.pattern().iter().zip(jacobian.entries()))
                    .map(|(&(i, c), &at)| (i as usize, c as usize, at as usize))
                    .filter(|&(_, c, _)| c < n),
            ),
            None => Vec::new(),
        };
        let directions = if analytic || sparse.is_some() { 0 } else { n };
        let mut identity = vec![0.0; n * directions];
        for i in 0..directions {
            identity[i * n + i] = 1.0;
        }
        Self {
            n,
            jac: vec![0.0; lu.placed_len()],
            lu,
            places,
            products: JacobianProducts::new(n, p, &vec![0.0; np * n], n, directions),
            identity,
            value: vec![0.0; n],
            analytic: analytic.then(|| (DMatrix::zeros(n, n), DMatrix::zeros(n, np))),
            entries,
        }
    }

    /// New parameter values.
    pub fn set_parameters(&mut self, p: &[f64]) {
        let zeros = vec![0.0; p.len() * self.n];
        self.products.set_parameters(p, &zeros);
    }

    /// Evaluates ∂g/∂y at (t, y, u) with parameters `p` and factorises E = I·`inv_gamma_h` − ∂g/∂y.
    pub fn factor<S: System>(
        &mut self,
        sys: &S,
        (t, y, p, u): (f64, &[f64], &[f64], &[f64]),
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        let n = self.n;
        match &mut self.analytic {
            // J's entries where the system's sparse Jacobian gives them (by the program of
            // its state columns, where it has one); the others stay 0.
            None if let Some(jacobian) = sys.sparse_jacobian(Function::Rhs) => {
                jacobian.for_state_columns().eval(t, y, p, u, &mut self.entries);
                for &(at, place) in &self.places {
                    self.jac[place] = self.entries[at];
                }
            }
            Some((jy, jp)) => {
                sys.jacobians(t, y, p, u, jy, jp);
                for i in 0..n {
                    for j in 0..n {
                        self.jac[i * n + j] = jy[(i, j)];
                    }
                }
            }
            None => {
                let args = (t, y, u);
                self.products.eval(
                    sys,
                    Function::Rhs,
                    args,
                    &self.identity,
                    &mut self.value,
                    &mut self.jac,
                );
            }
        }
        self.lu.factor(inv_gamma_h, &self.jac)
    }

    /// The Jacobian ∂g/∂y of the last factorisation, row by row.
    pub fn jacobian(&self) -> Vec<f64> {
        self.lu.dense(&self.jac)
    }

    /// Overwrites r with E⁻¹ r.
    pub fn solve(&mut self, r: &mut [f64]) {
        self.lu.solve(r);
    }

    /// Overwrites the n × k matrix R (row by row) with E⁻¹ R.
    pub fn solve_rows(&mut self, r: &mut [f64], k: usize) {
        self.lu.solve_rows(r, k);
    }

    /// Whether E is factorised sparse.
    pub fn is_sparse(&self) -> bool {
        self.lu.is_sparse()
    }

    /// Estimated operations of one [`factor`](Self::factor) (the Jacobian's evaluation
    /// included) and of one solve with one right-hand side, for a system of structure `s`.
    pub(crate) fn costs(&self, s: &Structure) -> (u64, u64) {
        let jacobian = match (&self.analytic, &self.lu) {
            (None, Factors::Dense(_)) => s.dense_jacobian(),
            _ => s.states,
        };
        let (factor, solve) = self.lu.costs();
        (jacobian + factor, solve)
    }
}

/// The structure of a system's functions that sets what its evaluations cost
/// ([`Costs`](crate::Costs)): from its sparse Jacobian where it has one (its program's
/// operations, the entries of its pattern), else as if its Jacobian were dense.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Structure {
    /// States.
    pub(crate) n: u64,
    /// One evaluation of f with the Jacobian's entries.
    pub(crate) linearized: u64,
    /// One evaluation of f alone, and of f with ∂f/∂y's entries (by the programs of their
    /// own where the system has them, else `linearized`).
    pub(crate) values: u64,
    pub(crate) states: u64,
    /// Entries of ∂f/∂y and of ∂f/∂α.
    pub(crate) state_entries: u64,
    pub(crate) parameter_entries: u64,
    /// The second derivatives' program and entries, where the system has them.
    pub(crate) curvature: Option<(u64, u64)>,
    /// Whether the system gives its sparse Jacobian (else its entries come from products
    /// with the identity).
    pub(crate) sparse: bool,
}

impl Structure {
    /// The Jacobian as a dense matrix: f's program with the Jacobian's entries, put in place
    /// (n² entries read by the factorisation), or, without a sparse Jacobian, f's program
    /// and its products with the n unit directions.
    pub(crate) fn dense_jacobian(&self) -> u64 {
        match self.sparse {
            true => self.states + self.n * self.n,
            false => self.linearized + self.state_entries * self.n + self.n * self.n,
        }
    }

    /// An implicit step's factorisation and solve before its matrix exists: the Jacobian
    /// made dense, dense LU.
    pub(crate) fn dense_implicit(&self) -> (u64, u64) {
        let (factor, solve) = dense_lu(self.n);
        (self.dense_jacobian() + factor, solve)
    }

    pub(crate) fn of<S: System>(sys: &S) -> Self {
        let sig = sys.signature();
        let (n, np) = (sig.n_states() as u64, sig.n_parameters() as u64);
        match sys.sparse_jacobian(Function::Rhs) {
            Some(jacobian) => {
                let states = jacobian.pattern().iter().filter(|e| u64::from(e.1) < n).count();
                let states = states as u64;
                Self {
                    n,
                    linearized: jacobian.operations() as u64,
                    values: jacobian.for_values().operations() as u64,
                    states: jacobian.for_state_columns().operations() as u64,
                    state_entries: states,
                    parameter_entries: jacobian.pattern().len() as u64 - states,
                    curvature: jacobian
                        .curvature()
                        .map(|c| (c.operations() as u64, c.pattern().len() as u64)),
                    sparse: true,
                }
            }
            None => {
                let linearized = 4 * n * (1 + n + np);
                Self {
                    n,
                    linearized,
                    values: linearized,
                    states: linearized,
                    state_entries: n * n,
                    parameter_entries: n * np,
                    curvature: None,
                    sparse: false,
                }
            }
        }
    }
}

/// J's entries (row, column), and where the system keeps the sparse LU's plan of them.
struct Pattern<'a> {
    entries: &'a [(u32, u32)],
    cell: Option<&'a PlanCell>,
}

/// The factors of E = I·c − J (n × n): dense, or sparse for a system with a sparse
/// Jacobian whose factors fill little of n² ([`SPARSE_SHARE`]).
pub(crate) enum Factors {
    Dense(Lu),
    Sparse(Box<SparseLu>),
}

impl Factors {
    /// For n states, J's nonzero entries (row, column) in `pattern` where they are known
    /// (columns from n on, the parameters', are left out), solving up to `columns`
    /// right-hand sides at once: sparse where the factors keep at most [`SPARSE_SHARE`] of
    /// n² entries, else dense.
    pub(crate) fn new(n: usize, pattern: Option<&[(u32, u32)]>, columns: usize) -> Self {
        Self::planned(n, pattern.map(|p| Pattern { entries: p, cell: None }), columns)
    }

    /// The factors of a system's sparse Jacobian `jacobian`: [`new`](Self::new) with its
    /// pattern, the order and fill found once for the system where it keeps them
    /// ([`SparseJacobian::lu_plan`]).
    pub(crate) fn of(n: usize, jacobian: Option<&dyn SparseJacobian>, columns: usize) -> Self {
        let pattern = jacobian.map(|j| Pattern { entries: j.pattern(), cell: j.lu_plan() });
        Self::planned(n, pattern, columns)
    }

    fn planned(n: usize, pattern: Option<Pattern<'_>>, columns: usize) -> Self {
        let dense = n * n / SPARSE_SHARE;
        // The factors hold at least J's own entries: too many of those, and the order and
        // fill are not worth finding.
        let few =
            |p: &Pattern<'_>| p.entries.iter().filter(|e| (e.1 as usize) < n).count() <= dense;
        let plan = |p: Pattern<'_>| match p.cell {
            Some(cell) => cell.get_or_find(n, p.entries),
            None => Plan::new(n, p.entries).map(Arc::new),
        };
        match pattern.filter(few).and_then(plan) {
            Some(plan) if plan.entries_of_factors() <= dense => {
                Self::Sparse(Box::new(SparseLu::with_plan(plan, columns)))
            }
            _ => Self::Dense(Lu::new(n, columns)),
        }
    }

    /// Factorises E = I·`inv_gamma_h` − J, J row by row for dense factors and its entries
    /// in their places for sparse ones ([`places`](Self::places)).
    pub(crate) fn factor(&mut self, inv_gamma_h: f64, jac: &[f64]) -> Result<(), FactorError> {
        match self {
            Self::Dense(lu) => {
                let n = lu.dim();
                lu.factor(|i, j| if i == j { inv_gamma_h } else { 0.0 } - jac[i * n + j])
            }
            Self::Sparse(lu) => lu.factor(inv_gamma_h, jac),
        }
    }

    /// Where J's entries (i, j, k) go in the J that [`factor`](Self::factor) reads, as
    /// (k, place): i·n + j for dense factors, the entry's place in the plan for sparse ones
    /// (an entry outside the plan's pattern, which the factors would not read, is left out).
    pub(crate) fn places(
        &self,
        entries: impl Iterator<Item = (usize, usize, usize)>,
    ) -> Vec<(usize, usize)> {
        match self {
            Self::Dense(lu) => entries.map(|(i, j, k)| (k, i * lu.dim() + j)).collect(),
            Self::Sparse(lu) => {
                entries.filter_map(|(i, j, k)| Some((k, lu.plan().place(i, j)?))).collect()
            }
        }
    }

    /// The length of the J that [`factor`](Self::factor) reads: n² for dense factors, the
    /// plan's entries for sparse ones.
    pub(crate) fn placed_len(&self) -> usize {
        match self {
            Self::Dense(lu) => lu.dim() * lu.dim(),
            Self::Sparse(lu) => lu.plan().entries(),
        }
    }

    /// J row by row from what [`factor`](Self::factor) reads.
    pub(crate) fn dense(&self, jac: &[f64]) -> Vec<f64> {
        match self {
            Self::Dense(_) => jac.to_vec(),
            Self::Sparse(lu) => lu.plan().spread(jac),
        }
    }

    /// Overwrites r with E⁻¹ r.
    pub(crate) fn solve(&mut self, r: &mut [f64]) {
        match self {
            Self::Dense(lu) => lu.solve(r),
            Self::Sparse(lu) => lu.solve(r),
        }
    }

    /// Overwrites r with E⁻ᵀ r.
    pub(crate) fn solve_transposed(&mut self, r: &mut [f64]) {
        match self {
            Self::Dense(lu) => lu.solve_transposed(r),
            Self::Sparse(lu) => lu.solve_transposed(r),
        }
    }

    /// Overwrites the n × k matrix R (row by row) with E⁻¹ R.
    pub(crate) fn solve_rows(&mut self, r: &mut [f64], k: usize) {
        match self {
            Self::Dense(lu) => lu.solve_rows(r, k),
            Self::Sparse(lu) => lu.solve_rows(r, k),
        }
    }

    /// Whether the factors are sparse.
    pub(crate) fn is_sparse(&self) -> bool {
        matches!(self, Self::Sparse(_))
    }

    /// Estimated operations of one factorisation and of one solve with one right-hand side:
    /// dense, 2n³/3 and 2n²; sparse, with F entries in the factors, F²/n (each of the n
    /// eliminations updating about (F/n)² entries) and 2F; a sparse LU that has fallen back
    /// to dense factors costs what those do.
    pub(crate) fn costs(&self) -> (u64, u64) {
        let n = match self {
            Self::Sparse(lu) if !lu.fell_back() => {
                let (f, n) = (lu.entries_of_factors() as u64, (lu.dim() as u64).max(1));
                return (f * f / n, 2 * f);
            }
            Self::Sparse(lu) => lu.dim(),
            Self::Dense(lu) => lu.dim(),
        };
        dense_lu(n as u64)
    }
}

/// E is factorised sparse ([`SparseLu`]) where the system gives its sparse Jacobian and the
/// factors, in their fill-reducing order, keep at most 1/`SPARSE_SHARE` of E's n² entries.
///
/// The sparse factors cost an indexed multiply-add per entry, the dense ones a contiguous,
/// vectorised one per entry of n²: the share is where the two meet. Measured on the PEtab
/// collection (`scripts/petab/binaries_beside.py`, NLL + gradient at nominal, one thread,
/// 2026-12-05; docs/petab.md, "Sparse factors by their fill"): sparse is faster with the
/// factors at 15–21 % of n² (Lucarelli 1.25×, Isensee 1.23×, Alkan 1.14×, Raimundez 1.06×,
/// Raia 1.05×, Laske 1.04×; Bachmann 0.98×); at a third, Elowitz (31 %) was 0.96× and Schwen
/// (32 %) 1.05×; Zheng (37 %) and SalazarCavazos (45 %) were 0.86× and 0.88× sparse. Smith
/// (11 % of n²; 1.3–1.4 s against 1.9–2.2 s dense), Lang (13 %) and Chen (3 %; a third of
/// the dense time) were sparse before, from 100 states. Lang refuses the diagonal pivots at
/// 98 % of its steps, which then factorise dense.
pub const SPARSE_SHARE: usize = 4;

/// The implicit solve of the state together with its sensitivities x = [y; S].
///
/// The augmented Jacobian is block lower triangular: ∂(J s_j + ∂g/∂α_j)/∂s_j = J and
/// ∂(J s_j + ∂g/∂α_j)/∂y = M_j, the second derivative of g in the direction s_j (and α_j for
/// a parameter column). So E_aug k = r is solved by one back-substitution with E for k_y, and
/// one for every column, (I/(γh) − J) k_sj = r_sj + M_j k_y, M_j k_y from one hyper-dual
/// evaluation of g (ε₁ along s_j and α_j, ε₂ along k_y). A system whose sparse Jacobian has
/// a [curvature](SparseJacobian::curvature) gives M_j k_y from its second derivatives
/// instead, evaluated once per factorisation: (M_j k_y)_i = Σ_e (Σ_l ∂J_e/∂y_l k_y,l) v_j,c(e)
/// over the entries e = (i, c) of J, with v_j the column's direction (s_j, and the unit seed
/// of its parameter).
pub(crate) struct AugmentedMatrix {
    matrix: IterationMatrix,
    /// The second derivatives at the factorisation's point, for systems that have them.
    curvature: Option<Curvature>,
    /// The point of the factorisation: t, u, y, S.
    t: f64,
    u: Vec<f64>,
    x: Vec<f64>,
    p: Vec<f64>,
    yd: Vec<HyperDual64>,
    pd: Vec<HyperDual64>,
    gd: Vec<HyperDual64>,
}

impl AugmentedMatrix {
    /// For `sys` at parameters `p`, with the sensitivity columns `wrt`.
    pub(crate) fn new<S: System>(sys: &S, p: &[f64], wrt: &[Wrt]) -> Self {
        let sig = sys.signature();
        let (n, k) = (sig.n_states(), wrt.len());
        let zero = HyperDual64::from_re(0.0);
        let curvature = sys.sparse_jacobian(Function::Rhs).and_then(|jacobian| {
            let second = jacobian.curvature()?;
            let pattern = jacobian.pattern();
            let seeds = parameter_seeds(p.len(), wrt);
            Some(Curvature {
                work: second.workspace(),
                along: vec![0.0; pattern.len()],
                plan: ProductPlan::new(pattern, 0..pattern.len() as u32, (n, n), &seeds, k),
            })
        });
        Self {
            matrix: IterationMatrix::new(sys, p, k),
            curvature,
            t: 0.0,
            u: vec![0.0; sig.n_inputs()],
            x: vec![0.0; n * (1 + k)],
            p: p.to_vec(),
            yd: vec![zero; n],
            pd: vec![zero; p.len()],
            gd: vec![zero; n],
        }
    }

    /// Factorises E at (t, x = [y; S]) with inputs `u`.
    pub(crate) fn factor<S: System>(
        &mut self,
        sys: &S,
        (t, x, u): (f64, &[f64], &[f64]),
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        self.t = t;
        self.u.copy_from_slice(u);
        self.x.copy_from_slice(x);
        let n = self.yd.len();
        // Second derivatives only couple sensitivities: none without them.
        if let Some(curvature) = &mut self.curvature
            && x.len() > n
            && let Some(second) = sys.sparse_jacobian(Function::Rhs).and_then(|j| j.curvature())
        {
            second.eval(t, &x[..n], &self.p, u, &mut curvature.work);
        }
        self.matrix.factor(sys, (t, &x[..n], &self.p, u), inv_gamma_h)
    }

    /// Estimated operations of one factorisation and one solve of the augmented system
    /// with k columns, for a system of structure `s`: one back-substitution with E per
    /// column and the state, and the coupling M_j k_y, from the second derivatives (their
    /// program at the factorisation, their entries and the products at each solve) or from
    /// a hyper-dual evaluation of f per column.
    pub(crate) fn costs(&self, s: &Structure, k: u64) -> (u64, u64) {
        let (factor, solve) = self.matrix.costs(s);
        let products = s.state_entries * k + s.parameter_entries;
        match (k, s.curvature) {
            (0, _) => (factor, solve),
            (_, Some((operations, entries))) => {
                (factor + operations, (1 + k) * solve + entries + products)
            }
            (_, None) => (factor, (1 + k) * solve + k * 4 * s.linearized),
        }
    }

    /// Overwrites r = [r_y; r_S] with E_aug⁻¹ r.
    pub(crate) fn solve<S: System>(&mut self, sys: &S, wrt: &[Wrt], r: &mut [f64]) {
        let n = self.yd.len();
        let k = wrt.len();
        let (ry, rs) = r.split_at_mut(n);
        self.matrix.solve(ry);
        if k == 0 {
            return;
        }
        let (y, s) = self.x.split_at(n);
        if let Some(curvature) = &mut self.curvature
            && let Some(second) = sys.sparse_jacobian(Function::Rhs).and_then(|j| j.curvature())
        {
            curvature.couple(second, (s, ry), rs);
            self.matrix.solve_rows(rs, k);
            return;
        }
        for (j, w) in wrt.iter().enumerate() {
            for i in 0..n {
                self.yd[i] = HyperDual64::new(y[i], s[i * k + j], ry[i], 0.0);
            }
            for (q, pq) in self.p.iter().enumerate() {
                let seed = if *w == Wrt::Parameter(q) { 1.0 } else { 0.0 };
                self.pd[q] = HyperDual64::new(*pq, seed, 0.0, 0.0);
            }
            sys.rhs(self.t, &self.yd, &self.pd, &self.u, &mut self.gd);
            for i in 0..n {
                rs[i * k + j] += self.gd[i].eps1eps2;
            }
        }
        self.matrix.solve_rows(rs, k);
    }
}

/// The second derivatives of a sparse Jacobian at the factorisation's point.
struct Curvature {
    work: Vec<f64>,
    /// Per entry e of J: Σ_l ∂J_e/∂y_l k_y,l.
    along: Vec<f64>,
    /// The products Σ_e along_e v_j,c(e) over J's pattern, for the columns' directions.
    plan: ProductPlan,
}

impl Curvature {
    /// rs += (M_j k_y)_j for every column j, with S (row by row) and k_y.
    ///
    /// The second derivatives come grouped by the entry of J they belong to (the pattern is
    /// sorted so): each group is summed in a register and stored once, where adding every
    /// term into `along` would chain each addition to the store before it (SalazarCavazos' 75
    /// states: 5 988 second derivatives over 2 421 entries of J, up to 49 to an entry; this
    /// loop took 30 % of its NLL + gradient).
    fn couple(&mut self, second: &dyn SparseJacobian, (s, ky): (&[f64], &[f64]), rs: &mut [f64]) {
        self.along.fill(0.0);
        let (pattern, entries) = (second.pattern(), second.entries());
        let mut i = 0;
        while i < pattern.len() {
            let e = pattern[i].0;
            let mut sum = 0.0;
            while i < pattern.len() && pattern[i].0 == e {
                sum += self.work[entries[i] as usize] * ky[pattern[i].1 as usize];
                i += 1;
            }
            self.along[e as usize] += sum;
        }
        self.plan.apply::<true>(&self.along, s, rs);
    }
}
