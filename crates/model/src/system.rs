//! The [`System`] a model file describes.

use std::sync::Arc;

use sysid_ode::{Function, Inputs, Scalar, Side, Signature, SparseJacobian, System};

use crate::expr::{Program, Switch};
use crate::file::EventSpec;
use crate::symbolic::Linearized;

/// A model read from a file: compiled right-hand sides and outputs, their symbolic
/// Jacobians, and its input signals. Cheap to clone (the programs are shared).
#[derive(Clone, Debug)]
pub struct ModelSystem {
    signature: Signature,
    equations: Arc<Vec<Program>>,
    outputs: Arc<Vec<Program>>,
    /// The right-hand side and the outputs with their Jacobians, or `None` to differentiate
    /// by dual numbers.
    symbolic: Option<Arc<(Linearized, Linearized)>>,
    inputs: Inputs,
    /// Where the right-hand side switches in time.
    switches: Arc<Vec<Switch>>,
    /// Whether the equations do not mention t outside their switches in time.
    time_free: bool,
    /// The state events (`[[events]]`).
    events: Arc<Vec<EventSpec>>,
}

impl ModelSystem {
    /// The system of compiled equations and outputs, driven by `inputs`; its Jacobians are
    /// derived symbolically here, once.
    pub fn new(
        signature: Signature,
        equations: Vec<Program>,
        outputs: Vec<Program>,
        inputs: Inputs,
    ) -> Self {
        let dims = (signature.n_states(), signature.n_parameters(), signature.n_inputs());
        // The outputs are differentiated and compiled beside the equations.
        let symbolic = std::thread::scope(|scope| {
            let outputs = scope.spawn(|| Linearized::new(&outputs, dims));
            let equations = Linearized::with_curvature(&equations, dims);
            (equations, outputs.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
        });
        let time_free = symbolic.0.independent_of_time();
        let mut switches: Vec<Switch> = Vec::new();
        for s in equations.iter().flat_map(Program::time_switches) {
            if !switches.contains(&s) {
                switches.push(s);
            }
        }
        Self {
            switches: Arc::new(switches),
            time_free,
            signature,
            equations: Arc::new(equations),
            outputs: Arc::new(outputs),
            symbolic: Some(Arc::new(symbolic)),
            inputs,
            events: Arc::new(Vec::new()),
        }
    }

    /// The same system with state events.
    pub fn with_events(self, events: Vec<EventSpec>) -> Self {
        Self { events: Arc::new(events), ..self }
    }

    /// The same equations with other input signals.
    pub fn with_inputs(&self, inputs: Inputs) -> Self {
        Self { inputs, ..self.clone() }
    }

    /// The same system differentiated by dual numbers instead of its symbolic Jacobians:
    /// the reference the symbolic derivatives are tested against.
    pub fn with_dual_numbers(&self) -> Self {
        Self { symbolic: None, ..self.clone() }
    }

    /// The right-hand side with its symbolic Jacobian, unless differentiated by dual numbers.
    pub fn symbolic_rhs(&self) -> Option<&Linearized> {
        self.symbolic.as_deref().map(|s| &s.0)
    }
}

impl System for ModelSystem {
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], dy: &mut [T]) {
        for (d, program) in dy.iter_mut().zip(self.equations.iter()) {
            *d = program.eval(t, y, p, u);
        }
    }
    fn outputs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], h: &mut [T]) {
        for (o, program) in h.iter_mut().zip(self.outputs.iter()) {
            *o = program.eval(t, y, p, u);
        }
    }
    fn input_values(&self, t: f64, side: Side, u: &mut [f64]) {
        self.inputs.eval(t, side, u);
    }
    fn discontinuities(&self) -> &[f64] {
        self.inputs.jumps()
    }
    fn autonomous(&self) -> bool {
        self.time_free && self.signature.n_inputs() == 0
    }
    fn switches(&self, p: &[f64]) -> Vec<f64> {
        self.switches.iter().map(|s| s.at(p)).collect()
    }
    fn moving_switches(&self, p: &[f64]) -> Vec<(f64, usize, f64)> {
        self.switches
            .iter()
            .filter_map(|s| s.parameter.map(|(q, slope)| (s.at(p), q, slope)))
            .collect()
    }
    fn n_events(&self) -> usize {
        self.events.len()
    }
    fn event_condition<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T]) -> T {
        self.events[i].condition.eval(t, y, p, &[])
    }
    fn event_reset<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T], y_new: &mut [T]) {
        for (state, value) in &self.events[i].resets {
            y_new[*state] = value.eval(t, y, p, &[]);
        }
    }
    fn sparse_jacobian(&self, function: Function) -> Option<&dyn SparseJacobian> {
        let symbolic = self.symbolic.as_deref()?;
        Some(match function {
            Function::Rhs => &symbolic.0,
            Function::Outputs => &symbolic.1,
        })
    }
}
