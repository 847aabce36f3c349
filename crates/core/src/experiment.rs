//! Experiments: one system under several conditions, fitted jointly.
//!
//! Each experiment has its own data, inputs (inside its system), t0, and its own way of
//! setting the system's initial values and parameters: a number, an unknown of the problem,
//! or a function of the unknowns (a dose, a per-experiment scale, `A0 * ratio`). Unknowns are
//! shared by every experiment that uses them. The residuals and sensitivities of all
//! experiments are stacked; each experiment integrates with sensitivities only for its
//! *slots*, the initial values and parameters that depend on a free unknown, and the chain
//! rule through the settings' Jacobian gives the columns of the unknowns.

use std::fmt;
use std::sync::Arc;

use sysid_ode::{Integrator, System, Wrt};

use crate::data::Data;
use crate::plan::{Plan, Sampled};

/// A function of the unknowns' values: how an experiment sets an initial value or a
/// parameter from them (`dose = "A0 * ratio"`).
pub trait SettingFunction: Send + Sync {
    /// The value at the unknowns' values `v` (the problem's declared order), with its
    /// gradient ∂/∂v written into `gradient` (zeroed by the caller).
    fn eval(&self, v: &[f64], gradient: &mut [f64]) -> f64;
    /// The unknowns (declared indices) it depends on.
    fn uses(&self) -> &[usize];
    /// The function as written, for messages.
    fn describe(&self) -> String;
    /// The same function in a problem integrated by `integrator`, for a function that
    /// integrates the system itself (a preequilibration's steady state), so that it follows
    /// the problem's tolerances: [`Problem::with_integrator`](crate::Problem::with_integrator)
    /// and the problem's build pass theirs. Default: `None`, the function does not integrate.
    fn with_integrator(&self, integrator: &Integrator) -> Option<Arc<dyn SettingFunction>> {
        let _ = integrator;
        None
    }
    /// Whether its value is computed by integrating the system (a preequilibration's steady
    /// state) rather than given by the model: such a value may be rounding (1e-20 beside
    /// states of 10), and is no size to hold a state to ([`Planned::sizes`]). Default: false.
    fn computed(&self) -> bool {
        false
    }
    /// Drops what it keeps of earlier points (a steady state solved there), so that the next
    /// evaluation computes afresh: for timing one evaluation
    /// ([`Problem::forget_cached`](crate::Problem::forget_cached)). Default: nothing kept.
    fn forget(&self) {}
    /// Why its value at `v`, last evaluated, is not finite, where it knows (a steady state
    /// that was not found: what stopped the search for it), for messages. Default: `None`.
    fn failure(&self, v: &[f64]) -> Option<String> {
        let _ = v;
        None
    }
}

/// How an experiment sets one initial value or parameter of its system.
#[derive(Clone)]
pub enum Setting {
    /// A number.
    Value(f64),
    /// The value of the unknown of this name.
    Unknown(String),
    /// A function of the unknowns.
    Function(Arc<dyn SettingFunction>),
}

impl fmt::Debug for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Setting::Value(v) => write!(f, "{v}"),
            Setting::Unknown(n) => write!(f, "{n}"),
            Setting::Function(g) => write!(f, "{}", g.describe()),
        }
    }
}

/// One experiment as given: a name, the system (with this experiment's input signals), the
/// time of its initial values, a setting for every state's initial value and every
/// parameter (in the system's order), and its measurements.
#[derive(Clone, Debug)]
pub struct Experiment<S> {
    /// Its name, unique in the problem.
    pub name: String,
    /// Other names it answers to, unique in the problem too (the PEtab conditions merged
    /// into it because they set the same values).
    pub also: Vec<String>,
    /// The model, driven by this experiment's inputs.
    pub system: S,
    /// Time of the initial values.
    pub t0: f64,
    /// One setting per state: its initial value.
    pub initial: Vec<Setting>,
    /// One setting per parameter.
    pub parameters: Vec<Setting>,
    /// The measurements.
    pub data: Data,
}

/// A setting resolved against the problem's unknowns.
#[derive(Clone)]
pub(crate) enum Resolved {
    Value(f64),
    /// The declared index of the unknown.
    Unknown(usize),
    Function(Arc<dyn SettingFunction>),
}

impl fmt::Debug for Resolved {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Resolved::Value(v) => write!(f, "{v}"),
            Resolved::Unknown(j) => write!(f, "unknown {j}"),
            Resolved::Function(g) => write!(f, "{}", g.describe()),
        }
    }
}

impl Resolved {
    fn value(&self, v: &[f64]) -> f64 {
        match self {
            Resolved::Value(x) => *x,
            Resolved::Unknown(j) => v[*j],
            Resolved::Function(g) => g.eval(v, &mut vec![0.0; v.len()]),
        }
    }

    /// Whether it depends on any unknown `free` marks.
    fn depends(&self, free: &[bool]) -> bool {
        match self {
            Resolved::Value(_) => false,
            Resolved::Unknown(j) => free[*j],
            Resolved::Function(g) => g.uses().iter().any(|&j| free[j]),
        }
    }
}

/// What [`Sensitivities::Auto`](crate::Sensitivities::Auto) found for an experiment at its first gradient where both ways
/// could be integrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Choice {
    /// The adjoint's counted work, weighted by
    /// [`ADJOINT_OPERATION_COST`](crate::ADJOINT_OPERATION_COST), was less than forward's.
    Adjoint,
    /// It did not.
    Forward,
    /// Its backward integration failed (forward is used, and reported as a fallback).
    AdjointFailed,
}

/// An experiment of a [`Problem`](crate::Problem), checked and planned: what the methods
/// integrate, one experiment at a time. Cheap to clone: the system is shared.
#[derive(Debug)]
pub struct Planned<S> {
    pub(crate) name: String,
    pub(crate) also: Vec<String>,
    pub(crate) system: Arc<S>,
    pub(crate) t0: f64,
    pub(crate) initial: Vec<Resolved>,
    pub(crate) parameters: Vec<Resolved>,
    pub(crate) data: Data,
    pub(crate) plan: Plan,
    /// The initial values and parameters that depend on a free unknown.
    pub(crate) slots: Vec<Wrt>,
    /// Which way its gradient takes fewer counted operations, by the adjoint or by forward
    /// sensitivities, as [`Sensitivities::Auto`](crate::Sensitivities::Auto) counted them at
    /// its first gradient;
    /// shared by the clones (a problem at other noise scales is a clone), made afresh for
    /// another integrator or other free unknowns.
    pub(crate) adjoint_cheaper: Arc<std::sync::OnceLock<Choice>>,
}

impl<S> Planned<S> {
    /// Its settings' functions for a problem integrated by `integrator`
    /// ([`SettingFunction::with_integrator`]).
    pub(crate) fn integrate_with(&mut self, integrator: &Integrator) {
        // Which gradient is cheaper depends on the scheme and the tolerances: counted again.
        self.adjoint_cheaper = Default::default();
        for s in self.initial.iter_mut().chain(&mut self.parameters) {
            if let Resolved::Function(g) = s
                && let Some(h) = g.with_integrator(integrator)
            {
                *s = Resolved::Function(h);
            }
        }
    }

    /// Its settings' functions forget what they keep of earlier points.
    pub(crate) fn forget_cached(&self) {
        for s in self.initial.iter().chain(&self.parameters) {
            if let Resolved::Function(g) = s {
                g.forget();
            }
        }
    }

    /// The same experiment with its system mapped by `f`.
    pub(crate) fn map_system<T>(self, f: impl Fn(Arc<S>) -> T) -> Planned<T> {
        Planned {
            name: self.name,
            also: self.also,
            system: Arc::new(f(self.system)),
            t0: self.t0,
            initial: self.initial,
            parameters: self.parameters,
            data: self.data,
            plan: self.plan,
            slots: self.slots,
            // Another system: measured again.
            adjoint_cheaper: Default::default(),
        }
    }
}

impl<S> Clone for Planned<S> {
    fn clone(&self) -> Self {
        Self {
            name: self.name.clone(),
            also: self.also.clone(),
            system: self.system.clone(),
            t0: self.t0,
            initial: self.initial.clone(),
            parameters: self.parameters.clone(),
            data: self.data.clone(),
            plan: self.plan.clone(),
            slots: self.slots.clone(),
            adjoint_cheaper: self.adjoint_cheaper.clone(),
        }
    }
}

/// ∂(slot)/∂(free unknown's value): one sparse row per slot, (free index, derivative).
pub type SlotJacobian = Vec<Vec<(usize, f64)>>;

impl<S: System> Planned<S> {
    /// Its name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Whether it is called `name`, by its name or by one of the others it answers to.
    pub fn answers_to(&self, name: &str) -> bool {
        self.name == name || self.also.iter().any(|a| a == name)
    }
    /// Its system (with its inputs).
    pub fn system(&self) -> &S {
        &self.system
    }
    /// Time of its initial values.
    pub fn t0(&self) -> f64 {
        self.t0
    }
    /// Its measurements.
    pub fn data(&self) -> &Data {
        &self.data
    }
    /// Its data in residual form.
    pub fn sampled(&self) -> &Sampled {
        self.plan.sampled()
    }
    /// Whether its data are a continuous record.
    pub fn is_continuous(&self) -> bool {
        matches!(self.plan, Plan::Continuous { .. })
    }
    /// The time span it is integrated over: its data together with t0.
    pub fn span(&self) -> (f64, f64) {
        let (lo, hi) = self.plan.span();
        (lo.min(self.t0), hi.max(self.t0))
    }
    /// The initial values and parameters that depend on a free unknown: the columns of its
    /// sensitivities.
    pub fn slots(&self) -> &[Wrt] {
        &self.slots
    }

    /// y(t0) and the parameters at the unknowns' values `v` (declared order).
    pub fn point(&self, v: &[f64]) -> (Vec<f64>, Vec<f64>) {
        (
            self.initial.iter().map(|s| s.value(v)).collect(),
            self.parameters.iter().map(|s| s.value(v)).collect(),
        )
    }

    /// The states' sizes their absolute tolerances are taken from
    /// ([`Ivp::sized`](sysid_ode::Ivp::sized)): `y0`, the initial values at a point, with a
    /// state whose initial value is [computed](SettingFunction::computed) (a steady state) at
    /// 0, which holds it to atol.
    pub fn sizes(&self, y0: &[f64]) -> Vec<f64> {
        let computed = |s: &Resolved| matches!(s, Resolved::Function(g) if g.computed());
        self.initial.iter().zip(y0).map(|(s, &y)| if computed(s) { 0.0 } else { y }).collect()
    }

    /// [`point`](Self::point), or the error that names the first setting that is not finite
    /// there and what it is: a preequilibration's steady state that was not found, say, which
    /// the integrator alone could only call a non-finite initial state.
    pub(crate) fn start(&self, v: &[f64]) -> Result<(Vec<f64>, Vec<f64>), sysid_ode::OdeError>
    where
        S: System,
    {
        let (y0, p) = self.point(v);
        let sig = self.system.signature();
        let bad = |values: &[f64], settings: &[Resolved], names: &[&str], kind: &str| {
            let i = values.iter().position(|x| !x.is_finite())?;
            let what = match &settings[i] {
                Resolved::Function(g) => {
                    let why = g
                        .failure(v)
                        .map_or(String::new(), |w| format!(" which was not found ({w}),"));
                    format!("{kind} `{}`, {},{why}", names[i], g.describe())
                }
                _ => format!("{kind} `{}`", names[i]),
            };
            Some(sysid_ode::OdeError::NonFinite { t: self.t0, what })
        };
        let states: Vec<&str> = sig.states().iter().map(|s| s.as_ref()).collect();
        let parameters: Vec<&str> = sig.parameters().iter().map(|s| s.as_ref()).collect();
        if let Some(e) = bad(&y0, &self.initial, &states, "the initial value of")
            .or_else(|| bad(&p, &self.parameters, &parameters, "the parameter"))
        {
            return Err(e);
        }
        Ok((y0, p))
    }

    /// The parameters at the unknowns' values `v` (declared order), without the initial
    /// values (which may need a steady state solved).
    pub fn parameters_at(&self, v: &[f64]) -> Vec<f64> {
        self.parameters.iter().map(|s| s.value(v)).collect()
    }

    fn setting(&self, w: Wrt) -> &Resolved {
        match w {
            Wrt::InitialValue(i) => &self.initial[i],
            Wrt::Parameter(k) => &self.parameters[k],
        }
    }

    /// The unknown (declared index) a slot is, when it is one unknown's value itself.
    pub fn slot_unknown(&self, slot: usize) -> Option<usize> {
        match self.setting(self.slots[slot]) {
            Resolved::Unknown(j) => Some(*j),
            _ => None,
        }
    }

    /// ∂slot/∂(value of each free unknown) at `v`, with `free_index[j]` the free index of
    /// declared unknown j (None when it is held).
    pub fn slot_jacobian(&self, v: &[f64], free_index: &[Option<usize>]) -> SlotJacobian {
        let mut gradient = vec![0.0; v.len()];
        self.slots
            .iter()
            .map(|&w| match self.setting(w) {
                Resolved::Value(_) => Vec::new(),
                Resolved::Unknown(j) => free_index[*j].map(|f| vec![(f, 1.0)]).unwrap_or_default(),
                Resolved::Function(g) => {
                    gradient.iter_mut().for_each(|x| *x = 0.0);
                    g.eval(v, &mut gradient);
                    g.uses()
                        .iter()
                        .filter_map(|&j| free_index[j].map(|f| (f, gradient[j])))
                        .collect()
                }
            })
            .collect()
    }
}

/// The slots of settings that depend on the unknowns marked `free`: those that are an
/// unknown itself in the unknowns' order (so that a problem of plain unknowns integrates its
/// sensitivities in the unknowns' order, its slot Jacobian the identity), then the
/// functions, initial values before parameters.
pub(crate) fn slots(initial: &[Resolved], parameters: &[Resolved], free: &[bool]) -> Vec<Wrt> {
    let all: Vec<(Wrt, &Resolved)> = initial
        .iter()
        .enumerate()
        .map(|(i, s)| (Wrt::InitialValue(i), s))
        .chain(parameters.iter().enumerate().map(|(k, s)| (Wrt::Parameter(k), s)))
        .filter(|(_, s)| s.depends(free))
        .collect();
    let mut plain: Vec<(usize, Wrt)> = all
        .iter()
        .filter_map(|(w, s)| match s {
            Resolved::Unknown(j) => Some((*j, *w)),
            _ => None,
        })
        .collect();
    plain.sort_by_key(|(j, _)| *j);
    let functions = all.iter().filter(|(_, s)| matches!(s, Resolved::Function(_)));
    plain.into_iter().map(|(_, w)| w).chain(functions.map(|(w, _)| *w)).collect()
}
