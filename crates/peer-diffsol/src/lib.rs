//! # sysid-peer-diffsol: diffsol as a peer of sysid-ode
//!
//! Poses any sysid [`System`] as a [diffsol](https://docs.rs/diffsol/0.14.2) problem, so that
//! the `ode` benchmark can time diffsol's explicit (Tsitouras 5(4)) and BDF solvers on exactly
//! the models, tolerances and output times sysid integrates, and so that tests can check two
//! independent codes against each other. Nothing in sysid's product depends on this crate: it
//! is a dev-dependency of the benchmarks and has its own agreement tests.
//!
//! How the model is handed over:
//! * the right-hand side is the system's own `rhs`; the products diffsol asks for, J_y·v and
//!   J_α·v, are one dual-number evaluation each (the same exact derivatives sysid uses);
//! * diffsol differentiates with respect to its parameter vector only. To get sensitivities
//!   to initial values as well, the vector given to diffsol is the list of unknowns (`Wrt`,
//!   initial values and parameters alike), and the initial condition depends on it;
//! * inputs are evaluated with their limit from the right, and the solver is stopped on every
//!   declared discontinuity, so that no step straddles a jump (as sysid's integrators do);
//! * tolerances: one relative and one absolute tolerance for every state and every
//!   sensitivity, as in sysid's error control over all components.
//!
//! ```
//! use sysid_ode::{Integrator, Ivp, Scalar, Signature, System, Wrt};
//! use sysid_peer_diffsol::{Peer, Solver};
//! struct Decay(Signature);
//! impl System for Decay {
//!     fn signature(&self) -> &Signature { &self.0 }
//!     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
//!         dy[0] = -p[0] * y[0];
//!     }
//! }
//! let decay = Decay(Signature::new(&["x"], &["k"]));
//! let peer = Peer::new(&decay, 0.0, &[2.0], &[0.5], 1e-10, 1e-12);
//! let sol = peer.solve_sensitivities(Solver::Bdf, &[Wrt::Parameter(0)], &[1.0]).unwrap();
//! // x = 2 e^{-kt}, ∂x/∂k = -2 t e^{-kt}
//! assert!((sol.state(0)[0] - 2.0 * (-0.5f64).exp()).abs() < 1e-8);
//! assert!((sol.sensitivity(0)[(0, 0)] + 2.0 * (-0.5f64).exp()).abs() < 1e-8);
//! ```
#![warn(missing_docs)]

use std::cell::{Cell, RefCell};
use std::fmt;

use diffsol::{
    DiffsolError, NalgebraLU, NalgebraMat, NalgebraVec, OdeBuilder, OdeEquations,
    OdeEquationsImplicitSens, OdeSolverMethod, OdeSolverStopReason, SensitivitiesOdeSolverMethod,
    VectorHost,
};
use nalgebra::DMatrix;
use num_dual::Dual64;
use sysid_ode::{Side, System, Wrt};

/// Which diffsol solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// Tsitouras 5(4), explicit, with its own dense output.
    Tsit45,
    /// Variable-order BDF (orders 1–5) with Newton iterations and dense LU (nalgebra).
    Bdf,
}

impl Solver {
    /// Both solvers, explicit first.
    pub const ALL: [Solver; 2] = [Solver::Tsit45, Solver::Bdf];

    /// A short lowercase name (`tsit45`, `bdf`).
    pub fn name(self) -> &'static str {
        match self {
            Solver::Tsit45 => "tsit45",
            Solver::Bdf => "bdf",
        }
    }
}

/// Why a diffsol integration failed.
#[derive(Debug)]
pub enum PeerError {
    /// The output times are empty, not ascending, or before t0 (diffsol integrates forwards).
    Times(String),
    /// diffsol's own error.
    Diffsol(DiffsolError),
}

impl fmt::Display for PeerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PeerError::Times(why) => write!(f, "output times: {why}"),
            PeerError::Diffsol(e) => write!(f, "diffsol: {e}"),
        }
    }
}

impl std::error::Error for PeerError {}

impl From<DiffsolError> for PeerError {
    fn from(e: DiffsolError) -> Self {
        PeerError::Diffsol(e)
    }
}

/// The states (and sensitivities) at the output times, with diffsol's work.
#[derive(Clone, Debug)]
pub struct Solution {
    n: usize,
    states: Vec<f64>,
    sensitivities: Vec<DMatrix<f64>>,
    /// Evaluations of the right-hand side.
    pub rhs_evaluations: usize,
    /// Products J_y·v and J_α·v (one dual-number evaluation each).
    pub jacobian_products: usize,
}

impl Solution {
    /// y(t_m).
    pub fn state(&self, m: usize) -> &[f64] {
        &self.states[m * self.n..(m + 1) * self.n]
    }

    /// ∂y(t_m)/∂(unknowns), n × k, columns in the order of the `Wrt` list.
    ///
    /// # Panics
    /// If the solution was computed without sensitivities.
    pub fn sensitivity(&self, m: usize) -> &DMatrix<f64> {
        &self.sensitivities[m]
    }
}

/// An initial-value problem of a sysid system, ready to be solved by diffsol.
pub struct Peer<'a, S> {
    system: &'a S,
    t0: f64,
    y0: &'a [f64],
    p: &'a [f64],
    rtol: f64,
    atol: f64,
}

impl<'a, S: System> Peer<'a, S> {
    /// The problem y' = g(t, y, α, u), y(t0) = y0, to be solved at tolerances `rtol`, `atol`
    /// (for the states and for the sensitivities alike).
    pub fn new(system: &'a S, t0: f64, y0: &'a [f64], p: &'a [f64], rtol: f64, atol: f64) -> Self {
        Self { system, t0, y0, p, rtol, atol }
    }

    /// The states at `times` (ascending, none before t0).
    pub fn solve(&self, solver: Solver, times: &[f64]) -> Result<Solution, PeerError> {
        let stops = self.stops(times)?;
        let model = Model::new(self, &[]);
        let n = self.y0.len();
        let problem = OdeBuilder::<NalgebraMat<f64>>::new()
            .t0(self.t0)
            .rtol(self.rtol)
            .atol([self.atol])
            .rhs_implicit(
                |x, q, t, y| model.rhs(x.as_slice(), q.as_slice(), t, y.as_mut_slice()),
                |x, q, t, v, y| {
                    model.jac_y(x.as_slice(), q.as_slice(), t, v.as_slice(), y.as_mut_slice())
                },
            )
            .init(|q, _t, y| model.init(q.as_slice(), y.as_mut_slice()), n)
            .build()?;
        let states = match solver {
            Solver::Tsit45 => states(&mut problem.tsit45()?, &stops, times, n)?,
            Solver::Bdf => states(&mut problem.bdf::<NalgebraLU<f64>>()?, &stops, times, n)?,
        };
        Ok(model.solution(states, Vec::new()))
    }

    /// The states and their sensitivities to the unknowns `wrt` at `times`.
    pub fn solve_sensitivities(
        &self,
        solver: Solver,
        wrt: &[Wrt],
        times: &[f64],
    ) -> Result<Solution, PeerError> {
        let stops = self.stops(times)?;
        let model = Model::new(self, wrt);
        let n = self.y0.len();
        let q: Vec<f64> = wrt
            .iter()
            .map(|w| match *w {
                Wrt::InitialValue(i) => self.y0[i],
                Wrt::Parameter(k) => self.p[k],
            })
            .collect();
        let problem = OdeBuilder::<NalgebraMat<f64>>::new()
            .t0(self.t0)
            .p(q)
            .rtol(self.rtol)
            .atol([self.atol])
            .sens_rtol(self.rtol)
            .sens_atol([self.atol])
            .rhs_sens_implicit(
                |x, q, t, y| model.rhs(x.as_slice(), q.as_slice(), t, y.as_mut_slice()),
                |x, q, t, v, y| {
                    model.jac_y(x.as_slice(), q.as_slice(), t, v.as_slice(), y.as_mut_slice())
                },
                |x, q, t, v, y| {
                    model.jac_q(x.as_slice(), q.as_slice(), t, v.as_slice(), y.as_mut_slice())
                },
            )
            .init_sens(
                |q, _t, y| model.init(q.as_slice(), y.as_mut_slice()),
                |_q, _t, v, y| model.init_sens(v.as_slice(), y.as_mut_slice()),
                n,
            )
            .build()?;
        let k = wrt.len();
        let (states, sens) = match solver {
            Solver::Tsit45 => sensitivities(&mut problem.tsit45_sens()?, &stops, times, n, k)?,
            Solver::Bdf => {
                sensitivities(&mut problem.bdf_sens::<NalgebraLU<f64>>()?, &stops, times, n, k)?
            }
        };
        Ok(model.solution(states, sens))
    }

    /// Where the solver must stop: the discontinuities inside (t0, t_last), then t_last.
    fn stops(&self, times: &[f64]) -> Result<Vec<f64>, PeerError> {
        let (Some(&first), Some(&last)) = (times.first(), times.last()) else {
            return Err(PeerError::Times("no output times".into()));
        };
        if first < self.t0 {
            return Err(PeerError::Times(format!(
                "t = {first} is before t0 = {}; diffsol integrates forwards only",
                self.t0
            )));
        }
        if times.windows(2).any(|w| w[1] < w[0]) || times.iter().any(|t| !t.is_finite()) {
            return Err(PeerError::Times("not finite and ascending".into()));
        }
        if last <= self.t0 {
            return Err(PeerError::Times(format!("the last time must be after t0 = {}", self.t0)));
        }
        let mut stops: Vec<f64> = (self.system.discontinuities().iter().copied())
            .filter(|&d| d > self.t0 && d < last)
            .collect();
        stops.push(last);
        Ok(stops)
    }
}

/// Steps `s` to each stop in turn, calling `write(s, m, t_m)` for every output time the
/// steps pass.
fn drive<'a, Eqn, M>(
    s: &mut M,
    stops: &[f64],
    times: &[f64],
    mut write: impl FnMut(&M, usize, f64) -> Result<(), DiffsolError>,
) -> Result<(), DiffsolError>
where
    Eqn: OdeEquations<T = f64> + 'a,
    M: OdeSolverMethod<'a, Eqn>,
{
    let mut m = 0;
    for &stop in stops {
        s.set_stop_time(stop)?;
        loop {
            let reason = s.step()?;
            let t = s.state().t;
            while m < times.len() && times[m] <= t {
                write(s, m, times[m])?;
                m += 1;
            }
            if matches!(reason, OdeSolverStopReason::TstopReached) {
                break;
            }
        }
    }
    Ok(())
}

/// The states at `times`, n per time.
fn states<'a, Eqn, M>(
    s: &mut M,
    stops: &[f64],
    times: &[f64],
    n: usize,
) -> Result<Vec<f64>, DiffsolError>
where
    Eqn: OdeEquations<T = f64, V = NalgebraVec<f64>> + 'a,
    M: OdeSolverMethod<'a, Eqn>,
{
    let mut states = vec![0.0; n * times.len()];
    drive(s, stops, times, |s, m, t| {
        states[m * n..(m + 1) * n].copy_from_slice(s.interpolate(t)?.as_slice());
        Ok(())
    })?;
    Ok(states)
}

/// The states (n per time) and the n × k sensitivities at `times`.
fn sensitivities<'a, Eqn, M>(
    s: &mut M,
    stops: &[f64],
    times: &[f64],
    n: usize,
    k: usize,
) -> Result<(Vec<f64>, Vec<DMatrix<f64>>), DiffsolError>
where
    Eqn: OdeEquationsImplicitSens<T = f64, V = NalgebraVec<f64>> + 'a,
    M: SensitivitiesOdeSolverMethod<'a, Eqn>,
{
    let mut states = vec![0.0; n * times.len()];
    let mut sens = vec![DMatrix::zeros(n, k); times.len()];
    drive(s, stops, times, |s, m, t| {
        states[m * n..(m + 1) * n].copy_from_slice(s.interpolate(t)?.as_slice());
        for (j, column) in s.interpolate_sens(t)?.iter().enumerate() {
            sens[m].column_mut(j).copy_from_slice(column.as_slice());
        }
        Ok(())
    })?;
    Ok((states, sens))
}

/// The system with its fixed values, the map from diffsol's parameter vector q (the
/// unknowns) to initial values and parameters, scratch space for the dual-number
/// evaluations, and counters.
struct Model<'a, S> {
    system: &'a S,
    y0: &'a [f64],
    p: &'a [f64],
    wrt: &'a [Wrt],
    scratch: RefCell<Scratch>,
    rhs_evaluations: Cell<usize>,
    jacobian_products: Cell<usize>,
}

struct Scratch {
    p: Vec<f64>,
    u: Vec<f64>,
    yd: Vec<Dual64>,
    pd: Vec<Dual64>,
    dy: Vec<Dual64>,
}

impl<'a, S: System> Model<'a, S> {
    fn new(peer: &Peer<'a, S>, wrt: &'a [Wrt]) -> Self {
        let (n, np) = (peer.y0.len(), peer.p.len());
        let zero = Dual64::from_re(0.0);
        Self {
            system: peer.system,
            y0: peer.y0,
            p: peer.p,
            wrt,
            scratch: RefCell::new(Scratch {
                p: peer.p.to_vec(),
                u: vec![0.0; peer.system.signature().n_inputs()],
                yd: vec![zero; n],
                pd: vec![zero; np],
                dy: vec![zero; n],
            }),
            rhs_evaluations: Cell::new(0),
            jacobian_products: Cell::new(0),
        }
    }

    /// The parameters with the unknown ones taken from q.
    fn parameters(&self, q: &[f64], p: &mut [f64]) {
        p.copy_from_slice(self.p);
        for (w, &v) in self.wrt.iter().zip(q) {
            if let Wrt::Parameter(k) = *w {
                p[k] = v;
            }
        }
    }

    fn rhs(&self, x: &[f64], q: &[f64], t: f64, y: &mut [f64]) {
        self.rhs_evaluations.set(self.rhs_evaluations.get() + 1);
        let s = &mut *self.scratch.borrow_mut();
        self.parameters(q, &mut s.p);
        self.system.input_values(t, Side::After, &mut s.u);
        self.system.rhs(t, x, &s.p, &s.u, y);
    }

    /// y = J_y v: the system evaluated at x + εv.
    fn jac_y(&self, x: &[f64], q: &[f64], t: f64, v: &[f64], y: &mut [f64]) {
        self.directional(x, q, t, y, |s| {
            for (d, &vi) in s.yd.iter_mut().zip(v) {
                d.eps = vi;
            }
        });
    }

    /// y = (∂g/∂q) v: the system evaluated with the unknown parameters at q + εv (unknown
    /// initial values do not enter g).
    fn jac_q(&self, x: &[f64], q: &[f64], t: f64, v: &[f64], y: &mut [f64]) {
        self.directional(x, q, t, y, |s| {
            for (w, &vj) in self.wrt.iter().zip(v) {
                if let Wrt::Parameter(k) = *w {
                    s.pd[k].eps = vj;
                }
            }
        });
    }

    /// One dual-number evaluation at (x, q) with the derivative parts `seed` sets (all zero
    /// before it runs); y = the derivative of g in that direction.
    fn directional(
        &self,
        x: &[f64],
        q: &[f64],
        t: f64,
        y: &mut [f64],
        seed: impl Fn(&mut Scratch),
    ) {
        self.jacobian_products.set(self.jacobian_products.get() + 1);
        let s = &mut *self.scratch.borrow_mut();
        self.parameters(q, &mut s.p);
        self.system.input_values(t, Side::After, &mut s.u);
        for (d, &xi) in s.yd.iter_mut().zip(x) {
            *d = Dual64::from_re(xi);
        }
        for (d, &pk) in s.pd.iter_mut().zip(&s.p) {
            *d = Dual64::from_re(pk);
        }
        seed(s);
        self.system.rhs(t, &s.yd, &s.pd, &s.u, &mut s.dy);
        for (yi, d) in y.iter_mut().zip(&s.dy) {
            *yi = d.eps;
        }
    }

    /// y(t0) with the unknown initial values taken from q.
    fn init(&self, q: &[f64], y: &mut [f64]) {
        y.copy_from_slice(self.y0);
        for (w, &v) in self.wrt.iter().zip(q) {
            if let Wrt::InitialValue(i) = *w {
                y[i] = v;
            }
        }
    }

    /// y = (∂y(t0)/∂q) v: the unit columns of the unknown initial values.
    fn init_sens(&self, v: &[f64], y: &mut [f64]) {
        y.fill(0.0);
        for (w, &vj) in self.wrt.iter().zip(v) {
            if let Wrt::InitialValue(i) = *w {
                y[i] = vj;
            }
        }
    }

    fn solution(&self, states: Vec<f64>, sensitivities: Vec<DMatrix<f64>>) -> Solution {
        Solution {
            n: self.y0.len(),
            states,
            sensitivities,
            rhs_evaluations: self.rhs_evaluations.get(),
            jacobian_products: self.jacobian_products.get(),
        }
    }
}
