//! Lotka–Volterra predator and prey: x' = a x − b x y, y' = d x y − g y.

use sysid_core::Unknown;
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::case::{Case, DataSource, Noise, grid};

/// x' = a x − b x y, y' = d x y − g y: states x, y; parameters a, b, g, d.
#[derive(Clone, Debug)]
pub struct LotkaVolterra(Signature);

impl Default for LotkaVolterra {
    fn default() -> Self {
        Self(Signature::new(&["x", "y"], &["a", "b", "g", "d"]))
    }
}

impl LotkaVolterra {
    /// The same system with one output, `total` = x + y: both populations counted together,
    /// for measuring what is not a state.
    pub fn with_total() -> Self {
        Self(Signature::new(&["x", "y"], &["a", "b", "g", "d"]).with_outputs(&["total"]))
    }
}

impl System for LotkaVolterra {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let (x, z) = (y[0], y[1]);
        let (a, b, g, d) = (p[0], p[1], p[2], p[3]);
        dy[0] = a * x - b * x * z;
        dy[1] = d * x * z - g * z;
    }
    fn outputs<T: Scalar>(&self, _t: f64, y: &[T], _p: &[T], _u: &[f64], h: &mut [T]) {
        h[0] = y[0] + y[1];
    }
}

/// `lotka-volterra`: the four rates from both populations every 0.1 on [0, 10], σ = 0.1.
pub fn lotka_volterra() -> Case<LotkaVolterra> {
    Case {
        name: "lotka-volterra",
        time_unit: "dimensionless",
        summary: "Lotka–Volterra, a = 1.5, b = 1, g = 3, d = 1: x, y at t = 0, 0.1, …, 10, σ = 0.1; a, b, g, d",
        system: LotkaVolterra::default(),
        t0: 0.0,
        known: vec![("x", 1.0), ("y", 1.0)],
        unknowns: vec![
            Unknown::new("a", 1.2),
            Unknown::new("b", 0.8),
            Unknown::new("g", 2.5),
            Unknown::new("d", 0.8),
        ],
        integrator: Integrator::dopri5(1e-8, 1e-10),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.1, 101),
            noise: vec![Noise::absolute("x", 0.1), Noise::absolute("y", 0.1)],
        },
        truth: vec![("a", 1.5), ("b", 1.0), ("g", 3.0), ("d", 1.0)],
        reference: None,
    }
}
