//! Test systems with closed-form solutions, and reference data. The catalogue's systems come
//! from sysid-systems (a dev-dependency only: the ode library itself knows no system).
#![allow(dead_code)]

use nalgebra::DMatrix;
use sysid_ode::{Scalar, Signature, System};

/// x' = v, v' = −ω² x; optionally with hand-written Jacobians.
pub struct Oscillator {
    pub sig: Signature,
    pub analytic: bool,
}
impl Oscillator {
    pub fn new(analytic: bool) -> Self {
        Self { sig: Signature::new(&["x", "v"], &["w"]), analytic }
    }
    /// (x, v, ∂x/∂ω, ∂v/∂ω) at time τ after t0.
    pub fn exact(x0: f64, v0: f64, w: f64, tau: f64) -> (f64, f64, f64, f64) {
        let (s, c) = (w * tau).sin_cos();
        let x = x0 * c + v0 / w * s;
        let v = -x0 * w * s + v0 * c;
        let dx = -x0 * tau * s + v0 * (tau * c / w - s / (w * w));
        let dv = -x0 * (s + w * tau * c) - v0 * tau * s;
        (x, v, dx, dv)
    }
}
impl System for Oscillator {
    fn signature(&self) -> &Signature {
        &self.sig
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = y[1];
        dy[1] = -p[0] * p[0] * y[0];
    }
    fn analytic_jacobians(&self) -> bool {
        self.analytic
    }
    fn jacobians(
        &self,
        _t: f64,
        y: &[f64],
        p: &[f64],
        _u: &[f64],
        jy: &mut DMatrix<f64>,
        jp: &mut DMatrix<f64>,
    ) {
        jy.copy_from_slice(&[0.0, -p[0] * p[0], 1.0, 0.0]);
        jp.copy_from_slice(&[0.0, -2.0 * p[0] * y[0]]);
    }
}

/// Robertson's classical rate constants k1, k2, k3, from the catalogue.
pub fn robertson_rates() -> [f64; 3] {
    sysid_systems::robertson::RATES.map(|(_, k)| k)
}

/// One value of tests/data/stiff_reference.csv (independent scipy Radau IIA solutions):
/// (value, spread between independent runs) of `component` of `problem` at t.
pub fn stiff_reference(problem: &str, t: f64, component: &str) -> (f64, f64) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../tests/data/stiff_reference.csv");
    let text = std::fs::read_to_string(path).expect("tests/data/stiff_reference.csv");
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let time: f64 = f[1].parse().unwrap();
        if f[0] == problem && (time - t).abs() <= 1e-12 * t.abs() && f[2] == component {
            return (f[3].parse().unwrap(), f[4].parse().unwrap());
        }
    }
    panic!("no reference for {problem} {component} at t = {t}");
}
