//! The model: dy/dt = g(t, y, α, u(t)), written once and generic over the scalar type.

use nalgebra::DMatrix;
use num_dual::{Dual64, DualNum};

use crate::error::SignatureError;
use crate::signal::Side;
use crate::sparse::SparseJacobian;

/// The scalar a right-hand side is written for: `f64`, or a forward-mode dual number
/// (`num_dual::Dual64`) carrying one directional derivative.
///
/// Arithmetic with `f64` works on the right-hand side (`y * 2.0`, `y - 1.0`); a constant on
/// the left is written `T::from(1.0) - y`.
pub trait Scalar: DualNum<f64> + Copy + Send + Sync {}
impl<T: DualNum<f64> + Copy + Send + Sync> Scalar for T {}

/// The names of a system's variables. Names are unique across states, parameters, inputs
/// and outputs, and their order is the order of the slices the right-hand side receives.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Signature {
    states: Vec<String>,
    parameters: Vec<String>,
    inputs: Vec<String>,
    outputs: Vec<String>,
}

impl Signature {
    /// States and parameters, no inputs and no outputs besides the states themselves.
    ///
    /// # Panics
    /// If a name is empty or used twice: the names of a system written in Rust are literals,
    /// so this is a programming error. Use [`Signature::try_new`] for names read at run time.
    pub fn new(states: &[&str], parameters: &[&str]) -> Self {
        let owned = |names: &[&str]| names.iter().map(|s| s.to_string()).collect();
        Self::try_new(owned(states), owned(parameters), Vec::new(), Vec::new())
            .unwrap_or_else(|e| panic!("invalid signature: {e}"))
    }

    /// The same as [`Signature::new`] with input signals u(t), in the order the right-hand
    /// side receives them.
    pub fn with_inputs(self, inputs: &[&str]) -> Self {
        let inputs = inputs.iter().map(|s| s.to_string()).collect();
        Self::try_new(self.states, self.parameters, inputs, self.outputs)
            .unwrap_or_else(|e| panic!("invalid signature: {e}"))
    }

    /// The same as [`Signature::new`] with measured outputs h(t, y, α, u) computed by
    /// [`System::outputs`].
    pub fn with_outputs(self, outputs: &[&str]) -> Self {
        let outputs = outputs.iter().map(|s| s.to_string()).collect();
        Self::try_new(self.states, self.parameters, self.inputs, outputs)
            .unwrap_or_else(|e| panic!("invalid signature: {e}"))
    }

    /// Checked constructor for names read at run time.
    pub fn try_new(
        states: Vec<String>,
        parameters: Vec<String>,
        inputs: Vec<String>,
        outputs: Vec<String>,
    ) -> Result<Self, SignatureError> {
        if states.is_empty() {
            return Err(SignatureError::NoStates);
        }
        let mut seen = std::collections::HashSet::new();
        for name in states.iter().chain(&parameters).chain(&inputs).chain(&outputs) {
            if name.is_empty() {
                return Err(SignatureError::EmptyName);
            }
            if name == "t" {
                return Err(SignatureError::Reserved { name: name.clone() });
            }
            if !seen.insert(name.as_str()) {
                return Err(SignatureError::Duplicate { name: name.clone() });
            }
        }
        Ok(Self { states, parameters, inputs, outputs })
    }

    /// State names, in state order.
    pub fn states(&self) -> &[String] {
        &self.states
    }
    /// Parameter names, in parameter order.
    pub fn parameters(&self) -> &[String] {
        &self.parameters
    }
    /// Input names, in the order of the `u` slice.
    pub fn inputs(&self) -> &[String] {
        &self.inputs
    }
    /// Names of the outputs computed by [`System::outputs`] (states are observable without
    /// being listed here).
    pub fn outputs(&self) -> &[String] {
        &self.outputs
    }
    /// Number of states n.
    pub fn n_states(&self) -> usize {
        self.states.len()
    }
    /// Number of parameters.
    pub fn n_parameters(&self) -> usize {
        self.parameters.len()
    }
    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.inputs.len()
    }
    /// Index of a state by name.
    pub fn state(&self, name: &str) -> Option<usize> {
        self.states.iter().position(|s| s == name)
    }
    /// Index of a parameter by name.
    pub fn parameter(&self, name: &str) -> Option<usize> {
        self.parameters.iter().position(|s| s == name)
    }
    /// What a name refers to as a measurable quantity: a state or an output.
    pub fn observable(&self, name: &str) -> Option<Observable> {
        self.state(name)
            .map(Observable::State)
            .or_else(|| self.outputs.iter().position(|s| s == name).map(Observable::Output))
    }
    /// The name of an observable.
    pub fn observable_name(&self, observable: Observable) -> &str {
        match observable {
            Observable::State(i) => &self.states[i],
            Observable::Output(j) => &self.outputs[j],
        }
    }
}

/// Which function of the system to differentiate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Function {
    /// The right-hand side g (length n).
    Rhs,
    /// The outputs h (length of the signature's outputs).
    Outputs,
}

/// A measurable quantity: one state, or one output function h_o(t, y, α, u).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Observable {
    /// The state with this index.
    State(usize),
    /// The output with this index in [`Signature::outputs`].
    Output(usize),
}

/// A dynamic system dy/dt = g(t, y, α, u(t)).
///
/// The implementer's contract:
/// * [`signature`](System::signature) names the states, parameters, inputs and outputs; the
///   slices passed to [`rhs`](System::rhs) have those lengths, in that order.
/// * [`rhs`](System::rhs) is a pure function of its arguments, written once for any
///   [`Scalar`]. Evaluated with dual numbers it gives exact Jacobian products, which is how
///   sysid integrates sensitivities; no Jacobian has to be written by hand.
/// * Input signals are evaluated by [`input_values`](System::input_values) (default: no
///   inputs). Times where an input jumps are listed by
///   [`discontinuities`](System::discontinuities); the integrators stop exactly on them and
///   evaluate each side with the input's limit from that side ([`Side`]).
/// * A system may supply analytic Jacobians by overriding [`jacobians`](System::jacobians) and
///   returning `true` from [`analytic_jacobians`](System::analytic_jacobians); sensitivities
///   are then formed as J_y S + J_α instead of with dual numbers.
/// * A system that differentiates itself (model files do, symbolically) may return its
///   right-hand side and outputs with their sparse Jacobians from
///   [`sparse_jacobian`](System::sparse_jacobian); every Jacobian product is then taken from
///   it instead of from dual numbers.
///
/// ```
/// use sysid_ode::{Scalar, Signature, System};
/// /// dx/dt = -k x
/// struct Decay(Signature);
/// impl System for Decay {
///     fn signature(&self) -> &Signature { &self.0 }
///     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
///         dy[0] = -p[0] * y[0];
///     }
/// }
/// let decay = Decay(Signature::new(&["x"], &["k"]));
/// assert_eq!(decay.signature().n_states(), 1);
/// ```
pub trait System: Send + Sync {
    /// Names and dimensions.
    fn signature(&self) -> &Signature;

    /// The right-hand side dy = g(t, y, α, u).
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], dy: &mut [T]);

    /// Output functions h(t, y, α, u) for the outputs named in the signature (default: none).
    fn outputs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], h: &mut [T]) {
        let _ = (t, y, p, u, h);
    }

    /// The input signals at time t, with the limit from `side` where an input jumps at t.
    fn input_values(&self, t: f64, side: Side, u: &mut [f64]) {
        let _ = (t, side, u);
    }

    /// Whether g depends on t neither directly nor through inputs (between the
    /// [`switches`](Self::switches)): a Rosenbrock step then takes ∂g/∂t = 0 instead of
    /// differencing it. Default: false.
    fn autonomous(&self) -> bool {
        false
    }

    /// Times where an input (or the right-hand side) is discontinuous, ascending.
    fn discontinuities(&self) -> &[f64] {
        &[]
    }

    /// Times where the right-hand side switches at the parameters `p` (a model file's
    /// `if(le(t, t_end), …)`): the integrators stop there too, as at
    /// [`discontinuities`](Self::discontinuities). Default: none.
    fn switches(&self, p: &[f64]) -> Vec<f64> {
        let _ = p;
        Vec::new()
    }

    /// The [`switches`](Self::switches) that move with a parameter, at the parameters `p`:
    /// each one's time τ, the parameter's index q and ∂τ/∂α_q. Where the right-hand side
    /// switches from g₋ to g₊ at τ(α), the sensitivity with respect to α_q jumps there by
    /// (g₋ − g₊)·∂τ/∂α_q (the state is continuous, the switch moves). Default: none.
    fn moving_switches(&self, p: &[f64]) -> Vec<(f64, usize, f64)> {
        let _ = p;
        Vec::new()
    }

    /// How many state events the system has: conditions on the state whose crossing resets
    /// it ([`event_condition`](Self::event_condition), [`event_reset`](Self::event_reset)).
    /// Default: none.
    fn n_events(&self) -> usize {
        0
    }

    /// Event i's condition c_i(t, y, α): the event fires where c_i falls from positive to
    /// zero or below, integrating forward (its trigger turning true); the integrators locate
    /// that time τ by root finding on the step's interpolant. Only called for
    /// i < [`n_events`](Self::n_events).
    fn event_condition<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T]) -> T {
        let _ = (i, t, y, p);
        T::from(1.0)
    }

    /// The state just after event i fires at (τ, y): y⁺ = r_i(τ, y, α), written into
    /// `y_new` (which holds y on entry: components the event leaves alone may stay).
    /// The sensitivities jump with it: S⁺ = R_y S + R_α + (R_y g⁻ − g⁺)·∂τ/∂z, where
    /// ∂τ/∂z = −(c_y S + c_α)/(c_y g⁻ + c_t) moves the event with the unknowns.
    fn event_reset<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T], y_new: &mut [T]) {
        let _ = (i, t, y, p, y_new);
    }

    /// The right-hand side (or the outputs) with the nonzero entries of its Jacobian, for
    /// systems that can evaluate them directly (default: none, dual numbers are used).
    fn sparse_jacobian(&self, function: Function) -> Option<&dyn SparseJacobian> {
        let _ = function;
        None
    }

    /// Whether [`jacobians`](System::jacobians) is hand-written and should be used for
    /// sensitivities instead of dual numbers.
    fn analytic_jacobians(&self) -> bool {
        false
    }

    /// The Jacobians J_y = ∂g/∂y (n × n) and J_α = ∂g/∂α (n × n_α) at a point. Default: exact,
    /// by one dual-number evaluation per column.
    fn jacobians(
        &self,
        t: f64,
        y: &[f64],
        p: &[f64],
        u: &[f64],
        jy: &mut DMatrix<f64>,
        jp: &mut DMatrix<f64>,
    ) {
        let n = y.len();
        let np = p.len();
        let mut yd: Vec<Dual64> = y.iter().map(|&v| Dual64::from_re(v)).collect();
        let mut pd: Vec<Dual64> = p.iter().map(|&v| Dual64::from_re(v)).collect();
        let mut dy = vec![Dual64::from_re(0.0); n];
        for j in 0..n {
            yd[j].eps = 1.0;
            self.rhs(t, &yd, &pd, u, &mut dy);
            yd[j].eps = 0.0;
            for i in 0..n {
                jy[(i, j)] = dy[i].eps;
            }
        }
        for k in 0..np {
            pd[k].eps = 1.0;
            self.rhs(t, &yd, &pd, u, &mut dy);
            pd[k].eps = 0.0;
            for i in 0..n {
                jp[(i, k)] = dy[i].eps;
            }
        }
    }
}

impl<S: System> System for &S {
    fn signature(&self) -> &Signature {
        (**self).signature()
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], dy: &mut [T]) {
        (**self).rhs(t, y, p, u, dy)
    }
    fn outputs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], h: &mut [T]) {
        (**self).outputs(t, y, p, u, h)
    }
    fn input_values(&self, t: f64, side: Side, u: &mut [f64]) {
        (**self).input_values(t, side, u)
    }
    fn autonomous(&self) -> bool {
        (**self).autonomous()
    }
    fn discontinuities(&self) -> &[f64] {
        (**self).discontinuities()
    }
    fn switches(&self, p: &[f64]) -> Vec<f64> {
        (**self).switches(p)
    }
    fn moving_switches(&self, p: &[f64]) -> Vec<(f64, usize, f64)> {
        (**self).moving_switches(p)
    }
    fn n_events(&self) -> usize {
        (**self).n_events()
    }
    fn event_condition<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T]) -> T {
        (**self).event_condition(i, t, y, p)
    }
    fn event_reset<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T], y_new: &mut [T]) {
        (**self).event_reset(i, t, y, p, y_new)
    }
    fn sparse_jacobian(&self, function: Function) -> Option<&dyn SparseJacobian> {
        (**self).sparse_jacobian(function)
    }
    fn analytic_jacobians(&self) -> bool {
        (**self).analytic_jacobians()
    }
    fn jacobians(
        &self,
        t: f64,
        y: &[f64],
        p: &[f64],
        u: &[f64],
        jy: &mut DMatrix<f64>,
        jp: &mut DMatrix<f64>,
    ) {
        (**self).jacobians(t, y, p, u, jy, jp)
    }
}

/// The simple case of a [`System`]: y' = f(t, y, α) with named states and parameters, no
/// inputs and no outputs (the states are what is measured). Implement it on a type of your
/// own and wrap it with [`OdeSystem::new`] (or `Problem::ode` in sysid-core) where a
/// [`System`] is wanted; implement [`System`] instead for inputs, outputs, switches or
/// hand-written Jacobians. Derive `Clone` (and `Debug`) on the type for the Monte-Carlo
/// studies and basin maps, which copy the system into each trial.
///
/// ```
/// use sysid_ode::{Ode, OdeSystem, Scalar, System};
/// /// dx/dt = −k x
/// struct Decay;
/// impl Ode for Decay {
///     const STATES: &[&str] = &["x"];
///     const PARAMETERS: &[&str] = &["k"];
///     fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], dy: &mut [T]) {
///         dy[0] = -(p[0] * y[0]);
///     }
/// }
/// let decay = OdeSystem::new(Decay);
/// assert_eq!(decay.signature().n_states(), 1);
/// assert_eq!(decay.signature().parameters(), ["k"]);
/// ```
pub trait Ode: Send + Sync {
    /// The states' names, in the order of y.
    const STATES: &'static [&'static str];
    /// The parameters' names, in the order of α.
    const PARAMETERS: &'static [&'static str];
    /// Whether f depends on t only through y (default: false). A Rosenbrock step then takes
    /// ∂f/∂t = 0 instead of differencing it.
    const AUTONOMOUS: bool = false;

    /// The right-hand side dy = f(t, y, α), written once for any [`Scalar`] so that the
    /// sensitivities come from dual numbers.
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], dy: &mut [T]);
}

/// An [`Ode`] as a [`System`]: the signature built once from its names.
#[derive(Debug, Clone)]
pub struct OdeSystem<O> {
    ode: O,
    signature: Signature,
}

impl<O: Ode> OdeSystem<O> {
    /// The system of `ode`.
    pub fn new(ode: O) -> Self {
        OdeSystem { ode, signature: Signature::new(O::STATES, O::PARAMETERS) }
    }

    /// The wrapped equations.
    pub fn ode(&self) -> &O {
        &self.ode
    }
}

impl<O: Ode> System for OdeSystem<O> {
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        self.ode.rhs(t, y, p, dy)
    }
    fn autonomous(&self) -> bool {
        O::AUTONOMOUS
    }
}
