//! A linear compartment chain with bounds: populations passed down eight stages, each with a
//! transfer and a loss rate, all of them non-negative, and a loss rate on its bound at the
//! optimum. The catalogue's bounded system: 23 unknowns, raw (unweighted) counts.

use sysid_core::Unknown;
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::case::{Case, DataSource, Noise, grid};

/// Compartments in a chain: x1' = −(k1 + d1) x1, x_i' = k_{i−1} x_{i−1} − (k_i + d_i) x_i,
/// x_n' = k_{n−1} x_{n−1} − d_n x_n: transfer rates k and loss rates d.
#[derive(Clone, Debug)]
pub struct Chain {
    signature: Signature,
    n: usize,
}

impl Chain {
    /// A chain of `n` compartments x1..xn with transfer rates k1..k(n−1) and loss rates
    /// d1..dn (parameters in that order).
    pub fn new(n: usize) -> Self {
        let states: Vec<String> = (1..=n).map(|i| format!("x{i}")).collect();
        let mut parameters: Vec<String> = (1..n).map(|i| format!("k{i}")).collect();
        parameters.extend((1..=n).map(|i| format!("d{i}")));
        let s: Vec<&str> = states.iter().map(String::as_str).collect();
        let p: Vec<&str> = parameters.iter().map(String::as_str).collect();
        Self { signature: Signature::new(&s, &p), n }
    }
}

impl System for Chain {
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let n = self.n;
        let (k, d) = p.split_at(n - 1);
        for i in 0..n {
            let mut out = d[i] * y[i];
            if i + 1 < n {
                out += k[i] * y[i];
            }
            dy[i] = -out;
            if i > 0 {
                dy[i] += k[i - 1] * y[i - 1];
            }
        }
    }
}

/// `compartment-chain`: 8 compartments, every state measured 30 times with σ = 100, fitted
/// unweighted (residual norm about 1.5e3, as a user fitting raw counts would); 23 unknowns
/// ≥ 0. The data were made with d1 = −0.01 (a source, not a loss), so the bounded optimum has
/// d1 = 0 on its bound, and every other rate inside.
pub fn compartment_chain() -> Case<Chain> {
    const K: [&str; 7] = ["k1", "k2", "k3", "k4", "k5", "k6", "k7"];
    const D: [&str; 8] = ["d1", "d2", "d3", "d4", "d5", "d6", "d7", "d8"];
    const X: [&str; 8] = ["x1", "x2", "x3", "x4", "x5", "x6", "x7", "x8"];
    let k = [0.4, 0.35, 0.3, 0.25, 0.3, 0.35, 0.4];
    let d = [-0.01, 0.08, 0.05, 0.1, 0.07, 0.05, 0.08, 0.06];
    let x0 = [50000.0, 30000.0, 20000.0, 10000.0, 8000.0, 6000.0, 4000.0, 2000.0];
    let mut truth: Vec<(&'static str, f64)> = K.into_iter().zip(k).collect();
    truth.extend(D.into_iter().zip(d));
    truth.extend(X.into_iter().zip(x0));
    // Starts 30 % off in alternating directions, inside the bounds.
    let unknowns = truth
        .iter()
        .enumerate()
        .map(|(i, (name, v))| {
            let f = if i % 2 == 0 { 1.3 } else { 0.7 };
            Unknown::new(*name, (v * f).abs().max(0.005)).min(0.0)
        })
        .collect();
    Case {
        name: "compartment-chain",
        summary: "8 compartments in a chain, 15 rates ≥ 0 and 8 initial values ≥ 0, σ = 100 unweighted; d1 on its bound 0",
        time_unit: "h",
        system: Chain::new(X.len()),
        t0: 0.0,
        known: vec![],
        unknowns,
        integrator: Integrator::default(),
        data: DataSource::Synthetic {
            times: grid(0.0, 1.0, 30),
            noise: X.iter().map(|x| Noise::absolute(x, 100.0).unweighted()).collect(),
        },
        truth,
        reference: None,
    }
}
