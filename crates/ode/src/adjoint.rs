//! Adjoint gradients: G_j = Σ_m c_mᵀ S_j(t_m) for every sensitivity column j at once, by one
//! backward integration of n + k values instead of the forward integration of n·(1 + k).
//!
//! A weighted sum of the sensitivities at the sample times is what the gradient of a
//! likelihood needs (c_m = ∂NLL/∂y(t_m)). With λ the adjoint state, the solution of
//!
//! dλ/dt = −J_yᵀ λ   backward from λ = 0 after the last sample, λ jumping by c_m at t_m,
//!
//! d(λᵀS_j)/dt = λᵀ(J_y S_j + ∂g/∂α_j) − λᵀJ_y S_j = λᵀ ∂g/∂α_j between the samples, so that
//!
//! G_j = λ(t0)ᵀ S_j(t0) + ∫_{t0}^{T} λᵀ ∂g/∂α_j dt + Σ_τ λ(τ)ᵀ(g₋ − g₊) ∂τ/∂α_j,
//!
//! the last sum over the switches τ(α) that move with a parameter, where S_j jumps by
//! (g₋ − g₊) ∂τ/∂α_j (see [`System::moving_switches`]). The integral is carried as k more
//! components μ, dμ/dt = −(∂g/∂α)ᵀλ, integrated backward with λ under the same error
//! control. J_y and ∂g/∂α are read at the forward solution y(t), interpolated from its
//! accepted steps (a [`DenseSolution`]).
//!
//! The error control measures λ as one vector and μ as another
//! ([`Rhs::errors_as_vectors`]): an entry is held to rtol of its vector's largest, or atol
//! where that is larger, as a forward sensitivity is held to rtol of its column. An error
//! δλ at t moves the gradient by δλᵀS(t), so λ's small entries matter in proportion to its
//! large ones, not to atol; held each to atol + rtol·|λ_i|, they set the backward steps
//! (Boehm's gradient took 1 630 steps forward and backward, 1 161 now, against the forward
//! sensitivities' 207). The backward steps run across the ends of the forward steps, where
//! the interpolated J(y(t)) is continuous but its derivatives are not: stopping at each one
//! held the backward integration to at least the forward's count of steps (Laske: 21 883
//! steps then, 11 722 now, against 7 166 forward), for gradients at rtol 1e-8 that were 10
//! to 50 times closer to a tight reference on Fujita, Zheng and Smith, and within a factor 5
//! elsewhere (docs/petab.md, "Adjoint gradients beside forward sensitivities").
//!
//! The backward integration runs from each sample time to the one before in time local to
//! the sample (see [`Local`]): a jump of λ sets off the system's fast modes, which only steps
//! shorter than the resolution of t far from 0 may resolve.
//!
//! The implicit steps solve with E = I/(γh) + J_yᵀ (h < 0: the transpose of the forward
//! problem's matrix) through the factors of its transpose, sparse in the same way for a
//! large system with a sparse Jacobian; the μ block is solved by substitution.
//!
//! A state event fired at τ (the forward solution records each one with the state y⁻
//! before it) maps the sensitivities as S⁺ = M S⁻ + N ([`events::fire`](crate::events)):
//! going back through τ, λ becomes Mᵀλ⁺ and μ gains Nᵀλ⁺, J_y read at y(τ⁻) below τ and at
//! y(τ⁺) above it. An event within the time's resolution of t0 or of the last sample is
//! refused (the caller integrates forward).

use nalgebra::DMatrix;

use crate::counts::{Costs, Counts, dense_lu};
use crate::driver::{integrate_part, resolution};
use crate::error::OdeError;
use crate::events::Reset;
use crate::implicit::{Factors, Structure};
use crate::interpolant::DenseSolution;
use crate::ivp::{Ivp, Trajectory, check_times, check_wrt, rhs_jump, stops};
use crate::jacobian::JacobianProducts;
use crate::lu::FactorError;
use crate::options::Integrator;
use crate::rhs::Rhs;
use crate::signal::Side;
use crate::system::{Function, System};
use crate::wrt::Wrt;

impl<S: System> Ivp<'_, S> {
    /// The state on [t0, the last of `times`] as a function of time (no sensitivities), and
    /// its values at `times` (non-decreasing, none before t0): the forward half of
    /// [`adjoint`](Self::adjoint).
    pub fn solve_dense(
        &self,
        integrator: &Integrator,
        times: &[f64],
    ) -> Result<(Trajectory, DenseSolution), OdeError> {
        check_times(times)?;
        let n = self.y0.len();
        if let Some(&t) = times.first().filter(|&&t| t < self.t0) {
            return Err(OdeError::InvalidSetup(format!(
                "an adjoint integration starts at t0 = {}; a sample at t = {t} is before it",
                self.t0
            )));
        }
        let t_last = times.last().copied().unwrap_or(self.t0);
        let (dense, counts) = self.dense(integrator, &[], (self.t0, t_last))?;
        let mut values = vec![0.0; times.len() * n];
        let mut hint = 0;
        for (m, &t) in times.iter().enumerate() {
            let out = &mut values[m * n..(m + 1) * n];
            if !dense.eval_hinted(t, &mut hint, out) {
                // Only t0 itself is outside an empty solution.
                out.copy_from_slice(self.y0);
            }
        }
        Ok((Trajectory { times: times.to_vec(), n, values, counts }, dense))
    }

    /// G_j = Σ_m c_mᵀ S_j(t_m) for the sensitivity columns `wrt`, by a backward (adjoint)
    /// integration along `forward` (from [`solve_dense`](Self::solve_dense) at the same
    /// times). `seeds` holds c_m, n values per time of `times` (non-decreasing, none before
    /// t0); `s0` is S(t0) (n × k, row by row), by default the unit columns of the initial
    /// values and zero for the parameters. Equal to the forward sensitivities' sum to the
    /// integration's tolerance; the work done is returned with it.
    pub fn adjoint(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        s0: Option<&[f64]>,
        (forward, times, seeds): (&DenseSolution, &[f64], &[f64]),
    ) -> Result<(Vec<f64>, Counts), OdeError> {
        self.check()?;
        check_wrt(self.system, wrt)?;
        check_times(times)?;
        let (n, k) = (self.y0.len(), wrt.len());
        let setup = |what: String| Err(OdeError::InvalidSetup(what));
        if seeds.len() != times.len() * n {
            return setup(format!(
                "{} adjoint seeds for {} times × {n} states",
                seeds.len(),
                times.len()
            ));
        }
        if s0.is_some_and(|s| s.len() != n * k) || forward.dim() != n {
            return setup(
                "an adjoint's initial sensitivities or forward solution of the wrong size".into(),
            );
        }
        if let Some(&t) = times.first().filter(|&&t| t < self.t0) {
            return setup(format!("an adjoint sample at t = {t}, before t0 = {}", self.t0));
        }
        if let Some(i) = seeds.iter().position(|c| !c.is_finite()) {
            let t = times[i / n];
            return Err(OdeError::NonFinite {
                t,
                what: format!("the adjoint seed of state {}", i % n),
            });
        }
        let scale = seeds.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let mut counts = Counts::default();
        if scale == 0.0 {
            return Ok((vec![0.0; k], counts));
        }
        let t_end = times[times.len() - 1];
        if let Some(tau) = forward.event_times().find(|&tau| {
            tau - self.t0 <= resolution(tau) || t_end - tau <= resolution(t_end) || tau > t_end
        }) {
            return setup(format!(
                "adjoint gradients through a state event at the first or last time ({tau})"
            ));
        }
        let mut rhs = AdjointRhs::new(self, wrt, forward, (times, seeds, 1.0 / scale));
        let mut x = vec![0.0; n + k];
        rhs.add_seeds(t_end, &mut x);
        if t_end - self.t0 > resolution(t_end) {
            // Stop where the forward solution did (its discontinuities and events) and at
            // every sample time, where λ jumps; not where the forward steps end (see the
            // module's docs).
            let mut inner: Vec<f64> = stops(self.system, self.p);
            inner.extend(forward.event_times());
            inner.sort_by(f64::total_cmp);
            // A forward step that ended a few ulps from a stop leaves no room for a step in
            // between: one of the two is enough.
            inner.dedup_by(|later, kept| *later - *kept <= resolution(*later));
            let mut samples: Vec<f64> =
                times.iter().copied().filter(|&t| t > self.t0 && t < t_end).collect();
            samples.dedup_by(|later, kept| *later - *kept <= resolution(*later));
            // From each sample back to the one before it (t0 last), in time local to the
            // sample (see [`Local`]), each part from Hairer's first step: λ has just jumped,
            // and a step carried over from before the jump can cross the fast modes it sets
            // off with an error its estimate does not see (on `Tied` in the tests, 4e-6 of
            // the gradient at rtol 1e-8). In local time a first step of 1e-15 (Rahman's, from
            // quadratures that start at 0 with derivatives of 1e11) costs a few steps more.
            // The automatic choice's scheme carries from part to part: λ jumps at a sample,
            // the Jacobian −J_yᵀ along the forward solution does not.
            let (mut from, mut stiff) = (t_end, false);
            for to in samples.into_iter().rev().chain([self.t0]) {
                let mut local = Local::new(&mut rhs, from, to, &inner);
                let local_stops = local.local.clone();
                let (c, x_end) = integrate_part(
                    integrator,
                    &mut local,
                    (0.0, &x),
                    to - from,
                    &local_stops,
                    &mut stiff,
                )?;
                counts += c;
                x = x_end;
                if to > self.t0 {
                    rhs.cross(to, &mut x, -1.0);
                }
                from = to;
            }
            counts.integrations = 1;
        }
        rhs.add_seeds(self.t0, &mut x);
        let (lambda, mu) = x.split_at(n);
        let gradient = (0..k)
            .map(|j| {
                let initial: f64 = match s0 {
                    Some(s0) => (0..n).map(|i| lambda[i] * s0[i * k + j]).sum(),
                    None => match wrt[j] {
                        Wrt::InitialValue(i) => lambda[i],
                        Wrt::Parameter(_) => 0.0,
                    },
                };
                scale * (mu[j] + initial)
            })
            .collect();
        Ok((gradient, counts))
    }
}

/// [∂g/∂y | ∂g/∂α] at a point, entry by entry.
struct Entries {
    /// (row i, column c): c < n is state c, n + q parameter q.
    pattern: Vec<(u32, u32)>,
    values: Vec<f64>,
    source: Source,
}

/// Where the entries come from.
enum Source {
    /// The system's own sparse Jacobian (a model file's compiled one), with its work space.
    Sparse(Vec<f64>),
    /// Hand-written Jacobians ([`System::jacobians`]).
    Analytic(DMatrix<f64>, DMatrix<f64>),
    /// Dual numbers seeded with the identity over the states and the parameters.
    Dual { products: Box<JacobianProducts>, seeds: Vec<f64>, value: Vec<f64> },
}

impl Entries {
    fn new<S: System>(sys: &S, p: &[f64]) -> Self {
        let sig = sys.signature();
        let (n, np) = (sig.n_states(), sig.n_parameters());
        let width = n + np;
        let every: Vec<(u32, u32)> =
            (0..n as u32).flat_map(|i| (0..width as u32).map(move |c| (i, c))).collect();
        let source = if sys.analytic_jacobians() {
            Source::Analytic(DMatrix::zeros(n, n), DMatrix::zeros(n, np))
        } else if let Some(jacobian) = sys.sparse_jacobian(Function::Rhs) {
            let pattern = jacobian.pattern().to_vec();
            let values = vec![0.0; pattern.len()];
            return Self { pattern, values, source: Source::Sparse(jacobian.workspace()) };
        } else {
            let mut vp = vec![0.0; np * width];
            for q in 0..np {
                vp[q * width + n + q] = 1.0;
            }
            let mut seeds = vec![0.0; n * width];
            for i in 0..n {
                seeds[i * width + i] = 1.0;
            }
            let products = Box::new(JacobianProducts::new(n, p, &vp, n, width));
            Source::Dual { products, seeds, value: vec![0.0; n] }
        };
        Self { values: vec![0.0; every.len()], pattern: every, source }
    }

    /// The entries at (t, y) with parameters `p` and inputs `u`.
    fn eval<S: System>(&mut self, sys: &S, (t, y, p, u): (f64, &[f64], &[f64], &[f64])) {
        match &mut self.source {
            Source::Sparse(work) => {
                if let Some(jacobian) = sys.sparse_jacobian(Function::Rhs) {
                    jacobian.eval(t, y, p, u, work);
                    for (v, &at) in self.values.iter_mut().zip(jacobian.entries()) {
                        *v = work[at as usize];
                    }
                }
            }
            Source::Analytic(jy, jp) => {
                sys.jacobians(t, y, p, u, jy, jp);
                let n = y.len();
                for (v, &(i, c)) in self.values.iter_mut().zip(&self.pattern) {
                    let (i, c) = (i as usize, c as usize);
                    *v = if c < n { jy[(i, c)] } else { jp[(i, c - n)] };
                }
            }
            Source::Dual { products, seeds, value } => {
                products.eval(sys, Function::Rhs, (t, y, u), seeds, value, &mut self.values);
            }
        }
    }
}

/// The implicit steps' matrix E_λ = I/(γh) + J_yᵀ, as the factors of its transpose
/// I/(γh) + J_y (J_y's own pattern, whose diagonal pivots hold where the transpose's need
/// not), and J's entries at that point for the μ block.
struct Implicit {
    factors: Factors,
    /// −J_y as the factors read it ([`Factors::places`]), and where each entry of the
    /// pattern goes in it.
    jac: Vec<f64>,
    places: Vec<(usize, usize)>,
    values: Vec<f64>,
    inv_gamma_h: f64,
}

/// x = [λ; μ] and its backward right-hand side [−J_yᵀλ; −(∂g/∂α)ᵀλ] along the forward
/// solution.
struct AdjointRhs<'a, S> {
    sys: &'a S,
    p: &'a [f64],
    forward: &'a DenseSolution,
    hint: usize,
    n: usize,
    k: usize,
    /// The column of each parameter among the k, where it has one.
    column_of: Vec<Option<usize>>,
    /// The Jacobian's entries in its pattern's order, split by what their products feed:
    /// (row i, state column c, entry) for −J_yᵀλ, and (row i, column j among the k, entry)
    /// for −(∂g/∂α)ᵀλ, without the parameters that have no column.
    states: Vec<(u32, u32, u32)>,
    parameters: Vec<(u32, u32, u32)>,
    y: Vec<f64>,
    u: Vec<f64>,
    entries: Entries,
    implicit: Option<Box<Implicit>>,
    /// Where `entries` were last evaluated: the Rosenbrock stages ask again at the same t
    /// (the factorisation's point, stages at t + h).
    evaluated_at: Option<(u64, Side)>,
    /// The sample times, their seeds and the factor they are scaled by.
    times: &'a [f64],
    seeds: &'a [f64],
    scale: f64,
    /// The samples not yet added to λ: the first `pending` (added from the last one down).
    pending: usize,
    moving: Vec<(f64, usize, f64)>,
    /// The state events not yet crossed: the first `events` of the forward solution's.
    events: usize,
    structure: Structure,
}

impl<'a, S: System> AdjointRhs<'a, S> {
    fn new(
        ivp: &Ivp<'a, S>,
        wrt: &[Wrt],
        forward: &'a DenseSolution,
        (times, seeds, scale): (&'a [f64], &'a [f64], f64),
    ) -> Self {
        let sig = ivp.system.signature();
        let mut column_of = vec![None; sig.n_parameters()];
        for (j, w) in wrt.iter().enumerate() {
            if let Wrt::Parameter(q) = *w {
                column_of[q] = Some(j);
            }
        }
        let n = sig.n_states();
        let entries = Entries::new(ivp.system, ivp.p);
        let (mut states, mut parameters) = (Vec::new(), Vec::new());
        for (e, &(i, c)) in entries.pattern.iter().enumerate() {
            match (c as usize).checked_sub(n) {
                None => states.push((i, c, e as u32)),
                Some(q) => {
                    if let Some(j) = column_of[q] {
                        parameters.push((i, j as u32, e as u32));
                    }
                }
            }
        }
        Self {
            sys: ivp.system,
            p: ivp.p,
            forward,
            hint: forward.len().saturating_sub(1),
            n,
            k: wrt.len(),
            column_of,
            states,
            parameters,
            y: ivp.y0.to_vec(),
            u: vec![0.0; sig.n_inputs()],
            entries,
            implicit: None,
            evaluated_at: None,
            times,
            seeds,
            scale,
            pending: times.len(),
            moving: ivp.system.moving_switches(ivp.p),
            events: forward.fired.len(),
            structure: Structure::of(ivp.system),
        }
    }

    /// λ += c_m (scaled) for the samples not yet added at t or after it (within the
    /// resolution of t): where the backward integration reaches them.
    fn add_seeds(&mut self, t: f64, x: &mut [f64]) {
        let n = self.n;
        while self.pending > 0 && self.times[self.pending - 1] >= t - resolution(t) {
            self.pending -= 1;
            let seed = &self.seeds[self.pending * n..(self.pending + 1) * n];
            for (l, c) in x[..n].iter_mut().zip(seed) {
                *l += c * self.scale;
            }
        }
    }

    /// y(t) from the forward solution (NaN outside it, which the integration reports).
    /// y(t) from the forward solution, the limit from `side` where a state event reset it.
    fn state_at(&mut self, t: f64, side: Side) {
        if self.forward.is_empty() || !self.forward.eval_side(t, side, &mut self.hint, &mut self.y)
        {
            self.y.fill(f64::NAN);
        }
    }

    fn jacobian_at(&mut self, t: f64, side: Side) {
        if self.evaluated_at == Some((t.to_bits(), side)) {
            return;
        }
        self.evaluated_at = Some((t.to_bits(), side));
        self.state_at(t, side);
        self.sys.input_values(t, side, &mut self.u);
        self.entries.eval(self.sys, (t, &self.y, self.p, &self.u));
    }
}

impl<S: System> Rhs for AdjointRhs<'_, S> {
    fn dim(&self) -> usize {
        self.n + self.k
    }

    fn states(&self) -> usize {
        self.n
    }

    fn errors_as_vectors(&self) -> bool {
        true
    }

    /// The forward state interpolated, f's program with the Jacobian's entries, and their
    /// products with λ (−J_yᵀλ and −(∂g/∂α)ᵀλ); an implicit step's factors are of J's
    /// transpose, and the μ block is one more product at each solve.
    fn costs(&self) -> Costs {
        let s = &self.structure;
        let entries = s.state_entries + s.parameter_entries;
        let (factor, solve) = match &self.implicit {
            Some(implicit) => implicit.factors.costs(),
            None => dense_lu(s.n),
        };
        Costs {
            eval: 5 * s.n + s.linearized + entries,
            factor: s.n * s.n + factor,
            solve: solve + s.parameter_entries,
        }
    }

    fn describe(&self, i: usize) -> String {
        let sig = self.sys.signature();
        match i.checked_sub(self.n) {
            None => format!("the adjoint of state {}", sig.states()[i]),
            Some(j) => format!("the adjoint quadrature of column {j}"),
        }
    }

    fn eval(&mut self, t: f64, side: Side, x: &[f64], dx: &mut [f64]) {
        self.jacobian_at(t, side);
        let n = self.n;
        let (lambda, (dl, dm)) = (&x[..n], dx.split_at_mut(n));
        dl.fill(0.0);
        dm.fill(0.0);
        // Each of dl and dm takes its terms in the pattern's order, as one pass over it would.
        let values = &self.entries.values;
        for &(i, c, e) in &self.states {
            dl[c as usize] -= values[e as usize] * lambda[i as usize];
        }
        for &(i, j, e) in &self.parameters {
            dm[j as usize] -= values[e as usize] * lambda[i as usize];
        }
    }

    fn factor(
        &mut self,
        t: f64,
        side: Side,
        _x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        self.jacobian_at(t, side);
        let n = self.n;
        let implicit = self.implicit.get_or_insert_with(|| {
            let factors = match (&self.entries.source, self.sys.sparse_jacobian(Function::Rhs)) {
                // Entries from the system's sparse Jacobian are in its pattern, the forward
                // integration's: its plan.
                (Source::Sparse(_), Some(jacobian)) => Factors::of(n, Some(jacobian), 1),
                _ => Factors::new(n, Some(&self.entries.pattern), 1),
            };
            let places = factors.places(
                (self.entries.pattern.iter().enumerate())
                    .map(|(e, &(i, c))| (i as usize, c as usize, e))
                    .filter(|&(_, c, _)| c < n),
            );
            Box::new(Implicit {
                jac: vec![0.0; factors.placed_len()],
                factors,
                places,
                values: vec![0.0; self.entries.values.len()],
                inv_gamma_h,
            })
        });
        for &(e, place) in &implicit.places {
            implicit.jac[place] = -self.entries.values[e];
        }
        implicit.values.copy_from_slice(&self.entries.values);
        implicit.inv_gamma_h = inv_gamma_h;
        implicit.factors.factor(inv_gamma_h, &implicit.jac)
    }

    /// E = [[I/(γh) + J_yᵀ, 0], [(∂g/∂α)ᵀ, I/(γh)]]: λ's block by the factors, then μ's by
    /// substitution.
    fn solve(&mut self, r: &mut [f64]) {
        let Some(implicit) = &mut self.implicit else { return };
        let n = self.n;
        let (ra, rb) = r.split_at_mut(n);
        implicit.factors.solve_transposed(ra);
        for &(i, j, e) in &self.parameters {
            rb[j as usize] -= implicit.values[e as usize] * ra[i as usize];
        }
        for b in rb {
            *b /= implicit.inv_gamma_h;
        }
    }

    /// At a switch that moves with a parameter, μ_j gains λᵀ(g₋ − g₊) ∂τ/∂α_j (λ from the
    /// side after τ: a sample at τ sees the state before the jump); then the samples at t
    /// join λ.
    fn cross(&mut self, t: f64, x: &mut [f64], _dir: f64) {
        let n = self.n;
        while self.events > 0
            && (self.forward.fired[self.events - 1].tau - t).abs() <= resolution(t)
        {
            self.events -= 1;
            self.cross_event(x);
        }
        if self.moving.iter().any(|m| m.0.to_bits() == t.to_bits()) {
            self.state_at(t, Side::Before);
            let jump = rhs_jump(self.sys, t, &self.y, self.p, &mut self.u);
            let along: f64 = x[..n].iter().zip(&jump).map(|(l, g)| l * g).sum();
            for &(_, q, slope) in self.moving.iter().filter(|m| m.0.to_bits() == t.to_bits()) {
                if let Some(j) = self.column_of[q] {
                    x[n + j] += along * slope;
                }
            }
        }
        self.add_seeds(t, x);
    }
}

impl<S: System> AdjointRhs<'_, S> {
    /// Back through the state event `self.events` of the forward solution, fired at τ from
    /// y⁻: forward, S⁺ = M S⁻ + N with M = R_y − d c_yᵀ/ρ and N_j = R_αj − d c_αj/ρ (d the
    /// drift R_y g⁻ − g⁺, ρ the rate c_y g⁻ + c_t; [`Reset`](crate::events::Reset)), so
    /// λ⁺ᵀS⁺ = (Mᵀλ⁺)ᵀS⁻ + λ⁺ᵀN: λ becomes Mᵀλ⁺ and μ_j gains λ⁺ᵀN_j.
    fn cross_event(&mut self, x: &mut [f64]) {
        let n = self.n;
        let fired = &self.forward.fired[self.events];
        let mut reset =
            Reset::new(self.sys, fired.event, fired.tau, (&fired.before, self.p, &mut self.u));
        let after = x[..n].to_vec();
        let along = reset.drift.iter().zip(&after).map(|(d, l)| d * l).sum::<f64>() / reset.rate;
        for (b, lambda) in x[..n].iter_mut().enumerate() {
            let carried: f64 = (0..n).map(|a| reset.r_y[a * n + b] * after[a]).sum();
            *lambda = carried - reset.c_y[b] * along;
        }
        for q in 0..self.column_of.len() {
            if let Some(j) = self.column_of[q] {
                let (c_q, r_q) = reset.parameter(self.sys, q);
                let gained: f64 = r_q.iter().zip(&after).map(|(r, l)| r * l).sum();
                x[n + j] += gained - c_q * along;
            }
        }
    }
}

/// The backward right-hand side seen in time τ local to a sample `origin`: t = origin + τ,
/// from τ = 0 back to the previous sample's τ.
///
/// A jump of λ at a sample sets off the system's fast modes, which the steps must resolve
/// (the forward integration meets them once, at t0, where t resolves any step). In absolute
/// time no step can be shorter than 16 ulps of t: 3e-10 at Lang's last sample, t = 136 471.6,
/// where its modes need steps of 1e-20, so its backward integration failed there. In local
/// time the first steps can be as short as the modes need. The right-hand side is read at
/// origin + τ rounded to the nearest time there is, which moves it by less than an ulp of t.
struct Local<'r, R> {
    rhs: &'r mut R,
    origin: f64,
    /// The stops between the two samples in local time, ascending, and the same stops in
    /// absolute time: a stop is handed on at its own absolute time, not at origin + τ
    /// rounded.
    local: Vec<f64>,
    absolute: Vec<f64>,
}

impl<'r, R: Rhs> Local<'r, R> {
    /// The part from `origin` back to `to` (< origin), with the stops of `stops` (sorted,
    /// none within the resolution of another) strictly between the two.
    fn new(rhs: &'r mut R, origin: f64, to: f64, stops: &[f64]) -> Self {
        let (first, end) =
            (stops.partition_point(|&s| s <= to), stops.partition_point(|&s| s < origin));
        let absolute = stops[first..end.max(first)].to_vec();
        let local = absolute.iter().map(|&s| s - origin).collect();
        Self { rhs, origin, local, absolute }
    }

    fn absolute(&self, tau: f64) -> f64 {
        match self.local.binary_search_by(|l| l.total_cmp(&tau)) {
            Ok(i) => self.absolute[i],
            Err(_) => self.origin + tau,
        }
    }
}

impl<R: Rhs> Rhs for Local<'_, R> {
    fn dim(&self) -> usize {
        self.rhs.dim()
    }

    fn describe(&self, i: usize) -> String {
        self.rhs.describe(i)
    }

    fn states(&self) -> usize {
        self.rhs.states()
    }

    fn autonomous(&self) -> bool {
        self.rhs.autonomous()
    }

    fn errors_as_vectors(&self) -> bool {
        self.rhs.errors_as_vectors()
    }

    fn eval(&mut self, t: f64, side: Side, x: &[f64], dx: &mut [f64]) {
        let t = self.absolute(t);
        self.rhs.eval(t, side, x, dx);
    }

    fn factor(
        &mut self,
        t: f64,
        side: Side,
        x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        let t = self.absolute(t);
        self.rhs.factor(t, side, x, inv_gamma_h)
    }

    fn solve(&mut self, r: &mut [f64]) {
        self.rhs.solve(r);
    }

    fn costs(&self) -> Costs {
        self.rhs.costs()
    }

    fn cross(&mut self, t: f64, x: &mut [f64], dir: f64) {
        let t = self.absolute(t);
        self.rhs.cross(t, x, dir);
    }
}
