//! The augmented state and the iterate x_k(t).
//!
//! Parameters are constant states (Bellman, Kagiwada & Kalaba; Goodman's eq. 4): the
//! augmented state is x = [y; θ], with θ the coordinates of the unknown parameters (ln α on a
//! log scale) and θ' = 0. Known parameters stay constants of the model.

use sysid_core::{Data, Problem, Record as Kind, Samples};
use sysid_ode::{Counts, DenseSolution, Interpolation, Ivp, OdeError, Record, Signal, System, Wrt};

use crate::options::{Start, StateFunction};

/// Where each unknown sits in the augmented state.
#[derive(Clone, Debug)]
pub struct Layout {
    /// Number of states n.
    pub n: usize,
    /// Per unknown: `Some(i)` for the initial value of state i, `None` for a parameter.
    pub state_of: Vec<Option<usize>>,
    /// Per unknown parameter, in order: (its unknown index, its parameter index, log scale).
    pub parameters: Vec<(usize, usize, bool)>,
}

impl Layout {
    /// The layout of a problem's unknowns.
    pub fn new<S: System>(problem: &Problem<S>) -> Self {
        let n = problem.system().signature().n_states();
        let mut state_of = Vec::new();
        let mut parameters = Vec::new();
        for (j, (u, w)) in
            problem.unknowns().list().iter().zip(problem.unknowns().wrt()).enumerate()
        {
            match *w {
                Wrt::InitialValue(i) => state_of.push(Some(i)),
                Wrt::Parameter(q) => {
                    state_of.push(None);
                    parameters.push((j, q, u.log));
                }
            }
        }
        Self { n, state_of, parameters }
    }

    /// Number of unknowns k.
    pub fn k(&self) -> usize {
        self.state_of.len()
    }

    /// The full parameter vector at the coordinates θ carried by z (the unknowns'
    /// coordinates), with the known values from `known`.
    pub fn parameters(&self, known: &[f64], z: &[f64]) -> Vec<f64> {
        let mut p = known.to_vec();
        for &(j, q, log) in &self.parameters {
            p[q] = if log { z[j].exp() } else { z[j] };
        }
        p
    }
}

/// The iterate x_k(t): the states as a function of time, and the constant coordinates of the
/// unknown parameters.
pub struct Trajectory {
    states: DenseSolution,
    /// Measured states that follow their data (a data-based start).
    follow: Vec<(usize, Record)>,
    /// A caller's trajectory (replaces `states`).
    custom: Option<StateFunction>,
    /// The unknowns' coordinates this iterate carries (parameters: θ; initial values: c).
    pub z: Vec<f64>,
}

impl Trajectory {
    /// x_{k+1} = p + Φ c, stored as a dense solution (not a re-integration).
    pub fn linear(states: DenseSolution, z: Vec<f64>) -> Self {
        Self { states, follow: Vec::new(), custom: None, z }
    }

    /// The first trajectory from the start z0, and the work of integrating it.
    pub fn start<S: System>(
        problem: &Problem<S>,
        z0: &[f64],
        start: &Start,
    ) -> Result<(Self, Counts), OdeError> {
        let sys = problem.system();
        let (y0, p) = problem.point(z0);
        let custom = match start {
            Start::Trajectory(f) => Some(f.clone()),
            _ => None,
        };
        let (states, counts) = if custom.is_some() {
            (DenseSolution::new(y0.len()), Counts::default())
        } else {
            let ivp = Ivp::new(sys, problem.t0(), &y0, &p);
            ivp.dense(problem.integrator(), &[], problem.span())?
        };
        let follow = match start {
            Start::Data => data_interpolants(problem),
            _ => Vec::new(),
        };
        Ok((Self { states, follow, custom, z: z0.to_vec() }, counts))
    }

    /// y(t), starting the search at step `hint`.
    pub fn eval(&self, t: f64, hint: &mut usize, y: &mut [f64]) {
        if let Some(f) = &self.custom {
            f(t, y);
        } else if !self.states.eval_hinted(t, hint, y) {
            // Outside the stored span (only at its ends, by rounding): the nearest end.
            let (lo, hi) = self.states.span().expect("a non-empty trajectory");
            self.states.eval_hinted(t.clamp(lo, hi), hint, y);
        }
        for (i, record) in &self.follow {
            y[*i] = record.value(t);
        }
    }
}

/// The data of every measured state as a function of time.
fn data_interpolants<S: System>(problem: &Problem<S>) -> Vec<(usize, Record)> {
    let sig = problem.system().signature();
    let Data { record, series } = problem.data();
    series
        .iter()
        .filter_map(|s| {
            let i = sig.state(&s.name)?;
            let r = match (&s.samples, record) {
                (Samples::Points { times, values }, _) => Record::Samples(
                    Signal::new(times.clone(), values.clone(), Interpolation::Linear).ok()?,
                ),
                (Samples::Function(f), Kind::Continuous { .. }) => Record::Function(f.clone()),
                (Samples::Function(_), Kind::Discrete) => return None,
            };
            Some((i, r))
        })
        .collect()
}
