//! Robertson's chemical kinetics (1966), the classical stiff test problem:
//! y1' = −k1 y1 + k3 y2 y3, y2' = k1 y1 − k2 y2² − k3 y2 y3, y3' = k2 y2².
//!
//! The rate constants span nine decades (k1 = 0.04, k2 = 3e7, k3 = 1e4): y2 relaxes in
//! 1e-5 s while y1 and y3 change over 1e4 s, so an explicit integrator's step is bound by
//! stability. The case is fitted with Rodas4.

use sysid_core::Unknown;
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::case::{Case, DataSource, Noise};

/// Robertson's kinetics: states y1, y2, y3; parameters k1, k2, k3.
#[derive(Clone, Debug)]
pub struct Robertson(Signature);

impl Default for Robertson {
    fn default() -> Self {
        Self(Signature::new(&["y1", "y2", "y3"], &["k1", "k2", "k3"]))
    }
}

impl System for Robertson {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let (k1, k2, k3) = (p[0], p[1], p[2]);
        let slow = k3 * y[1] * y[2];
        let fast = k2 * y[1] * y[1];
        dy[0] = -k1 * y[0] + slow;
        dy[1] = k1 * y[0] - fast - slow;
        dy[2] = fast;
    }
}

/// The measurement times: 20 log-spaced from 0.01 to 100, t_m = 10^(−2 + 4m/19).
pub fn times() -> Vec<f64> {
    (0..20).map(|m| 10f64.powf(-2.0 + 4.0 * m as f64 / 19.0)).collect()
}

/// The true rate constants.
pub const RATES: [(&str, f64); 3] = [("k1", 0.04), ("k2", 3e7), ("k3", 1e4)];

/// `robertson`: the three rate constants, on a log scale, from y1 and y3 with 1 % noise.
pub fn robertson() -> Case<Robertson> {
    // The default start: every rate constant a factor 10^0.3 ≈ 2 above the truth.
    let start = |k: f64| k * 10f64.powf(0.3);
    Case {
        name: "robertson",
        time_unit: "s",
        summary: "Robertson's stiff kinetics, k = (0.04, 3e7, 1e4): y1, y3 at 20 log-spaced t in [0.01, 100], 1 % relative noise; k1, k2, k3 on a log scale",
        system: Robertson::default(),
        t0: 0.0,
        known: vec![("y1", 1.0), ("y2", 0.0), ("y3", 0.0)],
        unknowns: RATES.iter().map(|&(name, k)| Unknown::new(name, start(k)).log()).collect(),
        // y3 starts at 3e-4 and the sensitivities ∂y/∂k2 are of order 1e-11: the absolute
        // tolerance sits below both.
        integrator: Integrator::rodas4(1e-8, 1e-16),
        data: DataSource::Synthetic {
            times: times(),
            noise: vec![Noise::relative("y1", 0.01), Noise::relative("y3", 0.01)],
        },
        truth: RATES.to_vec(),
        reference: None,
    }
}
