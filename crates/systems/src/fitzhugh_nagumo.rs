//! FitzHugh–Nagumo neuron: V' = c (V − V³/3 + R), R' = −(V − a + b R)/c.

use sysid_core::Unknown;
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::case::{Case, DataSource, Noise, grid};

/// V' = c (V − V³/3 + R), R' = −(V − a + b R)/c: states V, R; parameters a, b, c.
#[derive(Clone, Debug)]
pub struct FitzHughNagumo(Signature);

impl Default for FitzHughNagumo {
    fn default() -> Self {
        Self(Signature::new(&["V", "R"], &["a", "b", "c"]))
    }
}

impl System for FitzHughNagumo {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let (v, r) = (y[0], y[1]);
        let (a, b, c) = (p[0], p[1], p[2]);
        dy[0] = c * (v - v * v * v / 3.0 + r);
        dy[1] = -(v - a + b * r) / c;
    }
}

/// `fitzhugh-nagumo`: a, b, c from both variables every 0.05 on [0, 20], σ = 0.05.
pub fn fitzhugh_nagumo() -> Case<FitzHughNagumo> {
    Case {
        name: "fitzhugh-nagumo",
        time_unit: "dimensionless",
        summary: "FitzHugh–Nagumo, a = b = 0.2, c = 3: V, R at t = 0, 0.05, …, 20, σ = 0.05; a, b, c",
        system: FitzHughNagumo::default(),
        t0: 0.0,
        known: vec![("V", -1.0), ("R", 1.0)],
        unknowns: vec![Unknown::new("a", 0.3), Unknown::new("b", 0.3), Unknown::new("c", 2.5)],
        integrator: Integrator::dopri5(1e-8, 1e-10),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.05, 401),
            noise: vec![Noise::absolute("V", 0.05), Noise::absolute("R", 0.05)],
        },
        truth: vec![("a", 0.2), ("b", 0.2), ("c", 3.0)],
        reference: None,
    }
}
