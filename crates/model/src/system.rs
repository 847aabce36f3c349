//! The [`System`] a model file describes.

use std::sync::Arc;

use sysid_ode::{Inputs, Scalar, Side, Signature, System};

use crate::expr::Program;

/// A model read from a file: compiled right-hand sides and outputs, and its input signals.
/// Cheap to clone (the programs are shared).
#[derive(Clone, Debug)]
pub struct ModelSystem {
    signature: Signature,
    equations: Arc<Vec<Program>>,
    outputs: Arc<Vec<Program>>,
    inputs: Inputs,
}

impl ModelSystem {
    /// The system of compiled equations and outputs, driven by `inputs`.
    pub fn new(
        signature: Signature,
        equations: Vec<Program>,
        outputs: Vec<Program>,
        inputs: Inputs,
    ) -> Self {
        Self { signature, equations: Arc::new(equations), outputs: Arc::new(outputs), inputs }
    }

    /// The same equations with other input signals.
    pub fn with_inputs(&self, inputs: Inputs) -> Self {
        Self { inputs, ..self.clone() }
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
}
