//! Dense output: the solution between the ends of a step, and a whole stored trajectory.

use crate::events::Fired;
use crate::signal::Side;

/// The solution on one accepted step from `t` to `t + h` (h may be negative), as the
/// polynomial in θ = (s − t)/h
///
/// x(s) = r₁ + θ (r₂ + (1−θ)(r₃ + θ (r₄ + (1−θ)(r₅ + θ (r₆ + (1−θ)(r₇ + θ r₈))))))
///
/// which is Hairer's form for DOPRI5 (r₅ ≠ 0, r₆ = 0, order 4) and, with r₅ = r₆ = 0, the
/// cubic Hermite interpolant through both ends and their slopes (order 3) used for RK4; r₆
/// extends it to degree 5, the multistep scheme's interpolating polynomial at order 5, and
/// r₇, r₈ to degree 7, DOP853's dense output of order 7. A step's polynomial has six
/// coefficient vectors (r₇ = r₈ = 0, not stored) or all eight (DOP853's).
#[derive(Clone, Debug, PartialEq)]
pub struct Interpolant {
    t: f64,
    /// The exact end of the step (t + h may differ from it in the last bit).
    t_end: f64,
    h: f64,
    dim: usize,
    /// r₁..r₈, each of length `dim`, stored one after another; the first `terms` of them
    /// are the step's.
    coefficients: Vec<f64>,
    /// How many of r₁..r₈ the step's polynomial has: [`TERMS`] or [`ALL_TERMS`].
    terms: usize,
    /// Whether r₆ was last written (by the multistep scheme or DOP853): the other one-step
    /// schemes write r₁..r₅ and find r₆ = 0.
    sixth: bool,
}

/// The coefficient vectors of a step's polynomial but DOP853's (r₁..r₆).
const TERMS: usize = 6;
/// The coefficient vectors of DOP853's polynomial (r₁..r₈).
const ALL_TERMS: usize = 8;

impl Interpolant {
    pub(crate) fn new(dim: usize) -> Self {
        let coefficients = vec![0.0; ALL_TERMS * dim];
        Self { t: 0.0, t_end: 0.0, h: 0.0, dim, coefficients, terms: TERMS, sixth: false }
    }

    pub(crate) fn set_span(&mut self, t: f64, t_end: f64) {
        self.t = t;
        self.t_end = t_end;
        self.h = t_end - t;
    }

    /// Sets the interpolant on [t, t_end] to the cubic Hermite one through x and x_end with
    /// slopes f and f_end (r₅ = 0): RK4's dense output, and DOPRI5's before its r₅.
    pub(crate) fn set_hermite(
        &mut self,
        (t, t_end): (f64, f64),
        (x, x_end): (&[f64], &[f64]),
        (f, f_end): (&[f64], &[f64]),
    ) {
        let h = t_end - t;
        let n = self.dim;
        let [r1, r2, r3, r4, r5] = self.coefficients_mut();
        // Slices of one length: the loop below runs without bounds checks.
        let (r1, r2, r3, r4, r5) =
            (&mut r1[..n], &mut r2[..n], &mut r3[..n], &mut r4[..n], &mut r5[..n]);
        let (x, x_end, f, f_end) = (&x[..n], &x_end[..n], &f[..n], &f_end[..n]);
        for i in 0..n {
            r1[i] = x[i];
            r2[i] = x_end[i] - x[i];
            r3[i] = h * f[i] - r2[i];
            r4[i] = r2[i] - h * f_end[i] - r3[i];
            r5[i] = 0.0;
        }
        self.set_span(t, t_end);
    }

    /// r₁..r₅, for a scheme whose polynomial is of degree 4 at most (r₆ = 0).
    pub(crate) fn coefficients_mut(&mut self) -> [&mut [f64]; 5] {
        let clear = std::mem::take(&mut self.sixth);
        self.terms = TERMS;
        let [r1, r2, r3, r4, r5, r6, _, _] = self.split();
        if clear {
            r6.fill(0.0);
        }
        [r1, r2, r3, r4, r5]
    }

    /// r₁..r₆, all of which the caller writes.
    pub(crate) fn coefficients6_mut(&mut self) -> [&mut [f64]; TERMS] {
        self.sixth = true;
        self.terms = TERMS;
        let [r1, r2, r3, r4, r5, r6, _, _] = self.split();
        [r1, r2, r3, r4, r5, r6]
    }

    /// r₁..r₈, all of which the caller writes (DOP853's polynomial of degree 7).
    pub(crate) fn coefficients8_mut(&mut self) -> [&mut [f64]; ALL_TERMS] {
        self.sixth = true;
        self.terms = ALL_TERMS;
        self.split()
    }

    fn split(&mut self) -> [&mut [f64]; ALL_TERMS] {
        let dim = self.dim;
        let mut rest = self.coefficients.as_mut_slice();
        std::array::from_fn(|_| {
            let (r, tail) = std::mem::take(&mut rest).split_at_mut(dim);
            rest = tail;
            r
        })
    }

    /// The step's coefficient vectors, r₁ to the last it has.
    fn used(&self) -> &[f64] {
        &self.coefficients[..self.terms * self.dim]
    }

    /// Where the step starts.
    pub fn t_start(&self) -> f64 {
        self.t
    }
    /// Where the step ends, exactly (a segment end or output time it landed on).
    pub fn t_end(&self) -> f64 {
        self.t_end
    }
    /// The signed step size.
    pub fn h(&self) -> f64 {
        self.h
    }
    /// Length of the interpolated vector.
    pub fn dim(&self) -> usize {
        self.dim
    }
    /// The smaller and the larger end of the step.
    pub fn bounds(&self) -> (f64, f64) {
        let (a, b) = (self.t, self.t_end);
        if a <= b { (a, b) } else { (b, a) }
    }

    /// Writes the solution at time s (inside the step) into `out`.
    pub fn eval(&self, s: f64, out: &mut [f64]) {
        self.eval_range(s, 0, out);
    }

    /// Writes components `first .. first + out.len()` of the solution at s into `out`.
    pub fn eval_range(&self, s: f64, first: usize, out: &mut [f64]) {
        evaluate(self.t, self.t_end, self.dim, self.used(), s, first, out);
    }
}

/// A stored solution: the interpolants of every accepted step, evaluable at any time in the
/// integrated span. Used where a trajectory is needed as a function (quasilinearization's
/// iterate, predictions, the forward half of an adjoint gradient). Coefficients are kept in
/// one flat vector, so storing a step allocates only when the vector grows; that vector is
/// one a solution dropped before left behind, where there is one ([`SPARE`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DenseSolution {
    dim: usize,
    /// (start, end) of each step as integrated (end < start for a backward step), in
    /// increasing time once finished.
    spans: Vec<(f64, f64)>,
    /// The coefficients of every step (r₁..r₆ of [`Interpolant`], or r₁..r₈ for DOP853's),
    /// one step after another.
    coefficients: Vec<f64>,
    /// Where each step's coefficients begin in `coefficients`, and after the last step its
    /// end (empty while no step is stored).
    offsets: Vec<usize>,
    /// The state events fired along the solution, in order: (event, τ, the state before
    /// it). A step ends at each τ and the next begins there, after the reset.
    pub(crate) fired: Vec<Fired>,
}

/// The coefficients' storage of the largest [`DenseSolution`]s dropped lately, at most
/// [`SPARES`] of them, which the next ones stored fill. An adjoint gradient stores the forward
/// solution of every experiment at every evaluation (Chen's: 500 states over some 2 500
/// steps of the multistep scheme, 60 MB each): in freshly mapped memory each time (the
/// allocator maps blocks that large afresh and unmaps them when they are freed), the kernel's
/// page faults took an eighth of its time.
static SPARE: std::sync::Mutex<Vec<Vec<f64>>> = std::sync::Mutex::new(Vec::new());

/// How many storages [`SPARE`] keeps: one for each experiment integrated at once on a
/// machine of a few cores.
const SPARES: usize = 4;

/// The least storage [`SPARE`] keeps, in values: 32 MiB, above which glibc's allocator maps
/// every block afresh. Below it the allocator keeps freed blocks for the next ones itself,
/// from memory the process already uses (handing out the largest spare instead made Smith's
/// 34 experiments of 4–10 MB each 2 % slower).
const SPARE_FROM: usize = (32 << 20) / std::mem::size_of::<f64>();

impl Drop for DenseSolution {
    fn drop(&mut self) {
        let mut mine = std::mem::take(&mut self.coefficients);
        if mine.capacity() < SPARE_FROM {
            return;
        }
        mine.clear();
        let Ok(mut spare) = SPARE.lock() else { return };
        spare.push(mine);
        spare.sort_by_key(|v| std::cmp::Reverse(v.capacity()));
        spare.truncate(SPARES);
    }
}

impl DenseSolution {
    /// An empty solution of vectors of length `dim`.
    pub fn new(dim: usize) -> Self {
        // The largest storage kept (first after the sort).
        let coefficients = match SPARE.lock() {
            Ok(mut spare) if !spare.is_empty() => spare.remove(0),
            _ => Vec::new(),
        };
        Self { dim, spans: Vec::new(), coefficients, offsets: Vec::new(), fired: Vec::new() }
    }

    /// The solution over the single instant t, where it is y: what an integration over an
    /// empty span (every sample at t0, as a steady state measured at t = 0) leaves, so that
    /// evaluating it at t gives y instead of finding no step.
    pub fn at_instant(t: f64, y: &[f64]) -> Self {
        let dim = y.len();
        let mut coefficients = vec![0.0; TERMS * dim];
        coefficients[..dim].copy_from_slice(y);
        let offsets = vec![0, coefficients.len()];
        Self { dim, spans: vec![(t, t)], coefficients, offsets, fired: Vec::new() }
    }

    /// The coefficients of step i.
    fn step(&self, i: usize) -> &[f64] {
        &self.coefficients[self.offsets[i]..self.offsets[i + 1]]
    }

    /// Length of the vectors.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Adds a step. Forward steps arrive in increasing time, backward ones in decreasing
    /// time; call [`finish`](Self::finish) after integrating in both directions.
    pub fn push(&mut self, step: &Interpolant) {
        debug_assert_eq!(step.dim, self.dim);
        if self.offsets.is_empty() {
            self.offsets.push(self.coefficients.len());
        }
        self.spans.push((step.t, step.t_end));
        self.coefficients.extend_from_slice(step.used());
        self.offsets.push(self.coefficients.len());
    }

    /// Puts the steps in increasing time.
    pub fn finish(&mut self) {
        if self.spans.windows(2).all(|w| lower(w[0]) <= lower(w[1])) {
            return;
        }
        let mut order: Vec<usize> = (0..self.spans.len()).collect();
        order.sort_by(|&a, &b| lower(self.spans[a]).total_cmp(&lower(self.spans[b])));
        let spans = order.iter().map(|&i| self.spans[i]).collect();
        let mut coefficients = Vec::with_capacity(self.coefficients.len());
        let mut offsets = Vec::with_capacity(self.offsets.len());
        offsets.push(0);
        for &i in &order {
            coefficients.extend_from_slice(self.step(i));
            offsets.push(coefficients.len());
        }
        self.spans = spans;
        self.coefficients = coefficients;
        self.offsets = offsets;
    }

    /// The span covered, if any step is stored.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((lower(*self.spans.first()?), upper(*self.spans.last()?)))
    }

    /// Number of stored steps.
    pub fn len(&self) -> usize {
        self.spans.len()
    }

    /// Whether no step is stored.
    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// Writes the solution at t into `out`, or returns `false` if t is outside the span.
    pub fn eval(&self, t: f64, out: &mut [f64]) -> bool {
        let mut hint = self.spans.len() / 2;
        self.eval_hinted(t, &mut hint, out)
    }

    /// The times of the state events fired along the solution, in order.
    pub fn event_times(&self) -> impl Iterator<Item = f64> + '_ {
        self.fired.iter().map(|e| e.tau)
    }

    /// Like [`eval_hinted`](Self::eval_hinted), with the one-sided limit `side` where a step
    /// ends at t and the next begins there (the solution jumps at a state event).
    pub fn eval_side(&self, t: f64, side: Side, hint: &mut usize, out: &mut [f64]) -> bool {
        if !self.eval_hinted(t, hint, out) {
            return false;
        }
        let (i, n) = (*hint, self.spans.len());
        let at = |end: f64| end.to_bits() == t.to_bits();
        let other = match side {
            Side::Before if at(lower(self.spans[i])) && i > 0 => i - 1,
            Side::After if at(upper(self.spans[i])) && i + 1 < n => i + 1,
            _ => return true,
        };
        let ends_there = match side {
            Side::Before => at(upper(self.spans[other])),
            Side::After => at(lower(self.spans[other])),
        };
        if ends_there {
            *hint = other;
            let (a, b) = self.spans[other];
            evaluate(a, b, self.dim, self.step(other), t, 0, out);
        }
        true
    }

    /// Like [`eval`](Self::eval), starting the search at the step `hint` (updated): O(1)
    /// for the nearby, mostly monotone times an integrator asks for.
    pub fn eval_hinted(&self, t: f64, hint: &mut usize, out: &mut [f64]) -> bool {
        let n = self.spans.len();
        if n == 0 {
            return false;
        }
        let inside = |i: usize| lower(self.spans[i]) <= t && t <= upper(self.spans[i]);
        let i = (*hint).min(n - 1);
        let found = if inside(i) {
            Some(i)
        } else if i + 1 < n && inside(i + 1) {
            Some(i + 1)
        } else if i > 0 && inside(i - 1) {
            Some(i - 1)
        } else if lower(self.spans[0]) <= t && t <= upper(self.spans[n - 1]) {
            Some(self.spans.partition_point(|&s| upper(s) < t).min(n - 1))
        } else {
            None
        };
        let Some(i) = found else { return false };
        *hint = i;
        let (a, b) = self.spans[i];
        evaluate(a, b, self.dim, self.step(i), t, 0, out);
        true
    }

    /// The same solution under a linear map L of its vectors: `map(x, out)` writes L x (of
    /// length `dim`). Exact, because the interpolants are linear in their coefficients.
    pub fn map(&self, dim: usize, mut map: impl FnMut(&[f64], &mut [f64])) -> DenseSolution {
        let vectors = self.coefficients.len() / self.dim.max(1);
        let mut coefficients = vec![0.0; vectors * dim];
        for (r, o) in self.coefficients.chunks(self.dim).zip(coefficients.chunks_mut(dim)) {
            map(r, o);
        }
        let offsets = self.offsets.iter().map(|&o| o / self.dim.max(1) * dim).collect();
        DenseSolution { dim, spans: self.spans.clone(), coefficients, offsets, fired: Vec::new() }
    }
}

fn lower((a, b): (f64, f64)) -> f64 {
    a.min(b)
}

fn upper((a, b): (f64, f64)) -> f64 {
    a.max(b)
}

/// Evaluates the interpolation polynomial of a step from a to b with coefficients r₁..r₆ or
/// r₁..r₈ (each of length `dim`, stored one after another) at s, components
/// `first..first + out.len()`.
fn evaluate(a: f64, b: f64, dim: usize, c: &[f64], s: f64, first: usize, out: &mut [f64]) {
    let h = b - a;
    let theta = if h == 0.0 { 0.0 } else { (s - a) / h };
    let theta1 = 1.0 - theta;
    if c.len() == ALL_TERMS * dim {
        for (k, o) in out.iter_mut().enumerate() {
            let i = first + k;
            let r = |j: usize| c[j * dim + i];
            let tail = r(5) + theta1 * (r(6) + theta * r(7));
            *o = r(0)
                + theta
                    * (r(1) + theta1 * (r(2) + theta * (r(3) + theta1 * (r(4) + theta * tail))));
        }
        return;
    }
    for (k, o) in out.iter_mut().enumerate() {
        let i = first + k;
        *o = c[i]
            + theta
                * (c[dim + i]
                    + theta1
                        * (c[2 * dim + i]
                            + theta
                                * (c[3 * dim + i]
                                    + theta1 * (c[4 * dim + i] + theta * c[5 * dim + i]))));
    }
}
