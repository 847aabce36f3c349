//! Preequilibration: an experiment that starts from the steady state its system reaches
//! under other settings (`preequilibrate` in `[[experiments]]`; PEtab's
//! `preequilibrationConditionId`).
//!
//! The steady state and its forward sensitivities S (for the columns the unknowns move) are
//! integrated together from the initial values under the preequilibration's parameters, to
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

use sysid_core::{Setting, Unknown, plan::SettingFunction};
use sysid_ode::{Integrator, Ivp, Rhs, Scheme, SensitivityRhs, Side, Wrt};

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

/// A point, the integrator that solved there and its steady state (None: not found).
type Cached = (Integrator, Vec<f64>, Option<Solved>);

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

    /// The setting of state `i`'s initial value in `experiment`.
    pub(crate) fn component(
        self: &Arc<Self>,
        i: usize,
        state: &str,
        experiment: &str,
    ) -> Component {
        Component {
            steady: self.clone(),
            integrator: self.integrator,
            state: i,
            text: format!(
                "the steady state of `{state}` before experiment `{experiment}` (preequilibration)"
            ),
        }
    }

    fn solved(&self, v: &[f64], integrator: &Integrator) -> Option<Solved> {
        let same = |at: &[f64]| at.iter().zip(v).all(|(a, b)| a.to_bits() == b.to_bits());
        {
            let cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
            if let Some((_, _, solved)) =
                cache.iter().find(|(i, at, _)| i == integrator && same(at))
            {
                return solved.clone();
            }
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

    fn solve(&self, v: &[f64], integrator: &Integrator) -> Option<Solved> {
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
            return None;
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
        // The state and its sensitivities, integrated on by decades until both settle.
        let mut augmented = SensitivityRhs::new(sys, &p, &wrt);
        let mut x = augmented.initial_state(&y0);
        let mut t = 0.0;
        // How far the last decade moved, in tolerances of the farthest-moving component.
        let mut last_moved = None;
        // The integrator of the next decade.
        let mut scheme = *integrator;
        while !settled(&mut augmented, t, &x, integrator) {
            let next = if t == 0.0 { 1.0 } else { 10.0 * t };
            if next > LAST {
                return None;
            }
            let (y, s) = x.split_at(n);
            let ivp = Ivp::new(sys, t, y, &p);
            let trajectory = ivp.solve_sensitivities_from(&scheme, &wrt, s, &[next]).ok()?;
            // A decade that went stiff under the automatic scheme (it factorised Jacobians)
            // hands Rodas5P to the next: the stiffness is not looked for again from a
            // DOPRI5 start (Zheng's four decades: 193 steps in all, 139 so).
            if integrator.scheme == Scheme::Auto && trajectory.counts().jacobians > 0 {
                scheme.scheme = Scheme::Rodas5p;
            }
            let before = x.clone();
            x[..n].copy_from_slice(trajectory.state(0));
            x[n..].copy_from_slice(trajectory.sensitivity_slice(0));
            // Settled too: a decade from t ≥ 10 over which no component moved by more than
            // STILL of its tolerances (from 10 to 100, 90: a mean rate within what `settled`
            // asks of its derivative), and whose moves grew at most tenfold from the decade
            // before (no departure from an unstable point). Where large fluxes cancel,
            // rounding keeps the derivatives above the tolerance however long the
            // integration runs: Weber's at rtol 1e-11 stayed at 2–4 times it, in quanta of
            // 2⁻³¹, from t = 1e4 to 1e12, and it had no steady state; its decades moved
            // 1.5–4.5 tolerances at rtol 1e-11 and 10–30 at 1e-12, the integration's own
            // noise. The bound keeps a slow oscillation from passing on its mean alone.
            let span = next - t;
            let moved = x
                .iter()
                .zip(&before)
                .map(|(a, b)| (a - b).abs() / (integrator.atol + integrator.rtol * a.abs()))
                .fold(0.0, f64::max);
            let slow = moved <= STILL.min(span);
            let steady_pace = last_moved.is_some_and(|last: f64| moved <= 10.0 * last);
            last_moved = Some(moved);
            let from = t;
            t = next;
            if from >= 10.0 && slow && steady_pace {
                break;
            }
        }
        let mut dy = vec![0.0; n * nv];
        let k = wrt.len();
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
        y.iter().chain(&dy).all(|x| x.is_finite()).then_some(Solved { y, dy })
    }
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
            Some(s) => {
                for &j in &self.steady.uses {
                    gradient[j] = s.dy[self.state * nv + j];
                }
                s.y[self.state]
            }
            None => f64::NAN,
        }
    }
    fn uses(&self) -> &[usize] {
        &self.steady.uses
    }
    fn describe(&self) -> String {
        self.text.clone()
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
