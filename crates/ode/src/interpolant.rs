//! Dense output: the solution between the ends of a step, and a whole stored trajectory.

/// The solution on one accepted step from `t` to `t + h` (h may be negative), as the
/// polynomial in θ = (s − t)/h
///
/// x(s) = r₁ + θ (r₂ + (1−θ)(r₃ + θ (r₄ + (1−θ) r₅)))
///
/// which is Hairer's form for DOPRI5 (r₅ ≠ 0, order 4) and, with r₅ = 0, the cubic Hermite
/// interpolant through both ends and their slopes (order 3) used for RK4.
#[derive(Clone, Debug, PartialEq)]
pub struct Interpolant {
    t: f64,
    /// The exact end of the step (t + h may differ from it in the last bit).
    t_end: f64,
    h: f64,
    dim: usize,
    /// r₁..r₅, each of length `dim`, stored one after another.
    coefficients: Vec<f64>,
}

impl Interpolant {
    pub(crate) fn new(dim: usize) -> Self {
        Self { t: 0.0, t_end: 0.0, h: 0.0, dim, coefficients: vec![0.0; 5 * dim] }
    }

    pub(crate) fn set_span(&mut self, t: f64, t_end: f64) {
        self.t = t;
        self.t_end = t_end;
        self.h = t_end - t;
    }

    pub(crate) fn coefficients_mut(&mut self) -> [&mut [f64]; 5] {
        let (r1, rest) = self.coefficients.split_at_mut(self.dim);
        let (r2, rest) = rest.split_at_mut(self.dim);
        let (r3, rest) = rest.split_at_mut(self.dim);
        let (r4, r5) = rest.split_at_mut(self.dim);
        [r1, r2, r3, r4, r5]
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
        let theta = if self.h == 0.0 { 0.0 } else { (s - self.t) / self.h };
        let theta1 = 1.0 - theta;
        let d = self.dim;
        let c = &self.coefficients;
        for (k, o) in out.iter_mut().enumerate() {
            let i = first + k;
            *o = c[i]
                + theta
                    * (c[d + i]
                        + theta1 * (c[2 * d + i] + theta * (c[3 * d + i] + theta1 * c[4 * d + i])));
        }
    }
}

/// A stored solution: the interpolants of every accepted step, evaluable at any time in the
/// integrated span. Used where a trajectory is needed as a function (quasilinearization's
/// iterate, predictions).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DenseSolution {
    /// Steps in increasing time (backward steps are stored in increasing time too).
    steps: Vec<Interpolant>,
}

impl DenseSolution {
    /// An empty solution.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a step. Steps may arrive in any order; call [`finish`](Self::finish) afterwards.
    pub fn push(&mut self, step: &Interpolant) {
        self.steps.push(step.clone());
    }

    /// Sorts the steps by time. Needed after integrating in both directions.
    pub fn finish(&mut self) {
        self.steps.sort_by(|a, b| a.bounds().0.total_cmp(&b.bounds().0));
    }

    /// The span covered, if any step is stored.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((self.steps.first()?.bounds().0, self.steps.last()?.bounds().1))
    }

    /// The stored steps, in increasing time.
    pub fn steps(&self) -> &[Interpolant] {
        &self.steps
    }

    /// Writes the solution at t into `out`, or returns `false` if t is outside the span.
    pub fn eval(&self, t: f64, out: &mut [f64]) -> bool {
        match self.step_at(t) {
            Some(step) => {
                step.eval(t, out);
                true
            }
            None => false,
        }
    }

    /// The step whose span contains t.
    pub fn step_at(&self, t: f64) -> Option<&Interpolant> {
        let (lo, hi) = self.span()?;
        if !(lo..=hi).contains(&t) {
            return None;
        }
        let i = self.steps.partition_point(|s| s.bounds().1 < t);
        self.steps.get(i.min(self.steps.len() - 1))
    }
}
