//! Test systems with closed-form solutions.
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

/// y' = v, v' = g (Goodman's falling body).
pub struct FallingBody(pub Signature);
impl FallingBody {
    pub fn new() -> Self {
        Self(Signature::new(&["y", "v"], &["g"]))
    }
}
impl System for FallingBody {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = y[1];
        dy[1] = p[0];
    }
}

/// x' = v, v' = −x + μ (1 − x²) v.
pub struct VanDerPol(pub Signature);
impl VanDerPol {
    pub fn new() -> Self {
        Self(Signature::new(&["x", "v"], &["mu"]))
    }
}
impl System for VanDerPol {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = y[1];
        dy[1] = -y[0] + p[0] * (-(y[0] * y[0]) + 1.0) * y[1];
    }
}

/// x' = a x − b x y, y' = d x y − g y, with an output "total" = x + y.
pub struct LotkaVolterra(pub Signature);
impl LotkaVolterra {
    pub fn new() -> Self {
        Self(Signature::new(&["x", "y"], &["a", "b", "g", "d"]).with_outputs(&["total"]))
    }
}
impl System for LotkaVolterra {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = p[0] * y[0] - p[1] * y[0] * y[1];
        dy[1] = p[3] * y[0] * y[1] - p[2] * y[1];
    }
    fn outputs<T: Scalar>(&self, _t: f64, y: &[T], _p: &[T], _u: &[f64], h: &mut [T]) {
        h[0] = y[0] + y[1];
    }
}

/// Robertson's chemical kinetics (Hairer & Wanner, Solving ODE II, IV.1):
/// y1' = −k1 y1 + k3 y2 y3, y2' = k1 y1 − k2 y2² − k3 y2 y3, y3' = k2 y2².
pub struct Robertson(pub Signature);
impl Robertson {
    pub fn new() -> Self {
        Self(Signature::new(&["y1", "y2", "y3"], &["k1", "k2", "k3"]))
    }
    /// The classical rate constants.
    pub const RATES: [f64; 3] = [0.04, 3e7, 1e4];
}
impl System for Robertson {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let (fast, slow) = (p[1] * y[1] * y[1], p[2] * y[1] * y[2]);
        dy[0] = -p[0] * y[0] + slow;
        dy[1] = p[0] * y[0] - fast - slow;
        dy[2] = fast;
    }
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
