//! Stress cases for the certificate and the methods' honesty: problems built to break a
//! method's own stopping rule, not part of the benchmark catalogue. Tests run every method on
//! them and check that every claim of convergence survives an independent search.
//!
//! | name | what it stresses |
//! |---|---|
//! | `rate-on-bound` | A → B (k1), A → C (k2), k ≥ 0; the data were made with k2 = −0.03, so the bounded optimum has k2 = 0 on its bound |
//! | `outlier` | x' = −kx with σ = 0.01 data and one outlier of 1e3: weighted residual norm ≈ 1e5 |
//! | `slow-rates` | A → B → C with k1 = 2e-5 /s, k2 = 1e-5 /s on a linear scale, data of order 1e2 over 3e5 s |
//! | `two-sided-bound` | x' = −kx with 0.1 ≤ k ≤ 0.6 and data from k = 0.8: the optimum has k on its upper bound |
//! | `runaway` | y' = −k (y − cos t) from k = 10: a full Newton step makes k negative, and the solution grows like e^{28 t} |
//! | `vanishing-component` | y1 + y2 measured, y2 absent from the data: as y2(0) → 0 (its bound), k2 stops influencing the data (a singular direction away from the start) |

use sysid_core::{Data, Unknown};
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::Visit;
use crate::case::{Case, DataSource, Noise, grid};

/// Names of the stress cases.
pub const NAMES: &[&str] = &[
    "rate-on-bound",
    "two-sided-bound",
    "outlier",
    "slow-rates",
    "runaway",
    "vanishing-component",
];

/// Calls `visitor` with the stress case named `name`, or returns `None`.
pub fn visit<V: Visit>(name: &str, visitor: V) -> Option<V::Output> {
    Some(match name {
        "rate-on-bound" => visitor.visit(rate_on_bound()),
        "outlier" => visitor.visit(outlier()),
        "slow-rates" => visitor.visit(slow_rates()),
        "two-sided-bound" => visitor.visit(two_sided_bound()),
        "runaway" => visitor.visit(runaway()),
        "vanishing-component" => visitor.visit(vanishing_component()),
        _ => return None,
    })
}

/// A → B at rate k1 and A → C at rate k2: A' = −(k1 + k2) A, B' = k1 A, C' = k2 A.
#[derive(Clone, Debug)]
pub struct Branching(Signature);

impl Default for Branching {
    fn default() -> Self {
        Self(Signature::new(&["A", "B", "C"], &["k1", "k2"]))
    }
}

impl System for Branching {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -(p[0] + p[1]) * y[0];
        dy[1] = p[0] * y[0];
        dy[2] = p[1] * y[0];
    }
}

/// `rate-on-bound`: the bounded optimum has k2 = 0 on its lower bound.
pub fn rate_on_bound() -> Case<Branching> {
    Case {
        name: "rate-on-bound",
        summary: "A → B (k1), A → C (k2), k ≥ 0; data made with k2 = −0.03: the optimum has k2 on its bound 0",
        time_unit: "min",
        system: Branching::default(),
        t0: 0.0,
        known: vec![("A", 1.0), ("B", 0.0), ("C", 0.0)],
        unknowns: vec![Unknown::new("k1", 0.5).min(0.0), Unknown::new("k2", 0.2).min(0.0)],
        integrator: Integrator::default(),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.5, 21),
            noise: vec![Noise::absolute("A", 0.01), Noise::absolute("B", 0.01)],
        },
        truth: vec![("k1", 0.3), ("k2", -0.03)],
        reference: None,
    }
}

/// x' = −k x, the ode crate's closed-form test system (one declaration for the workspace).
pub use sysid_ode::testing::Decay;

/// `outlier`: 2 e^{−0.8 t} with σ = 0.01 (deterministic pseudo-noise) and 1e3 added to the
/// sample at t = 5; weight 1/σ² = 1e4, so the outlier's weighted residual is about 1e5.
pub fn outlier() -> Case<Decay> {
    fn data() -> Data {
        let times = grid(0.0, 0.5, 21);
        let values: Vec<f64> = times
            .iter()
            .enumerate()
            .map(|(m, &t)| {
                let outlier = if m == 10 { 1e3 } else { 0.0 };
                2.0 * (-0.8 * t).exp() + 0.01 * (7.0 * m as f64).sin() + outlier
            })
            .collect();
        Data::discrete().weighted_series("x", 1e4, &times, &values)
    }
    Case {
        name: "outlier",
        summary: "x' = −kx, σ = 0.01 data with one outlier of 1e3: weighted residual norm about 1e5",
        time_unit: "s",
        system: Decay::default(),
        t0: 0.0,
        known: vec![],
        unknowns: vec![Unknown::new("x", 1.5), Unknown::new("k", 0.5)],
        integrator: Integrator::default(),
        data: DataSource::Fixed(data),
        truth: vec![("x", 2.0), ("k", 0.8)],
        reference: None,
    }
}

/// `two-sided-bound`: 2 e^{−0.8 t} with σ = 0.01, k bounded to [0.1, 0.6]: the bounded
/// optimum has k = 0.6 on its upper bound, and x(0) free.
pub fn two_sided_bound() -> Case<Decay> {
    Case {
        name: "two-sided-bound",
        summary: "x' = −kx, data from k = 0.8, 0.1 ≤ k ≤ 0.6: the optimum has k on its upper bound",
        time_unit: "s",
        system: Decay::default(),
        t0: 0.0,
        known: vec![],
        unknowns: vec![Unknown::new("x", 1.5), Unknown::new("k", 0.2).min(0.1).max(0.6)],
        integrator: Integrator::default(),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.25, 21),
            noise: vec![Noise::absolute("x", 0.01)],
        },
        truth: vec![("x", 2.0), ("k", 0.8)],
        reference: None,
    }
}

/// A → B → C at rates k1, k2: A' = −k1 A, B' = k1 A − k2 B, C' = k2 B.
#[derive(Clone, Debug)]
pub struct Consecutive(Signature);

impl Default for Consecutive {
    fn default() -> Self {
        Self(Signature::new(&["A", "B", "C"], &["k1", "k2"]))
    }
}

impl System for Consecutive {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * y[0];
        dy[1] = p[0] * y[0] - p[1] * y[1];
        dy[2] = p[1] * y[1];
    }
}

/// `slow-rates`: rates of order 1e-5 /s on a linear scale, concentrations of order 1e2.
pub fn slow_rates() -> Case<Consecutive> {
    Case {
        name: "slow-rates",
        summary: "A → B → C, k1 = 2e-5 /s, k2 = 1e-5 /s (linear scale), B and C of order 1e2 over 3e5 s",
        time_unit: "s",
        system: Consecutive::default(),
        t0: 0.0,
        known: vec![("A", 100.0), ("B", 0.0), ("C", 0.0)],
        unknowns: vec![Unknown::new("k1", 3e-5).min(0.0), Unknown::new("k2", 0.7e-5).min(0.0)],
        integrator: Integrator::default(),
        data: DataSource::Synthetic {
            times: grid(0.0, 1e4, 31),
            noise: vec![Noise::absolute("B", 0.5), Noise::absolute("C", 0.5)],
        },
        truth: vec![("k1", 2e-5), ("k2", 1e-5)],
        reference: None,
    }
}

/// y' = −k (y − cos t): y relaxes towards cos t at rate k.
#[derive(Clone, Debug)]
pub struct Tracking(Signature);

impl Default for Tracking {
    fn default() -> Self {
        Self(Signature::new(&["y"], &["k"]))
    }
}

impl System for Tracking {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * (y[0] - t.cos());
    }
}

/// `runaway`: data made with k = 1, start k = 10.
pub fn runaway() -> Case<Tracking> {
    Case {
        name: "runaway",
        summary: "y' = −k (y − cos t), data from k = 1, start k = 10: a full step makes k negative",
        time_unit: "s",
        system: Tracking::default(),
        t0: 0.0,
        known: vec![("y", 1.0)],
        unknowns: vec![Unknown::new("k", 10.0)],
        integrator: Integrator::default(),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.25, 41),
            noise: vec![Noise::absolute("y", 0.01)],
        },
        truth: vec![("k", 1.0)],
        reference: None,
    }
}

/// Two independent decays, y1' = −k1 y1, y2' = −k2 y2, measured only as their sum h.
#[derive(Clone, Debug)]
pub struct TwoDecays(Signature);

impl Default for TwoDecays {
    fn default() -> Self {
        Self(Signature::new(&["y1", "y2"], &["k1", "k2"]).with_outputs(&["h"]))
    }
}

impl System for TwoDecays {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * y[0];
        dy[1] = -p[1] * y[1];
    }
    fn outputs<T: Scalar>(&self, _t: f64, y: &[T], _p: &[T], _u: &[f64], h: &mut [T]) {
        h[0] = y[0] + y[1];
    }
}

/// `vanishing-component`: h = e^{−0.5 t} plus pseudo-noise; the start has a second
/// component y2(0) = 0.5 ≥ 0 decaying at k2 = 2 ∈ [0.01, 10]. Where y2(0) reaches 0, k2 has
/// no influence on the data.
pub fn vanishing_component() -> Case<TwoDecays> {
    fn data() -> Data {
        let times = grid(0.0, 0.5, 21);
        let values: Vec<f64> = times
            .iter()
            .enumerate()
            .map(|(m, &t)| (-0.5 * t).exp() + 0.001 * (3.0 * m as f64).sin())
            .collect();
        Data::discrete().weighted_series("h", 1e6, &times, &values)
    }
    Case {
        name: "vanishing-component",
        summary: "y1 + y2 measured, data from y1 alone: k2 loses its influence as y2(0) → 0",
        time_unit: "s",
        system: TwoDecays::default(),
        t0: 0.0,
        known: vec![],
        unknowns: vec![
            Unknown::new("y1", 0.8),
            Unknown::new("y2", 0.5).min(0.0),
            Unknown::new("k1", 0.7),
            Unknown::new("k2", 2.0).min(0.01).max(10.0),
        ],
        integrator: Integrator::default(),
        data: DataSource::Fixed(data),
        truth: vec![("y1", 1.0), ("y2", 0.0), ("k1", 0.5), ("k2", 2.0)],
        reference: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stress_case_builds() {
        struct Build;
        impl Visit for Build {
            type Output = &'static str;
            fn visit<S: System + Clone + Send + Sync + 'static>(self, c: Case<S>) -> Self::Output {
                c.problem(1).unwrap_or_else(|e| panic!("{}: {e}", c.name));
                c.name
            }
        }
        for name in NAMES {
            assert_eq!(visit(name, Build), Some(*name));
        }
    }
}
