//! Initial-value problems of a [`System`]: the solution and its forward sensitivities
//! (Goodman 1966, eq. 6–7) at given times, on both sides of the initial time.

use nalgebra::{DMatrix, DMatrixView, Dyn};

use crate::counts::{Costs, Counts};
use crate::driver::{integrate, integrate_selected};
use crate::error::OdeError;
use crate::events::{self, Fired};
use crate::implicit::{AugmentedMatrix, IterationMatrix, Structure};
use crate::interpolant::{DenseSolution, Interpolant};
use crate::jacobian::JacobianProducts;
use crate::lu::FactorError;
use crate::options::Integrator;
use crate::rhs::Rhs;
use crate::signal::Side;
use crate::sparse::SparseJacobian;
use crate::system::{Function, Observable, System};
use crate::wrt::{Wrt, parameter_seeds, wrt_name};

/// An initial-value problem: a system, the initial time t0, the state y(t0) and the
/// parameters. The solution may be asked for at times before and after t0.
#[derive(Clone, Copy, Debug)]
pub struct Ivp<'a, S> {
    /// The model.
    pub system: &'a S,
    /// Time of the initial values.
    pub t0: f64,
    /// y(t0).
    pub y0: &'a [f64],
    /// Parameter values α.
    pub p: &'a [f64],
    /// Per sensitivity column of [`solve_sensitivities`](Self::solve_sensitivities), the
    /// factor w_j of the units its error is controlled in (see [`weighted`](Self::weighted)).
    weights: Option<&'a [f64]>,
    /// The states' sizes their absolute floors are taken from ([`sized`](Self::sized)).
    sizes: Option<&'a [f64]>,
}

/// The state at a list of times.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    pub(crate) times: Vec<f64>,
    pub(crate) n: usize,
    pub(crate) values: Vec<f64>,
    pub(crate) counts: Counts,
}

impl Trajectory {
    /// The times asked for.
    pub fn times(&self) -> &[f64] {
        &self.times
    }
    /// y(t_m).
    pub fn state(&self, m: usize) -> &[f64] {
        &self.values[m * self.n..(m + 1) * self.n]
    }
    /// The work done.
    pub fn counts(&self) -> Counts {
        self.counts
    }
}

/// The state y(t_m) and the sensitivity matrix S(t_m) = ∂y/∂z (n × k) at a list of times.
///
/// Layout (also of the integrated state x = [y; S]): S is stored row by row, row i holding
/// ∂y_i/∂z_1 … ∂y_i/∂z_k, so the k sensitivities of one state, which seed one dual-number
/// evaluation together, are contiguous.
#[derive(Clone, Debug, PartialEq)]
pub struct SensitivityTrajectory {
    times: Vec<f64>,
    n: usize,
    k: usize,
    /// Per time: y (n) followed by S row by row (n·k).
    data: Vec<f64>,
    counts: Counts,
}

impl SensitivityTrajectory {
    /// The times asked for.
    pub fn times(&self) -> &[f64] {
        &self.times
    }
    /// Number of sensitivity columns k.
    pub fn n_columns(&self) -> usize {
        self.k
    }
    fn block(&self, m: usize) -> &[f64] {
        let w = self.n * (1 + self.k);
        &self.data[m * w..(m + 1) * w]
    }
    /// y(t_m).
    pub fn state(&self, m: usize) -> &[f64] {
        &self.block(m)[..self.n]
    }
    /// S(t_m), n × k, column j = ∂y/∂z_j.
    pub fn sensitivity(&self, m: usize) -> DMatrixView<'_, f64, Dyn, Dyn> {
        DMatrixView::from_slice_with_strides(&self.block(m)[self.n..], self.n, self.k, self.k, 1)
    }
    /// S(t_m) as a flat slice, row by row.
    pub fn sensitivity_slice(&self, m: usize) -> &[f64] {
        &self.block(m)[self.n..]
    }
    /// The work done.
    pub fn counts(&self) -> Counts {
        self.counts
    }
}

/// The model alone as a flat right-hand side.
pub struct ModelRhs<'a, S> {
    sys: &'a S,
    p: &'a [f64],
    u: Vec<f64>,
    /// Allocated on the first implicit step.
    implicit: Option<Box<IterationMatrix>>,
    /// The work space of the system's own sparse Jacobian, where it has one: f is read from
    /// that evaluation (compiled for a model file) rather than from `rhs`.
    work: Vec<f64>,
    structure: Structure,
    /// The states' sizes for their floors ([`Ivp::sized`]).
    sizes: Option<&'a [f64]>,
}

impl<'a, S: System> ModelRhs<'a, S> {
    /// The right-hand side of `sys` at parameters `p`.
    pub fn new(sys: &'a S, p: &'a [f64]) -> Self {
        let work = functions_alone(sys).map(|f| f.workspace()).unwrap_or_default();
        let u = vec![0.0; sys.signature().n_inputs()];
        Self { sys, p, u, implicit: None, work, structure: Structure::of(sys), sizes: None }
    }

    /// The states' sizes for their absolute floors (see [`Ivp::sized`]).
    pub fn sized(self, sizes: Option<&'a [f64]>) -> Self {
        Self { sizes, ..self }
    }
}

/// The program by which f alone is evaluated, where the system has a sparse Jacobian: its
/// [values alone](SparseJacobian::values_alone), else the whole program.
fn functions_alone<S: System>(sys: &S) -> Option<&dyn SparseJacobian> {
    sys.sparse_jacobian(Function::Rhs).map(|j| j.for_values())
}

/// f(t, y, α, u) into `dx`: from the system's own sparse Jacobian's program where it has one
/// (for a model file, machine code that computes f alone, faster than its interpreter), in
/// `work`, that program's work space; else from [`System::rhs`].
fn rhs_of<S: System>(
    sys: &S,
    (t, x, p, u): (f64, &[f64], &[f64], &[f64]),
    work: &mut [f64],
    dx: &mut [f64],
) {
    match functions_alone(sys) {
        Some(f) if !work.is_empty() => {
            f.eval(t, x, p, u, work);
            for (d, &v) in dx.iter_mut().zip(f.values()) {
                *d = work[v as usize];
            }
        }
        _ => sys.rhs(t, x, p, u, dx),
    }
}

impl<S: System> Rhs for ModelRhs<'_, S> {
    fn dim(&self) -> usize {
        self.sys.signature().n_states()
    }
    fn state_sizes(&self) -> Option<&[f64]> {
        self.sizes
    }
    fn eval(&mut self, t: f64, side: Side, x: &[f64], dx: &mut [f64]) {
        self.sys.input_values(t, side, &mut self.u);
        rhs_of(self.sys, (t, x, self.p, &self.u), &mut self.work, dx);
    }
    fn describe(&self, i: usize) -> String {
        format!("state {}", self.sys.signature().states()[i])
    }
    fn autonomous(&self) -> bool {
        self.sys.autonomous()
    }
    fn costs(&self) -> Costs {
        let s = &self.structure;
        let (factor, solve) = match &self.implicit {
            Some(matrix) => matrix.costs(s),
            None => s.dense_implicit(),
        };
        Costs { eval: s.values, factor, solve }
    }
    fn factor(
        &mut self,
        t: f64,
        side: Side,
        x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        let (sys, p) = (self.sys, self.p);
        let matrix = self.implicit.get_or_insert_with(|| Box::new(IterationMatrix::new(sys, p, 1)));
        sys.input_values(t, side, &mut self.u);
        matrix.factor(sys, (t, x, p, &self.u), inv_gamma_h)
    }
    fn solve(&mut self, r: &mut [f64]) {
        if let Some(matrix) = &mut self.implicit {
            matrix.solve(r);
        }
    }
    fn n_events(&self) -> usize {
        self.sys.n_events()
    }
    fn event_conditions(&mut self, t: f64, y: &[f64], c: &mut [f64]) {
        events::conditions(self.sys, t, y, self.p, c);
    }
    fn fire(&mut self, i: usize, t: f64, x: &mut [f64]) {
        events::fire(self.sys, i, t, (self.p, &[], &mut self.u), x);
    }
}

/// The model together with its variational equations dS/dt = J_y S + J_α (for parameter
/// columns), on x = [y; S row by row]. J_y S + J_α comes from [`JacobianProducts`]: the
/// model evaluated with vector dual numbers seeded by the rows of S and by unit seeds for
/// the parameter columns, without forming a Jacobian and without allocating. Systems with
/// hand-written Jacobians use them instead.
pub struct SensitivityRhs<'a, S> {
    sys: &'a S,
    p: &'a [f64],
    wrt: &'a [Wrt],
    u: Vec<f64>,
    /// J_y S + J_α with the unit parameter directions of the parameter columns.
    products: JacobianProducts,
    jy: DMatrix<f64>,
    jp: DMatrix<f64>,
    /// Allocated on the first implicit step.
    implicit: Option<Box<AugmentedMatrix>>,
    /// The switches that move with a parameter ([`System::moving_switches`]).
    moving: Vec<(f64, usize, f64)>,
    /// The atol factor of every column (see [`Ivp::weighted`]).
    atol: Vec<f64>,
    /// Without columns: the work space of the system's own sparse Jacobian, from whose
    /// (compiled) evaluation f is read, as [`ModelRhs`] does.
    work: Vec<f64>,
    /// The state events fired so far, in order: (event, τ, the state before it).
    fired: Vec<Fired>,
    structure: Structure,
    /// The states' sizes for their floors ([`Ivp::sized`]).
    sizes: Option<&'a [f64]>,
}

impl<'a, S: System> SensitivityRhs<'a, S> {
    /// The augmented right-hand side of `sys` at parameters `p`, columns `wrt`.
    pub fn new(sys: &'a S, p: &'a [f64], wrt: &'a [Wrt]) -> Self {
        let sig = sys.signature();
        let (n, np) = (sig.n_states(), sig.n_parameters());
        let analytic = sys.analytic_jacobians();
        // Jacobian storage only for systems that supply them by hand.
        let (jn, jnp) = if analytic { (n, np) } else { (0, 0) };
        Self {
            sys,
            p,
            wrt,
            u: vec![0.0; sig.n_inputs()],
            products: JacobianProducts::new(
                n,
                p,
                &parameter_seeds(np, wrt),
                n,
                if analytic { 0 } else { wrt.len() },
            ),
            jy: DMatrix::zeros(jn, jn),
            jp: DMatrix::zeros(jn, jnp),
            implicit: None,
            moving: sys.moving_switches(p),
            fired: Vec::new(),
            atol: vec![1.0; wrt.len()],
            work: functions_alone(sys)
                .filter(|_| wrt.is_empty())
                .map(|f| f.workspace())
                .unwrap_or_default(),
            structure: Structure::of(sys),
            sizes: None,
        }
    }

    /// The states' sizes for their absolute floors (see [`Ivp::sized`]).
    pub fn sized(self, sizes: Option<&'a [f64]>) -> Self {
        Self { sizes, ..self }
    }

    /// Column j's error controlled as w_j·S_j: the atol factor 1/w_j (1 for a weight that
    /// is 0 or not finite).
    pub fn weighted(mut self, weights: &[f64]) -> Self {
        assert_eq!(weights.len(), self.wrt.len(), "a weight per sensitivity column");
        for (c, &w) in self.atol.iter_mut().zip(weights) {
            let w = w.abs();
            *c = if w > 0.0 && w.is_finite() { 1.0 / w } else { 1.0 };
        }
        self
    }

    /// The initial augmented state [y0; S(t0)] for these columns.
    pub fn initial_state(&self, y0: &[f64]) -> Vec<f64> {
        let n = y0.len();
        let mut x = vec![0.0; n * (1 + self.wrt.len())];
        x[..n].copy_from_slice(y0);
        let k = self.wrt.len();
        for (j, w) in self.wrt.iter().enumerate() {
            if let Wrt::InitialValue(i) = *w {
                x[n + i * k + j] = 1.0;
            }
        }
        x
    }
}

impl<S: System> Rhs for SensitivityRhs<'_, S> {
    fn dim(&self) -> usize {
        self.sys.signature().n_states() * (1 + self.wrt.len())
    }

    fn column_atol(&self) -> Option<&[f64]> {
        Some(&self.atol)
    }

    fn state_sizes(&self) -> Option<&[f64]> {
        self.sizes
    }

    // The sensitivities' right-hand side J·S + ∂g/∂α is as free of t as g is.
    fn autonomous(&self) -> bool {
        self.sys.autonomous()
    }

    /// f with its Jacobian's entries, then their products with the k columns; the implicit
    /// matrix's own estimate.
    fn costs(&self) -> Costs {
        let (s, k) = (&self.structure, self.wrt.len() as u64);
        let products = if k == 0 { 0 } else { s.state_entries * k + s.parameter_entries };
        let (factor, solve) = match &self.implicit {
            Some(matrix) => matrix.costs(s, k),
            None => s.dense_implicit(),
        };
        let eval = if k == 0 { s.values } else { s.linearized + products };
        Costs { eval, factor, solve }
    }

    fn eval(&mut self, t: f64, side: Side, x: &[f64], dx: &mut [f64]) {
        let n = self.sys.signature().n_states();
        self.sys.input_values(t, side, &mut self.u);
        if self.wrt.is_empty() {
            rhs_of(self.sys, (t, x, self.p, &self.u), &mut self.work, dx);
            return;
        }
        let (y, s) = x.split_at(n);
        let (dy, ds) = dx.split_at_mut(n);
        if !self.sys.analytic_jacobians() {
            let args = (t, y, self.u.as_slice());
            self.products.eval(self.sys, Function::Rhs, args, s, dy, ds);
            return;
        }
        self.sys.rhs(t, y, self.p, &self.u, dy);
        self.sys.jacobians(t, y, self.p, &self.u, &mut self.jy, &mut self.jp);
        let k = self.wrt.len();
        for (j, w) in self.wrt.iter().enumerate() {
            for i in 0..n {
                let mut v = (0..n).map(|l| self.jy[(i, l)] * s[l * k + j]).sum::<f64>();
                if let Wrt::Parameter(q) = *w {
                    v += self.jp[(i, q)];
                }
                ds[i * k + j] = v;
            }
        }
    }

    fn states(&self) -> usize {
        self.sys.signature().n_states()
    }

    fn describe(&self, i: usize) -> String {
        let sig = self.sys.signature();
        let n = sig.n_states();
        if i < n {
            return format!("state {}", sig.states()[i]);
        }
        let k = self.wrt.len();
        let (row, j) = ((i - n) / k, (i - n) % k);
        format!("sensitivity ∂{}/∂{}", sig.states()[row], wrt_name(sig, self.wrt[j]))
    }

    fn factor(
        &mut self,
        t: f64,
        side: Side,
        x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        let (sys, p) = (self.sys, self.p);
        let matrix =
            self.implicit.get_or_insert_with(|| Box::new(AugmentedMatrix::new(sys, p, self.wrt)));
        sys.input_values(t, side, &mut self.u);
        matrix.factor(sys, (t, x, &self.u), inv_gamma_h)
    }

    fn solve(&mut self, r: &mut [f64]) {
        if let Some(matrix) = &mut self.implicit {
            matrix.solve(self.sys, self.wrt, r);
        }
    }

    fn n_events(&self) -> usize {
        self.sys.n_events()
    }

    fn event_conditions(&mut self, t: f64, y: &[f64], c: &mut [f64]) {
        events::conditions(self.sys, t, y, self.p, c);
    }

    fn fire(&mut self, i: usize, t: f64, x: &mut [f64]) {
        let n = self.sys.signature().n_states();
        self.fired.push(Fired { event: i, tau: t, before: x[..n].to_vec() });
        events::fire(self.sys, i, t, (self.p, self.wrt, &mut self.u), x);
    }

    /// At a switch τ(α_q) the column of α_q jumps by (g₋ − g₊)·∂τ/∂α_q, g₋ the right-hand
    /// side on the side of smaller t (`dir` turns it round going backwards).
    fn cross(&mut self, t: f64, x: &mut [f64], dir: f64) {
        if !self.moving.iter().any(|m| m.0.to_bits() == t.to_bits()) {
            return;
        }
        let (n, k) = (self.sys.signature().n_states(), self.wrt.len());
        let (y, s) = x.split_at_mut(n);
        let jump = rhs_jump(self.sys, t, y, self.p, &mut self.u);
        for &(_, q, slope) in self.moving.iter().filter(|m| m.0.to_bits() == t.to_bits()) {
            let Some(j) = self.wrt.iter().position(|w| *w == Wrt::Parameter(q)) else { continue };
            for i in 0..n {
                s[i * k + j] += dir * jump[i] * slope;
            }
        }
    }
}

impl<'a, S: System> Ivp<'a, S> {
    /// The problem y' = g(t, y, α, u(t)), y(t0) = y0.
    pub fn new(system: &'a S, t0: f64, y0: &'a [f64], p: &'a [f64]) -> Self {
        Self { system, t0, y0, p, weights: None, sizes: None }
    }

    /// Error control of the sensitivities in the units they are used in: column j of
    /// [`solve_sensitivities`](Self::solve_sensitivities), S_j = ∂y/∂(slot j), is controlled
    /// as w_j·S_j, entry by entry to max(atol/w_j, rtol·m_j) + rtol·|S_ij| with m_j the
    /// column's largest entry (the states to atol + rtol·|y_i|). For a fit in ln p, w_j = p:
    /// the fit uses p·∂y/∂p, and its absolute floor is atol in those units. A weight that is
    /// 0 or not finite counts as 1. Without it (the default) every column has w_j = 1; the
    /// column-relative floor rtol·m_j holds either way.
    pub fn weighted(self, weights: &'a [f64]) -> Self {
        Self { weights: Some(weights), ..self }
    }

    /// Each state's absolute tolerance at most STATE_FLOOR·rtol·|size_i| (its sensitivities
    /// alike): for states whose initial value is the model's own, `sizes` their initial
    /// values, 0 for a state whose initial value was computed (a steady state, where a
    /// value of 1e-20 may be rounding, which no floor can hold). An absolute tolerance above
    /// a state's size controls nothing of it. Without it (the default) every state is held
    /// to atol. One size per state.
    pub fn sized(self, sizes: &'a [f64]) -> Self {
        Self { sizes: Some(sizes), ..self }
    }

    pub(crate) fn check(&self) -> Result<(), OdeError> {
        let sig = self.system.signature();
        if self.y0.len() != sig.n_states() {
            return Err(OdeError::Dimension {
                what: "initial state",
                actual: self.y0.len(),
                expected: sig.n_states(),
            });
        }
        if let Some(sizes) = self.sizes.filter(|s| s.len() != sig.n_states()) {
            return Err(OdeError::Dimension {
                what: "state sizes",
                actual: sizes.len(),
                expected: sig.n_states(),
            });
        }
        if self.p.len() != sig.n_parameters() {
            return Err(OdeError::Dimension {
                what: "parameter vector",
                actual: self.p.len(),
                expected: sig.n_parameters(),
            });
        }
        if let Some(k) = self.p.iter().position(|v| !v.is_finite()) {
            return Err(OdeError::InvalidInput {
                what: format!("parameter {}", sig.parameters()[k]),
                value: self.p[k],
            });
        }
        Ok(())
    }

    /// Checks that the weights given to [`weighted`](Self::weighted), if any, are one per
    /// column of `wrt` (an empty list panicked inside the integration).
    fn check_weights(&self, wrt: &[Wrt]) -> Result<(), OdeError> {
        match self.weights {
            Some(w) if w.len() != wrt.len() => Err(OdeError::Dimension {
                what: "the sensitivity columns' weights",
                actual: w.len(),
                expected: wrt.len(),
            }),
            _ => Ok(()),
        }
    }

    /// The state at `times` (non-decreasing; any side of t0).
    pub fn solve(&self, integrator: &Integrator, times: &[f64]) -> Result<Trajectory, OdeError> {
        self.check()?;
        let n = self.y0.len();
        let mut rhs = ModelRhs::new(self.system, self.p).sized(self.sizes);
        let mut values = vec![0.0; times.len() * n];
        let counts =
            sample(integrator, &mut rhs, self.t0, self.y0, times, &self.stops(), &mut values)?;
        Ok(Trajectory { times: times.to_vec(), n, values, counts })
    }

    /// The state and the sensitivities ∂y/∂z for the columns `wrt` at `times`.
    pub fn solve_sensitivities(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        times: &[f64],
    ) -> Result<SensitivityTrajectory, OdeError> {
        self.check()?;
        check_wrt(self.system, wrt)?;
        self.check_weights(wrt)?;
        let n = self.y0.len();
        // Columns of parameters the right-hand side does not depend on are zero for all t
        // (their initial values are 0): only the others are integrated.
        let moving = moving_columns(self.system, self.p, wrt);
        let integrated: Vec<Wrt> = moving.iter().map(|&j| wrt[j]).collect();
        let mut rhs = SensitivityRhs::new(self.system, self.p, &integrated).sized(self.sizes);
        if let Some(weights) = self.weights {
            let moving_weights: Vec<f64> = moving.iter().map(|&j| weights[j]).collect();
            rhs = rhs.weighted(&moving_weights);
        }
        let x0 = rhs.initial_state(self.y0);
        let mut data = vec![0.0; times.len() * x0.len()];
        let counts = sample(integrator, &mut rhs, self.t0, &x0, times, &self.stops(), &mut data)?;
        let k = wrt.len();
        if moving.len() < k {
            data = widened(&data, n, &moving, k);
        }
        Ok(SensitivityTrajectory { times: times.to_vec(), n, k, data, counts })
    }

    /// As [`solve_sensitivities`](Self::solve_sensitivities), from the sensitivities `s0`
    /// at t0 (n × `wrt.len()`, row by row) in place of the unit columns of the initial values:
    /// an integration continued from where another stopped. Every column is integrated.
    pub fn solve_sensitivities_from(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        s0: &[f64],
        times: &[f64],
    ) -> Result<SensitivityTrajectory, OdeError> {
        self.check()?;
        check_wrt(self.system, wrt)?;
        self.check_weights(wrt)?;
        let (n, k) = (self.y0.len(), wrt.len());
        if s0.len() != n * k {
            return Err(OdeError::Dimension { what: "s0", actual: s0.len(), expected: n * k });
        }
        let mut rhs = SensitivityRhs::new(self.system, self.p, wrt).sized(self.sizes);
        if let Some(weights) = self.weights {
            rhs = rhs.weighted(weights);
        }
        let x0: Vec<f64> = self.y0.iter().chain(s0).copied().collect();
        let mut data = vec![0.0; times.len() * x0.len()];
        let counts = sample(integrator, &mut rhs, self.t0, &x0, times, &self.stops(), &mut data)?;
        Ok(SensitivityTrajectory { times: times.to_vec(), n, k, data, counts })
    }

    /// Integrates the state and the sensitivities `wrt` from t0 to `t_hi` and from t0 back to
    /// `t_lo`, handing every accepted step's interpolant of [y; S] to `on_step` (forward steps
    /// first).
    pub fn integrate_steps(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        span: (f64, f64),
        on_step: impl FnMut(&Interpolant),
    ) -> Result<Counts, OdeError> {
        self.integrate_logged(integrator, wrt, span, on_step).map(|(counts, _)| counts)
    }

    /// [`integrate_steps`](Self::integrate_steps), with the state events fired: (event, τ,
    /// the state before it), in the order they fired.
    fn integrate_logged(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        (t_lo, t_hi): (f64, f64),
        mut on_step: impl FnMut(&Interpolant),
    ) -> Result<(Counts, Vec<Fired>), OdeError> {
        self.check()?;
        check_wrt(self.system, wrt)?;
        let mut rhs = SensitivityRhs::new(self.system, self.p, wrt).sized(self.sizes);
        let x0 = rhs.initial_state(self.y0);
        let stops = self.stops();
        let mut counts = Counts::default();
        if t_hi > self.t0 {
            counts +=
                integrate(integrator, &mut rhs, (self.t0, &x0), t_hi, &stops, &mut on_step)?.0;
        }
        if t_lo < self.t0 {
            counts +=
                integrate(integrator, &mut rhs, (self.t0, &x0), t_lo, &stops, &mut on_step)?.0;
        }
        Ok((counts, rhs.fired))
    }

    /// The whole solution (with the sensitivities `wrt`, possibly none) on [t_lo, t_hi] as a
    /// function of time.
    pub fn dense(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        span: (f64, f64),
    ) -> Result<(DenseSolution, Counts), OdeError> {
        let mut solution = DenseSolution::new(self.y0.len() * (1 + wrt.len()));
        let (counts, fired) = self.integrate_logged(integrator, wrt, span, |s| solution.push(s))?;
        solution.finish();
        solution.fired = fired;
        Ok((solution, counts))
    }

    /// The discontinuities and the switches at this problem's parameters, ascending.
    fn stops(&self) -> Vec<f64> {
        stops(self.system, self.p)
    }
}

/// g₋ − g₊: the right-hand side of `system` at (y, `p`) just before the stop t minus just
/// after it (the inputs, in `u`, from each side), the jump a switch at t makes. Allocates;
/// it runs at stops only.
pub fn rhs_jump<S: System>(system: &S, t: f64, y: &[f64], p: &[f64], u: &mut [f64]) -> Vec<f64> {
    let n = y.len();
    let (mut before, mut after) = (vec![0.0; n], vec![0.0; n]);
    for (g, (at, side)) in
        [(&mut before, (t.next_down(), Side::Before)), (&mut after, (t.next_up(), Side::After))]
    {
        system.input_values(at, side, u);
        system.rhs(at, y, p, u, g);
    }
    for (b, a) in before.iter_mut().zip(&after) {
        *b -= a;
    }
    before
}

/// Where an integration of `system` at the parameters `p` stops: the inputs'
/// [discontinuities](System::discontinuities) and the right-hand side's
/// [switches](System::switches), ascending.
pub fn stops<S: System>(system: &S, p: &[f64]) -> Vec<f64> {
    let mut stops = system.discontinuities().to_vec();
    let switches = system.switches(p);
    if !switches.is_empty() {
        stops.extend(switches.into_iter().filter(|t| t.is_finite()));
        stops.sort_by(f64::total_cmp);
        stops.dedup();
    }
    stops
}

pub(crate) fn check_wrt<S: System>(sys: &S, wrt: &[Wrt]) -> Result<(), OdeError> {
    let sig = sys.signature();
    for w in wrt {
        let (ok, what) = match *w {
            Wrt::InitialValue(i) => (i < sig.n_states(), "initial-value column"),
            Wrt::Parameter(k) => (k < sig.n_parameters(), "parameter column"),
        };
        if !ok {
            return Err(OdeError::InvalidSetup(format!("{what} {w:?} is out of range")));
        }
    }
    Ok(())
}

/// Checks that times are finite and non-decreasing.
pub fn check_times(times: &[f64]) -> Result<(), OdeError> {
    if let Some(i) = times.iter().position(|t| !t.is_finite()) {
        return Err(OdeError::InvalidInput { what: format!("output time {i}"), value: times[i] });
    }
    if let Some(i) = times.windows(2).position(|w| w[1] < w[0]) {
        return Err(OdeError::TimesOutOfOrder {
            index: i + 1,
            previous: times[i],
            time: times[i + 1],
        });
    }
    Ok(())
}

/// Integrates from (t0, x0) forward to the last time after t0 and backward to the first time
/// before it, writing x(t_m) into row m of `out` (rows of length `x0.len()`).
pub(crate) fn sample<R: Rhs>(
    integrator: &Integrator,
    rhs: &mut R,
    t0: f64,
    x0: &[f64],
    times: &[f64],
    stops: &[f64],
    out: &mut [f64],
) -> Result<Counts, OdeError> {
    check_times(times)?;
    let w = x0.len();
    let mut counts = Counts::default();
    let before = times.partition_point(|&t| t < t0);
    let at = times.partition_point(|&t| t <= t0);
    for m in before..at {
        out[m * w..(m + 1) * w].copy_from_slice(x0);
    }
    if at < times.len() {
        // The next output time, shared by the step filter and the callback.
        let next = std::cell::Cell::new(at);
        let t_last = times[times.len() - 1];
        let wants = |_: f64, t_end: f64| times.get(next.get()).is_some_and(|&t| t <= t_end);
        let (c, x_end) =
            integrate_selected(integrator, rhs, (t0, x0), t_last, stops, wants, |s| {
                let mut m = next.get();
                while m < times.len() && times[m] <= s.t_end() {
                    s.eval(times[m], &mut out[m * w..(m + 1) * w]);
                    m += 1;
                }
                next.set(m);
            })?;
        let next = next.get();
        counts += c;
        // Only times equal to the end can remain: the integration stops exactly on it.
        for m in next..times.len() {
            out[m * w..(m + 1) * w].copy_from_slice(&x_end);
        }
    }
    if before > 0 {
        let next = std::cell::Cell::new(before);
        let wants = |_: f64, t_end: f64| next.get() > 0 && times[next.get() - 1] >= t_end;
        let (c, x_end) =
            integrate_selected(integrator, rhs, (t0, x0), times[0], stops, wants, |s| {
                let mut m = next.get();
                while m > 0 && times[m - 1] >= s.t_end() {
                    m -= 1;
                    s.eval(times[m], &mut out[m * w..(m + 1) * w]);
                }
                next.set(m);
            })?;
        let next = next.get();
        counts += c;
        for m in 0..next {
            out[m * w..(m + 1) * w].copy_from_slice(&x_end);
        }
    }
    Ok(counts)
}

/// Values and gradients of observables: h_o(t, y, α, u) and ∂h_o/∂z = ∂h_o/∂y S + ∂h_o/∂α
/// (parameter columns), exact by dual numbers for outputs that are not states.
pub struct ObservableGradient<'a, S> {
    sys: &'a S,
    u: Vec<f64>,
    products: JacobianProducts,
    h: Vec<f64>,
    dh: Vec<f64>,
}

impl<'a, S: System> ObservableGradient<'a, S> {
    /// For `sys` at parameters `p`, sensitivity columns `wrt`.
    pub fn new(sys: &'a S, p: &'a [f64], wrt: &'a [Wrt]) -> Self {
        let sig = sys.signature();
        let (n, np, no) = (sig.n_states(), sig.n_parameters(), sig.outputs().len());
        Self {
            sys,
            u: vec![0.0; sig.n_inputs()],
            products: JacobianProducts::new(
                n,
                p,
                &parameter_seeds(np, wrt),
                no,
                if no > 0 { wrt.len() } else { 0 },
            ),
            h: vec![0.0; no],
            dh: vec![0.0; no * wrt.len()],
        }
    }

    /// The value of `obs` at (t, y) and its gradient row ∂h/∂z in `grad` (length k), given
    /// S(t) row by row in `s`.
    pub fn eval(&mut self, t: f64, y: &[f64], s: &[f64], obs: Observable, grad: &mut [f64]) -> f64 {
        let k = grad.len();
        match obs {
            Observable::State(i) => {
                grad.copy_from_slice(&s[i * k..(i + 1) * k]);
                y[i]
            }
            Observable::Output(o) => {
                self.sys.input_values(t, Side::After, &mut self.u);
                let args = (t, y, self.u.as_slice());
                self.products.eval(self.sys, Function::Outputs, args, s, &mut self.h, &mut self.dh);
                grad.copy_from_slice(&self.dh[o * k..(o + 1) * k]);
                self.h[o]
            }
        }
    }
}

/// The columns of `wrt` whose sensitivities can be nonzero: initial values, parameters the
/// right-hand side depends on (by its sparse Jacobian's pattern; all of them for a system
/// without one), and parameters that move a switch (at `p`). A parameter that enters only
/// the outputs, a σ or nothing has S = 0 for all t.
fn moving_columns<S: System>(system: &S, p: &[f64], wrt: &[Wrt]) -> Vec<usize> {
    let n = system.signature().n_states();
    let Some(sparse) = system.sparse_jacobian(Function::Rhs) else {
        return (0..wrt.len()).collect();
    };
    // An event's condition or reset may depend on any parameter.
    if system.n_events() > 0 {
        return (0..wrt.len()).collect();
    }
    let mut enters = vec![false; system.signature().n_parameters()];
    for &(_, c) in sparse.pattern() {
        if let Some(q) = (c as usize).checked_sub(n) {
            enters[q] = true;
        }
    }
    for (_, q, _) in system.moving_switches(p) {
        enters[q] = true;
    }
    (0..wrt.len())
        .filter(|&j| match wrt[j] {
            Wrt::Parameter(q) => enters[q],
            _ => true,
        })
        .collect()
}

/// Per time, [y; S] with S's columns `moving` of k (row by row), from the integrated
/// [y; S_moving]: the other columns zero.
fn widened(data: &[f64], n: usize, moving: &[usize], k: usize) -> Vec<f64> {
    let (narrow, wide) = (n * (1 + moving.len()), n * (1 + k));
    let times = data.len() / narrow;
    let mut out = vec![0.0; times * wide];
    for (from, to) in data.chunks_exact(narrow).zip(out.chunks_exact_mut(wide)) {
        to[..n].copy_from_slice(&from[..n]);
        for i in 0..n {
            for (c, &j) in moving.iter().enumerate() {
                to[n + i * k + j] = from[n + i * moving.len() + c];
            }
        }
    }
    out
}
