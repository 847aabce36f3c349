//! Jacobian–matrix products by forward-mode dual numbers: g(t, y, α, u) and
//! J_y V_y + J_α V_α for a batch of K directions, W directions per model evaluation.
//!
//! This is how sysid differentiates models: the right-hand side (or the outputs) is
//! evaluated with vector dual numbers whose derivative parts are the directions, so the
//! Jacobian is never formed and nothing is allocated per call. The sensitivity equations
//! use the columns of S as directions; quasilinearization uses the columns of Φ and the
//! displacement from the previous trajectory.
//!
//! A system that supplies its own sparse Jacobian ([`System::sparse_jacobian`], model
//! files) is evaluated once per call instead, and the products are summed over the nonzero
//! entries: one multiply-add per entry and direction.

use nalgebra::{Const, SVector, U1};
use num_dual::{Derivative, DualSVec64};

use crate::lu::{PANEL, by_width, panels};
use crate::sparse::SparseJacobian;
use crate::system::{Function, System};

/// Preallocated work space for g and J·V with K directions.
///
/// Directions are given row by row: `vy` is n × K (row i: the K directions' components for
/// state i) and `vp` is n_α × K; the products come back row by row in the same way. The
/// parameters and their directions are set once ([`set_parameters`](Self::set_parameters))
/// and reused by every evaluation: they are constant during an integration.
pub struct JacobianProducts {
    duals: Duals,
    /// The parameter values, for evaluations without directions.
    p: Vec<f64>,
    /// The parameter directions n_α × K, row by row, for systems with a sparse Jacobian.
    vp: Vec<f64>,
    /// Number of directions K.
    k: usize,
    /// Work space of the sparse Jacobian, allocated on its first use.
    sparse: Option<SparseWork>,
}

/// A sparse Jacobian's work space and the plan of its products with the directions.
struct SparseWork {
    /// The function the work space is for.
    function: Function,
    work: Vec<f64>,
    /// The registers of the function values.
    values: Vec<u32>,
    /// The plan for the current parameter directions; `None` until the next evaluation
    /// after they change.
    plan: Option<ProductPlan>,
}

/// The plan of sparse Jacobian–matrix products J_y V_y + J_α V_α with K directions, the
/// entries of J read from a slice of values by index: the pattern's rows in order, each
/// with its state entries (index, offset c·K of column c in V_y) and, per parameter entry,
/// the nonzero components of its direction (index, direction, component).
///
/// The sensitivity right-hand side reads J's entries from the registers of its work space;
/// the implicit solve's coupling reads its per-entry values in pattern order.
pub(crate) struct ProductPlan {
    k: usize,
    /// Per row: the end of its terms in `states` and in `parameters`.
    rows: Vec<(u32, u32)>,
    states: Vec<(u32, u32)>,
    parameters: Vec<(u32, u32, f64)>,
}

impl ProductPlan {
    /// The plan for `m` rows of the pattern (row-ordered) whose e-th entry is read at
    /// index `index[e]`, n states, parameter directions `vp` (n_α × K, row by row).
    pub(crate) fn new(
        pattern: &[(u32, u32)],
        index: impl IntoIterator<Item = u32>,
        (m, n): (usize, usize),
        vp: &[f64],
        k: usize,
    ) -> Self {
        let mut plan = Self { k, rows: Vec::new(), states: Vec::new(), parameters: Vec::new() };
        let mut entries = pattern.iter().zip(index).peekable();
        for row in 0..m as u32 {
            while let Some((&(_, column), register)) = entries.next_if(|e| e.0.0 == row) {
                let column = column as usize;
                if column < n {
                    plan.states.push((register, (column * k) as u32));
                    continue;
                }
                let q = column - n;
                for (j, &v) in vp[q * k..(q + 1) * k].iter().enumerate() {
                    if v != 0.0 {
                        plan.parameters.push((register, j as u32, v));
                    }
                }
            }
            plan.rows.push((plan.states.len() as u32, plan.parameters.len() as u32));
        }
        plan
    }

    /// out = J_y vy + J_α vp (K columns, row by row), J's entries read from `entries`; with
    /// `ADD`, out += instead.
    pub(crate) fn apply<const ADD: bool>(&self, entries: &[f64], vy: &[f64], out: &mut [f64]) {
        let k = self.k;
        if k == 0 {
            return;
        }
        if k <= PANEL {
            return by_width!(k, K => self.accumulate::<K, ADD>(entries, vy, out));
        }
        // Wider: the states' terms panel by panel ([`panels`]), each panel's sums in
        // registers, then the parameters' terms. Every entry of `out` receives the same
        // terms in the same order as in one pass.
        for (first, width) in panels(k) {
            by_width!(width, W => self.accumulate_states::<W, ADD>(first, entries, vy, out));
        }
        let mut q = 0;
        for (row, &(_, q_end)) in out.chunks_exact_mut(k).zip(&self.rows) {
            for &(r, j, v) in &self.parameters[q..q_end as usize] {
                row[j as usize] += entries[r as usize] * v;
            }
            q = q_end as usize;
        }
    }

    /// The products row by row for K directions known at compile time: each row's K sums
    /// stay in registers until they are stored.
    #[inline(always)]
    fn accumulate<const K: usize, const ADD: bool>(
        &self,
        entries: &[f64],
        vy: &[f64],
        out: &mut [f64],
    ) {
        let (mut s, mut q) = (0, 0);
        for (row, &(s_end, q_end)) in out.chunks_exact_mut(K).zip(&self.rows) {
            let mut sums = [0.0; K];
            if ADD {
                sums.copy_from_slice(row);
            }
            for &(r, column) in &self.states[s..s_end as usize] {
                let a = entries[r as usize];
                let column = column as usize;
                let direction: &[f64; K] = vy[column..column + K].try_into().expect("K values");
                for j in 0..K {
                    sums[j] += a * direction[j];
                }
            }
            // The parameters' terms after the store: indexing the sums by a run-time
            // column would keep them in memory instead of registers.
            row.copy_from_slice(&sums);
            for &(r, j, v) in &self.parameters[q..q_end as usize] {
                row[j as usize] += entries[r as usize] * v;
            }
            (s, q) = (s_end as usize, q_end as usize);
        }
    }

    /// The states' terms J_y vy of columns `first..first + W` of the plan's k, row by row,
    /// the panel's W sums in registers until they are stored.
    #[inline(always)]
    fn accumulate_states<const W: usize, const ADD: bool>(
        &self,
        first: usize,
        entries: &[f64],
        vy: &[f64],
        out: &mut [f64],
    ) {
        let mut s = 0;
        for (row, &(s_end, _)) in out.chunks_exact_mut(self.k).zip(&self.rows) {
            let block: &mut [f64; W] =
                (&mut row[first..first + W]).try_into().expect("a panel of values");
            let mut sums = [0.0; W];
            if ADD {
                sums.copy_from_slice(block);
            }
            for &(r, column) in &self.states[s..s_end as usize] {
                let (a, at) = (entries[r as usize], column as usize + first);
                let direction: &[f64; W] = vy[at..at + W].try_into().expect("a panel of values");
                for j in 0..W {
                    sums[j] += a * direction[j];
                }
            }
            *block = sums;
            s = s_end as usize;
        }
    }
}

impl JacobianProducts {
    /// Work space for `n` states, the parameters `p` with directions `vp` (n_α × K, row by
    /// row), `m` function values and K = `directions` directions.
    pub fn new(n: usize, p: &[f64], vp: &[f64], m: usize, directions: usize) -> Self {
        let mut products = Self {
            duals: Duals::new(n, p.len(), m, directions),
            p: p.to_vec(),
            vp: vp.to_vec(),
            k: directions,
            sparse: None,
        };
        products.set_parameters(p, vp);
        products
    }

    /// New parameter values and directions.
    pub fn set_parameters(&mut self, p: &[f64], vp: &[f64]) {
        self.p.copy_from_slice(p);
        self.vp.copy_from_slice(vp);
        if let Some(sparse) = &mut self.sparse {
            // Planned again for the new directions on the next evaluation.
            sparse.plan = None;
        }
        self.duals.set_parameters(p, vp);
    }

    /// value = f(t, y, p, u) and out = J_y vy + J_p vp (both row-major with K columns),
    /// where f is the right-hand side or the outputs.
    #[allow(clippy::too_many_arguments)]
    pub fn eval<S: System>(
        &mut self,
        sys: &S,
        function: Function,
        (t, y, u): (f64, &[f64], &[f64]),
        vy: &[f64],
        value: &mut [f64],
        out: &mut [f64],
    ) {
        if self.k > 0
            && let Some(jacobian) = sys.sparse_jacobian(function)
        {
            let (vp, k) = (&self.vp, self.k);
            // A work space is for one function (a caller alternating would reallocate).
            if self.sparse.as_ref().is_some_and(|s| s.function != function) {
                self.sparse = None;
            }
            let sparse = self.sparse.get_or_insert_with(|| SparseWork::new(jacobian, function));
            sparse.products(jacobian, (t, y, &self.p, u), (vy, vp, k), value, out);
            return;
        }
        self.duals.eval(sys, function, (t, y, &self.p, u), vy, value, out);
    }
}

impl SparseWork {
    /// The work space of `function`'s sparse Jacobian, planned on its first evaluation.
    fn new(jacobian: &dyn SparseJacobian, function: Function) -> Self {
        Self {
            function,
            work: jacobian.workspace(),
            values: jacobian.values().to_vec(),
            plan: None,
        }
    }

    /// value = f and out = J_y vy + J_α vp (K columns, row by row) from one evaluation of
    /// the function and its nonzero Jacobian entries.
    fn products(
        &mut self,
        jacobian: &dyn SparseJacobian,
        (t, y, p, u): (f64, &[f64], &[f64], &[f64]),
        (vy, vp, k): (&[f64], &[f64], usize),
        value: &mut [f64],
        out: &mut [f64],
    ) {
        let plan = self.plan.get_or_insert_with(|| {
            let (m, n) = (self.values.len(), y.len());
            ProductPlan::new(jacobian.pattern(), jacobian.entries().iter().copied(), (m, n), vp, k)
        });
        jacobian.eval(t, y, p, u, &mut self.work);
        for (v, &r) in value.iter_mut().zip(&self.values) {
            *v = self.work[r as usize];
        }
        plan.apply::<false>(&self.work, vy, out);
    }
}

/// Dual-number buffers of one chunk width W (a const generic, chosen at run time).
struct Chunked<const W: usize> {
    /// Number of directions K.
    k: usize,
    yd: Vec<DualSVec64<W>>,
    /// Per chunk of directions: the seeded parameters.
    pd: Vec<Vec<DualSVec64<W>>>,
    fd: Vec<DualSVec64<W>>,
}

impl<const W: usize> Chunked<W> {
    fn new(n: usize, np: usize, m: usize, k: usize) -> Self {
        let zero = DualSVec64::<W>::from_re(0.0);
        let chunks = k.div_ceil(W);
        Self { k, yd: vec![zero; n], pd: vec![vec![zero; np]; chunks], fd: vec![zero; m] }
    }

    fn set_parameters(&mut self, p: &[f64], vp: &[f64]) {
        let k = self.k;
        for (c, pd) in self.pd.iter_mut().enumerate() {
            let first = c * W;
            Self::seed(pd, p, vp, k, first, W.min(k - first));
        }
    }

    /// Seeds `duals` with values `x` and directions `v[i*K + first ..][..width]`.
    #[inline(always)]
    fn seed(
        duals: &mut [DualSVec64<W>],
        x: &[f64],
        v: &[f64],
        k: usize,
        first: usize,
        width: usize,
    ) {
        // Copies of compile-time length for a full chunk (the usual case): no memcpy call.
        for (i, d) in duals.iter_mut().enumerate() {
            let at = i * k + first;
            let seed = if width == W {
                let row: [f64; W] = v[at..at + W].try_into().expect("a full chunk");
                SVector::from(row)
            } else {
                SVector::from_fn(|j, _| if j < width { v[at + j] } else { 0.0 })
            };
            *d = DualSVec64::new(x[i], Derivative::some(seed));
        }
    }

    // One function per width, never inlined into the dispatch over widths: the model's
    // right-hand side then compiles the same way whichever crate instantiates it (25 %
    // apart on van der Pol between two such crates otherwise).
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn eval<S: System>(
        &mut self,
        sys: &S,
        function: Function,
        (t, y, u): (f64, &[f64], &[f64]),
        vy: &[f64],
        value: &mut [f64],
        out: &mut [f64],
    ) {
        let k = self.k;
        for (c, pd) in self.pd.iter().enumerate() {
            let first = c * W;
            let width = W.min(k - first);
            Self::seed(&mut self.yd, y, vy, k, first, width);
            match function {
                Function::Rhs => sys.rhs(t, &self.yd, pd, u, &mut self.fd),
                Function::Outputs => sys.outputs(t, &self.yd, pd, u, &mut self.fd),
            }
            for (i, d) in self.fd.iter().enumerate() {
                let eps = d.eps.unwrap_generic(Const::<W>, U1);
                let at = i * k + first;
                if width == W {
                    let row: &mut [f64; W] =
                        (&mut out[at..at + W]).try_into().expect("a full chunk");
                    *row = eps.into();
                } else {
                    out[at..at + width].copy_from_slice(&eps.as_slice()[..width]);
                }
                if first == 0 {
                    value[i] = d.re;
                }
            }
        }
    }
}

macro_rules! duals {
    ($($w:literal => $variant:ident),*) => {
        /// The chunk width for a number of directions: K itself up to 8, else 8.
        enum Duals { None, $($variant(Chunked<$w>)),* }

        impl Duals {
            fn new(n: usize, np: usize, m: usize, k: usize) -> Self {
                match k {
                    0 => Duals::None,
                    $($w => Duals::$variant(Chunked::new(n, np, m, k)),)*
                    _ => Duals::W8(Chunked::new(n, np, m, k)),
                }
            }

            fn set_parameters(&mut self, p: &[f64], vp: &[f64]) {
                match self {
                    Duals::None => {}
                    $(Duals::$variant(c) => c.set_parameters(p, vp),)*
                }
            }

            fn eval<S: System>(
                &mut self,
                sys: &S,
                function: Function,
                (t, y, p, u): (f64, &[f64], &[f64], &[f64]),
                vy: &[f64],
                value: &mut [f64],
                out: &mut [f64],
            ) {
                match self {
                    Duals::None => match function {
                        Function::Rhs => sys.rhs(t, y, p, u, value),
                        Function::Outputs => sys.outputs(t, y, p, u, value),
                    },
                    $(Duals::$variant(c) => c.eval(sys, function, (t, y, u), vy, value, out),)*
                }
            }
        }
    };
}
duals!(1 => W1, 2 => W2, 3 => W3, 4 => W4, 5 => W5, 6 => W6, 7 => W7, 8 => W8);

#[cfg(test)]
mod tests {
    use super::*;

    /// J_y V_y + J_α V_α by its definition, entry by entry in the pattern's order (the order
    /// the plan adds its terms in), onto `start`.
    fn by_definition(
        pattern: &[(u32, u32)],
        values: &[f64],
        (m, n, k): (usize, usize, usize),
        (vy, vp): (&[f64], &[f64]),
        start: &[f64],
    ) -> Vec<f64> {
        let mut out = start.to_vec();
        for row in 0..m {
            let entries = || pattern.iter().zip(values).filter(|(e, _)| e.0 as usize == row);
            for j in 0..k {
                let o = &mut out[row * k + j];
                for (&(_, c), &a) in entries().filter(|(e, _)| (e.1 as usize) < n) {
                    *o += a * vy[c as usize * k + j];
                }
                for (&(_, c), &a) in entries().filter(|(e, _)| (e.1 as usize) >= n) {
                    let v = vp[(c as usize - n) * k + j];
                    if v != 0.0 {
                        *o += a * v;
                    }
                }
            }
        }
        out
    }

    /// Every width the plan has a path for gives the products of the definition to the bit:
    /// one pass of a compile-time width (1 to 32) and the panels of wider ones (33 as 17 +
    /// 16, 70 as three), written over the output and added to it.
    #[test]
    fn the_products_are_the_definitions_at_every_width() {
        let (m, n) = (3, 4);
        // Rows in order; columns 4 and 5 are the two parameters.
        let pattern = [(0, 0), (0, 2), (0, 4), (1, 1), (1, 3), (1, 5), (2, 0), (2, 1), (2, 2)];
        let values: Vec<f64> = (0..pattern.len()).map(|e| (e as f64 * 0.7).sin() + 0.1).collect();
        for k in [1, 5, 16, 17, 24, 32, 33, 35, 70] {
            let vy: Vec<f64> = (0..n * k).map(|i| (i as f64 * 0.31).cos()).collect();
            // Sparse directions for the parameters, as unit seeds are.
            let vp: Vec<f64> =
                (0..2 * k).map(|i| if i % 3 == 0 { 1.0 + i as f64 } else { 0.0 }).collect();
            let plan = ProductPlan::new(&pattern, 0..pattern.len() as u32, (m, n), &vp, k);
            let start: Vec<f64> = (0..m * k).map(|i| (i as f64 * 0.13).tan()).collect();
            let mut written = start.clone();
            plan.apply::<false>(&values, &vy, &mut written);
            let zero = vec![0.0; m * k];
            assert_eq!(
                written,
                by_definition(&pattern, &values, (m, n, k), (&vy, &vp), &zero),
                "k = {k}"
            );
            let mut added = start.clone();
            plan.apply::<true>(&values, &vy, &mut added);
            assert_eq!(
                added,
                by_definition(&pattern, &values, (m, n, k), (&vy, &vp), &start),
                "k = {k}"
            );
        }
    }
}
