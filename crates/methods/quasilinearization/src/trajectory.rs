//! The augmented state and the iterate x_k(t), one per experiment.
//!
//! Parameters are constant states (Bellman, Kagiwada & Kalaba; Goodman's eq. 4): the
//! augmented state of an experiment is x = [y; θ], with θ the coordinates of its parameters
//! that depend on the unknowns (ln α for a parameter that is a log-scale unknown itself) and
//! θ' = 0. The constants c of the linear family are the experiment's *slots*: those
//! parameters' coordinates and the initial values that depend on the unknowns. Each slot is
//! an affine function of the unknowns' coordinates z around the current z (exactly, for a slot
//! that is one unknown itself). Known values stay constants of the model.

use nalgebra::DMatrix;
use sysid_core::{Data, Problem, Record as Kind, Samples, plan::Planned};
use sysid_ode::{Counts, DenseSolution, Interpolation, Ivp, OdeError, Record, Signal, System, Wrt};

use crate::options::{Start, StateFunction};

/// What a column of the family (a slot) is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Column {
    /// The initial value of state i.
    State(usize),
    /// Parameter q, in coordinates θ = ln α when `log`.
    Parameter {
        /// The parameter.
        index: usize,
        /// Whether θ = ln α.
        log: bool,
    },
}

/// Where each slot of an experiment sits in its augmented state.
#[derive(Clone, Debug)]
pub struct Layout {
    /// Number of states n.
    pub n: usize,
    /// The slots, in the experiment's order.
    pub columns: Vec<Column>,
}

impl Layout {
    /// The layout of experiment `e` of `problem`.
    pub fn new<S: System>(problem: &Problem<S>, e: &Planned<S>) -> Self {
        let n = e.system().signature().n_states();
        let columns = e
            .slots()
            .iter()
            .enumerate()
            .map(|(s, w)| match *w {
                Wrt::InitialValue(i) => Column::State(i),
                Wrt::Parameter(index) => Column::Parameter {
                    index,
                    log: e.slot_unknown(s).is_some_and(|j| problem.declared()[j].log),
                },
            })
            .collect();
        Self { n, columns }
    }

    /// Number of slots k.
    pub fn k(&self) -> usize {
        self.columns.len()
    }

    /// The full parameter vector at the slot coordinates `c`, the others from `known`.
    pub fn parameters(&self, known: &[f64], c: &[f64]) -> Vec<f64> {
        let mut p = known.to_vec();
        for (column, &cj) in self.columns.iter().zip(c) {
            if let Column::Parameter { index, log } = *column {
                p[index] = if log { cj.exp() } else { cj };
            }
        }
        p
    }

    /// The slot coordinates at z and their Jacobian ∂c/∂z (slots × k): for a slot that is
    /// one unknown itself, c = z_j exactly; otherwise the slot's value, linearised.
    pub fn coordinates<S: System>(
        &self,
        problem: &Problem<S>,
        e: &Planned<S>,
        z: &[f64],
    ) -> (Vec<f64>, DMatrix<f64>) {
        let v = problem.values_at(z);
        let free = problem.free_index();
        let (y0, p) = e.point(&v);
        let chain: Vec<f64> =
            problem.unknowns().list().iter().zip(z).map(|(u, &zi)| u.scale(zi)).collect();
        let jacobian = e.slot_jacobian(&v, &free);
        let mut d = DMatrix::zeros(self.k(), z.len());
        let mut c = Vec::with_capacity(self.k());
        for (s, column) in self.columns.iter().enumerate() {
            let plain = e.slot_unknown(s).and_then(|j| free[j]);
            match (plain, *column) {
                (Some(f), _) => {
                    c.push(z[f]);
                    d[(s, f)] = 1.0;
                }
                (None, Column::State(i)) => c.push(y0[i]),
                (None, Column::Parameter { index, .. }) => c.push(p[index]),
            }
            if plain.is_none() {
                for &(f, x) in &jacobian[s] {
                    d[(s, f)] += x * chain[f];
                }
            }
        }
        (c, d)
    }
}

/// The iterate x_k(t) of one experiment: the states as a function of time, and the constant
/// coordinates of its slots.
pub struct Trajectory {
    states: DenseSolution,
    /// Measured states that follow their data (a data-based start).
    follow: Vec<(usize, Record)>,
    /// A caller's trajectory (replaces `states`).
    custom: Option<StateFunction>,
    /// The slots' coordinates this iterate carries.
    pub c: Vec<f64>,
}

impl Trajectory {
    /// x_{k+1} = p + Φ c, stored as a dense solution (not a re-integration).
    pub fn linear(states: DenseSolution, c: Vec<f64>) -> Self {
        Self { states, follow: Vec::new(), custom: None, c }
    }

    /// The first trajectory of experiment `e` from the start z, and the work of integrating
    /// it.
    pub fn start<S: System>(
        problem: &Problem<S>,
        e: &Planned<S>,
        layout: &Layout,
        z0: &[f64],
        start: &Start,
    ) -> Result<(Self, Counts), OdeError> {
        let (y0, p) = e.point(&problem.values_at(z0));
        let custom = match start {
            Start::Trajectory(f) => Some(f.clone()),
            _ => None,
        };
        let (states, counts) = if custom.is_some() {
            (DenseSolution::new(y0.len()), Counts::default())
        } else {
            let ivp = Ivp::new(e.system(), e.t0(), &y0, &p);
            let (states, counts) = ivp.dense(problem.integrator(), &[], e.span())?;
            // Every sample at t0 (a steady state measured at t = 0): nothing to integrate.
            let states =
                if states.is_empty() { DenseSolution::at_instant(e.t0(), &y0) } else { states };
            (states, counts)
        };
        let follow = match start {
            Start::Data => data_interpolants(e),
            _ => Vec::new(),
        };
        let (c, _) = layout.coordinates(problem, e, z0);
        Ok((Self { states, follow, custom, c }, counts))
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

/// The data of every state an experiment measures directly, as a function of time.
fn data_interpolants<S: System>(e: &Planned<S>) -> Vec<(usize, Record)> {
    let sig = e.system().signature();
    let Data { record, series } = e.data();
    series
        .iter()
        .filter(|s| s.transform == sysid_core::Transform::Lin)
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
