//! One iteration of quasilinearization (Bellman, Kagiwada & Kalaba 1963) in its own terms.
//!
//! Around the current trajectory x_k(t) the augmented model is linearised,
//!
//! x' = G(x_k) + J(x_k) (x − x_k),  J = ∂G/∂x along x_k,
//!
//! and its solutions are x(t) = p(t) + Φ(t) c with
//!
//! Φ' = J Φ,  Φ(t0) = unit columns of the unknowns,
//! p' = G(x_k) + J(x_k)(p − x_k),  p(t0) = the known initial values (0 for unknowns),
//!
//! so c holds the unknowns' coordinates. BKK carry all N columns of Φ for the N components of
//! the augmented state and fix the known ones; folding the known columns into p gives the
//! same family with k columns. The parameter rows are constant (θ' = 0: p_θ = 0, Φ_θ = unit
//! rows), so only the n state rows of p and Φ are integrated: n (1 + k) equations, with the
//! products J·[Φ, p − x_k] from one dual-number evaluation per stage. c minimises ε of the
//! linear family, a linear least-squares problem (QR, faer); x_{k+1} = p + Φ c is kept as a
//! dense solution and linearised around next.

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    Linearization,
    method::{LinearLeastSquares, Singular, minimise_in_box},
    plan::Planned,
};
use sysid_ode::{
    Counts, DenseSolution, FactorError, Function, Integrator, IterationMatrix, JacobianProducts,
    Observable, OdeError, Rhs, Side, System, integrate, rhs_jump, stops,
};

use crate::trajectory::{Column, Layout, Trajectory};

/// The linear system for [p; Φ] (state rows; Φ row by row) around x_k.
struct LinearRhs<'a, S> {
    sys: &'a S,
    previous: &'a Trajectory,
    hint: usize,
    n: usize,
    k: usize,
    products: JacobianProducts,
    u: Vec<f64>,
    y: Vec<f64>,
    vy: Vec<f64>,
    g: Vec<f64>,
    jv: Vec<f64>,
    /// The model's parameters along x_k, and E = I/(γh) − J(x_k) for implicit steps
    /// (allocated on the first).
    p: Vec<f64>,
    implicit: Option<Box<IterationMatrix>>,
    /// The parameters' directions ([`parameter_directions`]) and the switches in time that
    /// move with a parameter (τ, q, ∂τ/∂α_q) at `p`.
    vp: Vec<f64>,
    moving: Vec<(f64, usize, f64)>,
}

/// The directions of the parameters, n_α × (k + 1) row by row: column j < k is the θ row of
/// Φ (a unit row for each parameter slot) and column k is p_θ − θ_k = −θ_k, both mapped by
/// dα/dθ (α itself on a log scale).
fn parameter_directions(layout: &Layout, np: usize, c: &[f64]) -> Vec<f64> {
    let kk = layout.k() + 1;
    let mut vp = vec![0.0; np * kk];
    for (j, column) in layout.columns.iter().enumerate() {
        if let Column::Parameter { index: q, log } = *column {
            let scale = if log { c[j].exp() } else { 1.0 };
            vp[q * kk + j] = scale;
            vp[q * kk + layout.k()] = -scale * c[j];
        }
    }
    vp
}

impl<'a, S: System> LinearRhs<'a, S> {
    fn new(sys: &'a S, layout: &Layout, previous: &'a Trajectory, known: &[f64]) -> Self {
        let sig = sys.signature();
        let (n, k) = (layout.n, layout.k());
        let p = layout.parameters(known, &previous.c);
        let vp = parameter_directions(layout, p.len(), &previous.c);
        Self {
            sys,
            previous,
            hint: 0,
            n,
            k,
            products: JacobianProducts::new(n, &p, &vp, n, k + 1),
            u: vec![0.0; sig.n_inputs()],
            y: vec![0.0; n],
            vy: vec![0.0; n * (k + 1)],
            g: vec![0.0; n],
            jv: vec![0.0; n * (k + 1)],
            moving: sys.moving_switches(&p),
            vp,
            p,
            implicit: None,
        }
    }
}

impl<S: System> Rhs for LinearRhs<'_, S> {
    fn dim(&self) -> usize {
        self.n * (1 + self.k)
    }

    fn eval(&mut self, t: f64, side: Side, w: &[f64], dw: &mut [f64]) {
        let (n, k) = (self.n, self.k);
        let kk = k + 1;
        self.previous.eval(t, &mut self.hint, &mut self.y);
        self.sys.input_values(t, side, &mut self.u);
        let (p, phi) = w.split_at(n);
        // Directions [Φ | p − x_k], row by row.
        for i in 0..n {
            self.vy[i * kk..i * kk + k].copy_from_slice(&phi[i * k..(i + 1) * k]);
            self.vy[i * kk + k] = p[i] - self.y[i];
        }
        let args = (t, self.y.as_slice(), self.u.as_slice());
        self.products.eval(self.sys, Function::Rhs, args, &self.vy, &mut self.g, &mut self.jv);
        let (dp, dphi) = dw.split_at_mut(n);
        for i in 0..n {
            dp[i] = self.g[i] + self.jv[i * kk + k];
            dphi[i * k..(i + 1) * k].copy_from_slice(&self.jv[i * kk..i * kk + k]);
        }
    }

    /// The linear system's Jacobian is J(x_k(t)) on every block (p and each column of Φ),
    /// independent of [p; Φ]: one n × n factorisation serves them all.
    fn factor(
        &mut self,
        t: f64,
        side: Side,
        _w: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        let (sys, k) = (self.sys, self.k);
        let p = &self.p;
        let matrix = self.implicit.get_or_insert_with(|| Box::new(IterationMatrix::new(sys, p, k)));
        self.previous.eval(t, &mut self.hint, &mut self.y);
        sys.input_values(t, side, &mut self.u);
        matrix.factor(sys, (t, &self.y, p, &self.u), inv_gamma_h)
    }

    fn solve(&mut self, r: &mut [f64]) {
        if let Some(matrix) = &mut self.implicit {
            let (p, phi) = r.split_at_mut(self.n);
            matrix.solve(p);
            if self.k > 0 {
                matrix.solve_rows(phi, self.k);
            }
        }
    }

    fn states(&self) -> usize {
        self.n
    }

    /// At a switch τ(α_q), where the model's right-hand side changes from g₋ to g₊ along
    /// x_k, the linearised jump (g₋ − g₊)·∂τ/∂α_q·(α_q − α_q,k): each column of Φ jumps by
    /// (g₋ − g₊)·∂τ/∂α_q times its direction in α_q, and p by the same times the direction's
    /// column p_θ − θ_k (as the sensitivities jump; `dir` turns it round going backwards).
    fn cross(&mut self, t: f64, w: &mut [f64], dir: f64) {
        if !self.moving.iter().any(|m| m.0.to_bits() == t.to_bits()) {
            return;
        }
        let (n, k, kk) = (self.n, self.k, self.k + 1);
        self.previous.eval(t, &mut self.hint, &mut self.y);
        let jump = rhs_jump(self.sys, t, &self.y, &self.p, &mut self.u);
        let (p, phi) = w.split_at_mut(n);
        for &(_, q, slope) in self.moving.iter().filter(|m| m.0.to_bits() == t.to_bits()) {
            let direction = &self.vp[q * kk..(q + 1) * kk];
            for i in 0..n {
                let d = dir * jump[i] * slope;
                p[i] += d * direction[k];
                for j in 0..k {
                    phi[i * k + j] += d * direction[j];
                }
            }
        }
    }

    fn describe(&self, i: usize) -> String {
        let sig = self.sys.signature();
        if i < self.n {
            format!("particular solution p of state {}", sig.states()[i])
        } else {
            let row = (i - self.n) / self.k;
            format!("fundamental matrix Φ, row of state {}", sig.states()[row])
        }
    }
}

/// The integrated family: [p; Φ] as a function of time.
pub struct Family {
    /// p (n) followed by Φ (n × k, row by row).
    pub dense: DenseSolution,
    /// Work of the integration.
    pub counts: Counts,
}

/// Integrates the linear system of experiment `e` around `previous` from t0 over its span;
/// `y0` and `known` are its initial values and parameters at the current point (the slots'
/// entries are replaced by the family's columns).
pub fn integrate_family<S: System>(
    e: &Planned<S>,
    integrator: &Integrator,
    layout: &Layout,
    previous: &Trajectory,
    (y0, known): (&[f64], &[f64]),
) -> Result<Family, OdeError> {
    let sys = e.system();
    let (n, k) = (layout.n, layout.k());
    let mut rhs = LinearRhs::new(sys, layout, previous, known);
    // p(t0): the known initial values (slots 0); Φ(t0): unit columns of the initial-value
    // slots.
    let mut w0 = vec![0.0; n * (1 + k)];
    for (i, v) in y0.iter().enumerate() {
        if !layout.columns.contains(&Column::State(i)) {
            w0[i] = *v;
        }
    }
    for (j, column) in layout.columns.iter().enumerate() {
        if let Column::State(i) = *column {
            w0[n + i * k + j] = 1.0;
        }
    }
    let t0 = e.t0();
    let (t_lo, t_hi) = e.span();
    let stops = stops(sys, &rhs.p);
    let mut dense = DenseSolution::new(w0.len());
    let mut counts = Counts::default();
    for t_end in [t_hi, t_lo] {
        if (t_end - t0).abs() > 0.0 {
            counts +=
                integrate(integrator, &mut rhs, (t0, &w0), t_end, &stops, |s| dense.push(s))?.0;
        }
    }
    dense.finish();
    if dense.is_empty() {
        // Every sample at t0: the family is its initial value there.
        dense = DenseSolution::at_instant(t0, &w0);
    }
    Ok(Family { dense, counts })
}

/// The linear least-squares problem of a family: residuals a + B c (weighted rows).
pub struct LeastSquares {
    /// a.
    pub a: DVector<f64>,
    /// B.
    pub b: DMatrix<f64>,
}

impl LeastSquares {
    /// The rows of experiment `e`'s family at its data: r = √w (T(h_k) + T'(h_k)·∇h·(p + Φc
    /// − x_k) − T(b)) with h_k the value along x_k, which is √w (p_i + Φ_i c − b) for a
    /// state measured on its own scale; `known` are its parameters at the current point.
    pub fn new<S: System>(
        e: &Planned<S>,
        layout: &Layout,
        previous: &Trajectory,
        family: &Family,
        known: &[f64],
    ) -> Self {
        let sys = e.system();
        let sig = sys.signature();
        let (n, k) = (layout.n, layout.k());
        let kk = k + 1;
        let sampled = e.sampled();
        let rows: usize = sampled.series.iter().map(|s| s.samples.len()).sum();
        let (mut a, mut b) = (DVector::zeros(rows), DMatrix::zeros(rows, k));
        // p and Φ at every sample time.
        let mut at = vec![0.0; sampled.times.len() * n * (1 + k)];
        let width = n * (1 + k);
        let mut hint = 0;
        for (m, &t) in sampled.times.iter().enumerate() {
            family.dense.eval_hinted(t, &mut hint, &mut at[m * width..(m + 1) * width]);
        }
        // Outputs that are not states are linearised around x_k with dual numbers.
        let n_out = sig.outputs().len();
        let params = layout.parameters(known, &previous.c);
        let vp = parameter_directions(layout, params.len(), &previous.c);
        let mut products =
            JacobianProducts::new(n, &params, &vp, n_out, if n_out > 0 { kk } else { 0 });
        let mut g = vec![0.0; k];
        let (mut y, mut vy, mut h, mut dh, mut u) = (
            vec![0.0; n],
            vec![0.0; n * kk],
            vec![0.0; n_out],
            vec![0.0; n_out * kk],
            vec![0.0; sig.n_inputs()],
        );
        let mut row = 0;
        let mut hint = 0;
        for series in &sampled.series {
            for sample in &series.samples {
                let t = sampled.times[sample.index];
                let w = &at[sample.index * width..(sample.index + 1) * width];
                let (p, phi) = w.split_at(n);
                let sw = sample.sqrt_weight;
                let transform = series.transform;
                // The family's value h0 + g·c of the measured quantity, and its value along
                // x_k where a scale other than its own linearises it.
                let (h0, along) = match series.observable {
                    Observable::State(i) => {
                        g.copy_from_slice(&phi[i * k..(i + 1) * k]);
                        let along = match transform {
                            sysid_core::Transform::Lin => None,
                            _ => {
                                previous.eval(t, &mut hint, &mut y);
                                Some(y[i])
                            }
                        };
                        (p[i], along)
                    }
                    Observable::Output(o) => {
                        previous.eval(t, &mut hint, &mut y);
                        sys.input_values(t, Side::After, &mut u);
                        for i in 0..n {
                            vy[i * kk..i * kk + k].copy_from_slice(&phi[i * k..(i + 1) * k]);
                            vy[i * kk + k] = p[i] - y[i];
                        }
                        products.eval(sys, Function::Outputs, (t, &y, &u), &vy, &mut h, &mut dh);
                        g.copy_from_slice(&dh[o * kk..o * kk + k]);
                        (h[o] + dh[o * kk + k], Some(h[o]))
                    }
                };
                let (value, slope) = match (transform, along) {
                    (sysid_core::Transform::Lin, _) | (_, None) => (h0, 1.0),
                    (t, Some(hk)) => (t.apply(hk) + t.derivative(hk) * (h0 - hk), t.derivative(hk)),
                };
                a[row] = sw * (value - sample.value);
                for j in 0..k {
                    b[(row, j)] = sw * slope * g[j];
                }
                row += 1;
            }
        }
        Self { a, b }
    }

    /// The c minimising ‖a + B c‖ within the bounds (lo, hi) of the unknowns' coordinates,
    /// and the condition number of the free columns; or the unknowns B cannot tell apart.
    /// Without bounds one QR solve; with them bounded-variable least squares (Stark & Parker's
    /// active-set method, QR on the free columns) from the feasible `start`: never the free
    /// solution clipped.
    pub fn solve(
        &self,
        (lo, hi): (&[f64], &[f64]),
        start: &[f64],
        max_condition: f64,
    ) -> Result<(DVector<f64>, f64), Singular> {
        let problem = LinearLeastSquares { b: &self.b, a: &self.a };
        let solution = minimise_in_box(&problem, (lo, hi), start, max_condition)?;
        Ok((DVector::from_vec(solution.x), solution.condition.value()))
    }

    /// The linear family's residual at c, a + B c.
    pub fn residual(&self, c: &[f64]) -> DVector<f64> {
        &self.a + &self.b * DVector::from_column_slice(c)
    }

    /// ε, U and A of the linear family at c (A = BᵀB, U = Bᵀ(a + Bc)): at convergence those
    /// of the nonlinear problem, whose Jacobian B then is.
    pub fn linearization(&self, c: &[f64], counts: Counts) -> Linearization {
        let r = self.residual(c);
        let cost = r.norm_squared();
        Linearization {
            z: c.to_vec(),
            cost,
            gradient: self.b.tr_mul(&r),
            normal: self.b.tr_mul(&self.b),
            residuals: None,
            norm: cost.sqrt(),
            experiment_costs: vec![cost],
            counts,
        }
    }

    /// The rows of several experiments in the unknowns' coordinates z: each experiment's
    /// a + B c with c ≈ c_k + D (z − z_k), stacked.
    pub fn stacked(parts: &[(LeastSquares, Vec<f64>, DMatrix<f64>)], z: &[f64]) -> Self {
        let rows: usize = parts.iter().map(|p| p.0.a.len()).sum();
        let k = z.len();
        let zk = DVector::from_column_slice(z);
        let (mut a, mut b) = (DVector::zeros(rows), DMatrix::zeros(rows, k));
        let mut at = 0;
        for (ls, c, d) in parts {
            let m = ls.a.len();
            let offset = DVector::from_column_slice(c) - d * &zk;
            a.rows_mut(at, m).copy_from(&(&ls.a + &ls.b * offset));
            b.rows_mut(at, m).copy_from(&(&ls.b * d));
            at += m;
        }
        Self { a, b }
    }
}

/// x_{k+1} = p + Φ c as a dense solution of one experiment's states.
pub fn next_trajectory(layout: &Layout, family: &Family, c: &[f64]) -> Trajectory {
    let (n, k) = (layout.n, layout.k());
    let states = family.dense.map(n, |w, y| {
        for i in 0..n {
            y[i] = w[i] + (0..k).map(|j| w[n + i * k + j] * c[j]).sum::<f64>();
        }
    });
    Trajectory::linear(states, c.to_vec())
}
