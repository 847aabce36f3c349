//! Preequilibration: an experiment that starts from the steady state its system reaches
//! under other settings (`preequilibrate` in `[[experiments]]`; PEtab's
//! `preequilibrationConditionId`).
//!
//! Where the Jacobian is nonsingular at the start and the equilibrium reached is isolated
//! and attracting, the state is integrated alone until it settles, refined by a Newton step,
//! and its sensitivities are −J⁻¹ ∂f/∂α ([`by_newton`]). Otherwise the steady state and its
//! forward sensitivities S (for the columns the unknowns move) are integrated together from
//! the initial values under the preequilibration's parameters, to
//! t = 1, 10, 100, … until both have settled: every |dyᵢ/dt| ≤ atol + rtol·|yᵢ| and every
//! |dSᵢⱼ/dt| = |(J·S + ∂f/∂α)ᵢⱼ| ≤ atol + rtol·|Sᵢⱼ| (the problem's integrator's
//! tolerances), or, over the last decade from t ≥ 10, no component moved by more than 100
//! tolerances (90 over the decade from 10 to 100, a mean rate within the tolerance) and the
//! largest move was at most ten times the decade before's (rounding can keep the derivatives
//! above the tolerance at a steady state, where large fluxes cancel), at most to t = 1e12. A
//! state can settle before its derivatives do, where a slow mode hardly moves it: Weber's
//! nominal point settles by t = 1, its sensitivities only by t = 1000. S is chained with the
//! derivatives of the preequilibration's parameters and initial values: a conserved quantity
//! (a singular Jacobian) keeps its dependence on the initial values, which
//! the implicit-function formula −J⁻¹ ∂f/∂α would lose.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use nalgebra::{DMatrix, DVector, Schur};
use sysid_core::{Setting, Unknown, plan::SettingFunction};
use sysid_ode::{Integrator, Ivp, ModelRhs, Rhs, Scheme, SensitivityRhs, Side, Wrt};

use crate::ModelSystem;

/// The last time a steady state is looked for.
const LAST: f64 = 1e12;

/// The most tolerances a component may move over a decade that counts as settled where its
/// derivatives stay above the tolerance (see [`SteadyState::solve`]).
const STILL: f64 = 100.0;

/// The steady state of a preequilibration, shared by its states' settings and by every
/// experiment preequilibrated the same way, and computed once per point of the unknowns.
pub(crate) struct SteadyState {
    system: ModelSystem,
    /// The integrator of the components [`component`](Self::component) makes.
    integrator: Integrator,
    parameters: Vec<Setting>,
    initial: Vec<Setting>,
    /// The declared unknowns' names.
    names: Vec<String>,
    uses: Vec<usize>,
    /// The last points met (with the integrator that solved there) and their steady states
    /// (None: not found there), the newest first: see [`CACHED`].
    cache: Mutex<VecDeque<Cached>>,
}

/// How many points' steady states are kept. Every state's initial value asks for the steady
/// state at the same point, so one evaluation solves once; fits running side by side (a
/// multistart's starts, a study's trials) each keep their point in the cache. With one entry
/// they evicted each other's, and each of Weber's 7 states solved again: a start from
/// nominal took 60 s beside two others instead of 7 s alone, and the lock, held over the
/// solve, made the fits wait for each other.
const CACHED: usize = 64;

/// A point, the integrator that solved there and its steady state (or why it was not
/// found).
type Cached = (Integrator, Vec<f64>, Result<Solved, String>);

/// A steady state and its derivatives ∂y/∂v (n × n_v, row by row).
#[derive(Clone)]
struct Solved {
    y: Vec<f64>,
    dy: Vec<f64>,
}

impl SteadyState {
    /// The steady state of `system` under `settings` (parameters, initial values).
    pub(crate) fn new(
        system: ModelSystem,
        integrator: Integrator,
        settings: (Vec<Setting>, Vec<Setting>),
        declared: &[Unknown],
    ) -> Self {
        let names: Vec<String> = declared.iter().map(|u| u.name.clone()).collect();
        let mut uses = Vec::new();
        for s in settings.0.iter().chain(&settings.1) {
            let list = match s {
                Setting::Value(_) => Vec::new(),
                Setting::Unknown(name) => {
                    names.iter().position(|n| n == name).into_iter().collect()
                }
                Setting::Function(f) => f.uses().to_vec(),
            };
            for j in list {
                if !uses.contains(&j) {
                    uses.push(j);
                }
            }
        }
        uses.sort_unstable();
        Self {
            system,
            integrator,
            parameters: settings.0,
            initial: settings.1,
            names,
            uses,
            cache: Mutex::new(VecDeque::with_capacity(CACHED)),
        }
    }

    /// Every state's initial value in `experiment` (`states` by name, in state order): its
    /// component of this steady state.
    pub(crate) fn initial_values(
        self: &Arc<Self>,
        states: &[String],
        experiment: &str,
    ) -> Vec<Setting> {
        let component = |(i, state): (usize, &String)| Component {
            steady: self.clone(),
            integrator: self.integrator,
            state: i,
            text: format!(
                "the steady state of `{state}` before experiment `{experiment}` (preequilibration)"
            ),
        };
        states.iter().enumerate().map(|s| Setting::Function(Arc::new(component(s)))).collect()
    }

    /// The steady state solved at `v` with `integrator` (or why it was not found), if it is
    /// still in the cache.
    fn cached(&self, v: &[f64], integrator: &Integrator) -> Option<Result<Solved, String>> {
        let same = |at: &[f64]| at.iter().zip(v).all(|(a, b)| a.to_bits() == b.to_bits());
        let cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        cache.iter().find(|(i, at, _)| i == integrator && same(at)).map(|(.., s)| s.clone())
    }

    fn solved(&self, v: &[f64], integrator: &Integrator) -> Result<Solved, String> {
        if let Some(solved) = self.cached(v, integrator) {
            return solved;
        }
        // Solved without the lock: fits on other threads need their own points meanwhile.
        let solved = self.solve(v, integrator);
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if cache.len() == CACHED {
            cache.pop_back();
        }
        cache.push_front((*integrator, v.to_vec(), solved.clone()));
        solved
    }

    /// A setting's value at `v`, its gradient into `g`.
    fn setting(&self, s: &Setting, v: &[f64], g: &mut [f64], integrator: &Integrator) -> f64 {
        match s {
            Setting::Value(x) => *x,
            Setting::Unknown(name) => match self.names.iter().position(|n| n == name) {
                Some(j) => {
                    g[j] = 1.0;
                    v[j]
                }
                None => f64::NAN,
            },
            // A steady state that starts from another one solves that with the same tolerances.
            Setting::Function(f) => match f.with_integrator(integrator) {
                Some(f) => f.eval(v, g),
                None => f.eval(v, g),
            },
        }
    }

    fn solve(&self, v: &[f64], integrator: &Integrator) -> Result<Solved, String> {
        let nv = v.len();
        let (np, n) = (self.parameters.len(), self.initial.len());
        let mut dp = vec![0.0; np * nv];
        let p: Vec<f64> = (0..np)
            .map(|q| {
                let g = &mut dp[q * nv..(q + 1) * nv];
                self.setting(&self.parameters[q], v, g, integrator)
            })
            .collect();
        let mut dy0 = vec![0.0; n * nv];
        let y0: Vec<f64> = (0..n)
            .map(|i| {
                let g = &mut dy0[i * nv..(i + 1) * nv];
                self.setting(&self.initial[i], v, g, integrator)
            })
            .collect();
        if !p.iter().chain(&y0).all(|x| x.is_finite()) {
            return Err("its parameters or initial values are not finite there".into());
        }
        let sys = &self.system;
        // The columns the unknowns move.
        let moved = |rows: &[f64], k: usize| rows[k * nv..(k + 1) * nv].iter().any(|d| *d != 0.0);
        let mut wrt = Vec::new();
        let mut chain: Vec<&[f64]> = Vec::new();
        for q in (0..np).filter(|&q| moved(&dp, q)) {
            wrt.push(Wrt::Parameter(q));
            chain.push(&dp[q * nv..(q + 1) * nv]);
        }
        for i in (0..n).filter(|&i| moved(&dy0, i)) {
            wrt.push(Wrt::InitialValue(i));
            chain.push(&dy0[i * nv..(i + 1) * nv]);
        }
        let k = wrt.len();
        let x = match by_newton(sys, &p, &y0, &wrt, integrator) {
            Some(x) => x,
            // The state and its sensitivities, integrated on by decades until both settle.
            None => {
                let mut augmented = SensitivityRhs::new(sys, &p, &wrt);
                let x = augmented.initial_state(&y0);
                by_decades(&mut augmented, x, integrator, |t, x, next, scheme| {
                    let (y, s) = x.split_at(n);
                    let ivp = Ivp::new(sys, t, y, &p);
                    let trajectory = ivp
                        .solve_sensitivities_from(scheme, &wrt, s, &[next])
                        .map_err(|e| towards(t, next, &e))?;
                    let mut x = trajectory.state(0).to_vec();
                    x.extend_from_slice(trajectory.sensitivity_slice(0));
                    Ok((x, trajectory.counts().jacobians > 0))
                })?
                .1
            }
        };
        let mut dy = vec![0.0; n * nv];
        for i in 0..n {
            for (c, row) in chain.iter().enumerate() {
                let sic = x[n + i * k + c];
                if sic != 0.0 {
                    for j in 0..nv {
                        dy[i * nv + j] += sic * row[j];
                    }
                }
            }
        }
        let y = x[..n].to_vec();
        if y.iter().chain(&dy).all(|x| x.is_finite()) {
            Ok(Solved { y, dy })
        } else {
            Err("the state or its sensitivities there are not finite".into())
        }
    }
}

/// Why the integration of a decade towards a steady state failed, for messages.
fn towards(t: f64, next: f64, error: &sysid_ode::OdeError) -> String {
    format!("integrating towards it from t = {t} to {next}: {error}")
}

/// Integrates `x` (a state, or a state and its sensitivities) on by decades, t = 1, 10, 100,
/// …, each by `decade(t, x, next, integrator)` (the new x, and whether the decade went stiff),
/// until `rhs` says it has [settled] or a decade from t ≥ 10 moved it by at most [`STILL`]
/// tolerances, at a steady pace: the time it settled by and x there. Why not where it has not
/// by [`LAST`] or a decade fails.
fn by_decades(
    rhs: &mut impl Rhs,
    mut x: Vec<f64>,
    integrator: &Integrator,
    mut decade: impl FnMut(f64, &[f64], f64, &Integrator) -> Result<(Vec<f64>, bool), String>,
) -> Result<(f64, Vec<f64>), String> {
    let mut t = 0.0;
    // How far the last decade moved, in tolerances of the farthest-moving component.
    let mut last_moved = None;
    // The integrator of the next decade.
    let mut scheme = *integrator;
    while !settled(rhs, t, &x, integrator) {
        let next = if t == 0.0 { 1.0 } else { 10.0 * t };
        if next > LAST {
            return Err(format!("it had not settled by t = {LAST:e}"));
        }
        let (after, stiff) = decade(t, &x, next, &scheme)?;
        // A decade that went stiff under the automatic scheme (it factorised Jacobians)
        // hands Rodas5P to the next: the stiffness is not looked for again from a DOPRI5
        // start (Zheng's four decades: 193 steps in all, 139 so).
        if integrator.scheme == Scheme::Auto && stiff {
            scheme.scheme = Scheme::Rodas5p;
        }
        // Settled too: a decade from t ≥ 10 over which no component moved by more than
        // STILL of its tolerances (from 10 to 100, 90: a mean rate within what `settled`
        // asks of its derivative), and whose moves grew at most tenfold from the decade
        // before (no departure from an unstable point). Where large fluxes cancel, rounding
        // keeps the derivatives above the tolerance however long the integration runs:
        // Weber's at rtol 1e-11 stayed at 2–4 times it, in quanta of 2⁻³¹, from t = 1e4 to
        // 1e12, and it had no steady state; its decades moved 1.5–4.5 tolerances at rtol
        // 1e-11 and 10–30 at 1e-12, the integration's own noise. The bound keeps a slow
        // oscillation from passing on its mean alone.
        let span = next - t;
        let moved = after
            .iter()
            .zip(&x)
            .map(|(a, b)| (a - b).abs() / (integrator.atol + integrator.rtol * a.abs()))
            .fold(0.0, f64::max);
        x = after;
        let slow = moved <= STILL.min(span);
        let steady_pace = last_moved.is_some_and(|last: f64| moved <= 10.0 * last);
        last_moved = Some(moved);
        let from = t;
        t = next;
        if from >= 10.0 && slow && steady_pace {
            break;
        }
    }
    Ok((t, x))
}

/// The smallest modulus an eigenvalue of the Jacobian at the steady state may have, relative
/// to the largest, for [`by_newton`]: below it the Jacobian counts as singular (a conserved
/// quantity, whose eigenvalue 0 is computed as rounding).
const SINGULAR: f64 = 1e-9;

/// The steady state [y*; S] (S n × k, row by row) without integrating the sensitivities,
/// where the Jacobian J there is nonsingular and every eigenvalue has a negative real part:
/// the equilibrium is then isolated and attracting, so the sensitivities' own equations
/// S' = J S + ∂f/∂α settle, whatever their start, at S = −J⁻¹ ∂f/∂α (the initial values'
/// columns 0). The state is integrated alone by decades until it settles, then refined by
/// one Newton step, y* = y − J⁻¹ f(y), which may move it by at most [`STILL`] tolerances.
/// None where any of this does not hold: a conserved quantity (A ⇌ B keeps A + B) makes J
/// singular and keeps the steady state's dependence on the initial values, which only the
/// integration of S follows.
fn by_newton(
    sys: &ModelSystem,
    p: &[f64],
    y0: &[f64],
    wrt: &[Wrt],
    integrator: &Integrator,
) -> Option<Vec<f64>> {
    let n = y0.len();
    // f(t, y) and J(t, y) from the augmented right-hand side at [y; I] for every initial
    // value.
    let all: Vec<Wrt> = (0..n).map(Wrt::InitialValue).collect();
    let jacobian = |t: f64, y: &[f64]| {
        let mut rhs = SensitivityRhs::new(sys, p, &all);
        let x = rhs.initial_state(y);
        let mut dx = vec![0.0; x.len()];
        rhs.eval(t, Side::After, &x, &mut dx);
        let f = DVector::from_column_slice(&dx[..n]);
        let j = DMatrix::from_row_slice(n, n, &dx[n..]);
        (j.iter().chain(f.iter()).all(|v| v.is_finite())).then_some((j, f))
    };
    // A conserved quantity makes J singular everywhere: such a problem goes to the
    // integration of S at once, without settling the state alone first.
    let eigenvalues = |j: &DMatrix<f64>| {
        let schur = Schur::try_new(j.clone(), f64::EPSILON, 100 * n.max(10))?;
        let eigenvalues = schur.complex_eigenvalues();
        let largest = eigenvalues.iter().map(|l| l.norm()).fold(0.0, f64::max);
        Some((eigenvalues, largest))
    };
    let (at_start, largest) = eigenvalues(&jacobian(0.0, y0)?.0)?;
    if at_start.iter().any(|l| l.norm().is_nan() || l.norm() < SINGULAR * largest) {
        return None;
    }
    let mut model = ModelRhs::new(sys, p);
    let (t, y) = by_decades(&mut model, y0.to_vec(), integrator, |t, y, next, scheme| {
        let trajectory =
            Ivp::new(sys, t, y, p).solve(scheme, &[next]).map_err(|e| towards(t, next, &e))?;
        Ok((trajectory.state(0).to_vec(), trajectory.counts().jacobians > 0))
    })
    .ok()?;
    let (j, f) = jacobian(t, &y)?;
    let step = j.lu().solve(&f)?;
    let tolerances = y
        .iter()
        .zip(step.iter())
        .map(|(y, d)| d.abs() / (integrator.atol + integrator.rtol * y.abs()))
        .fold(0.0, f64::max);
    if tolerances.is_nan() || tolerances > STILL {
        return None;
    }
    let y: Vec<f64> = y.iter().zip(step.iter()).map(|(y, d)| y - d).collect();
    let (j, _) = jacobian(t, &y)?;
    let (at_steady, largest) = eigenvalues(&j)?;
    if !at_steady.iter().all(|l| l.re < -SINGULAR * largest) {
        return None;
    }
    // ∂f/∂α for the columns: S' at S = 0.
    let k = wrt.len();
    let mut rhs = SensitivityRhs::new(sys, p, wrt);
    let mut x = y.clone();
    x.resize(n * (1 + k), 0.0);
    let mut dx = vec![0.0; x.len()];
    rhs.eval(t, Side::After, &x, &mut dx);
    let s = j.lu().solve(&-DMatrix::from_row_slice(n, k, &dx[n..]))?;
    if !s.iter().all(|v| v.is_finite()) {
        return None;
    }
    x[n..].iter_mut().enumerate().for_each(|(e, v)| *v = s[(e / k, e % k)]);
    Some(x)
}

/// Whether every component of `x` (a state, or a state and its sensitivities) changes at t
/// by at most atol + rtol·|xᵢ| per unit time.
fn settled(rhs: &mut impl Rhs, t: f64, x: &[f64], integrator: &Integrator) -> bool {
    let mut dx = vec![0.0; x.len()];
    rhs.eval(t, Side::After, x, &mut dx);
    dx.iter().zip(x).all(|(d, xi)| d.abs() <= integrator.atol + integrator.rtol * xi.abs())
}

/// One state's initial value: its component of the steady state, solved with `integrator`.
pub(crate) struct Component {
    steady: Arc<SteadyState>,
    integrator: Integrator,
    state: usize,
    text: String,
}

impl SettingFunction for Component {
    fn eval(&self, v: &[f64], gradient: &mut [f64]) -> f64 {
        let nv = v.len();
        match self.steady.solved(v, &self.integrator) {
            Ok(s) => {
                for &j in &self.steady.uses {
                    gradient[j] = s.dy[self.state * nv + j];
                }
                s.y[self.state]
            }
            Err(_) => f64::NAN,
        }
    }
    fn failure(&self, v: &[f64]) -> Option<String> {
        self.steady.cached(v, &self.integrator)?.err()
    }
    fn uses(&self) -> &[usize] {
        &self.steady.uses
    }
    fn describe(&self) -> String {
        self.text.clone()
    }
    fn computed(&self) -> bool {
        true
    }
    fn forget(&self) {
        self.steady.cache.lock().unwrap_or_else(|e| e.into_inner()).clear();
    }
    fn with_integrator(&self, integrator: &Integrator) -> Option<Arc<dyn SettingFunction>> {
        Some(Arc::new(Component {
            steady: self.steady.clone(),
            integrator: *integrator,
            state: self.state,
            text: self.text.clone(),
        }))
    }
}
