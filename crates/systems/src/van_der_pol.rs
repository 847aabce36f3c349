//! The van der Pol oscillator x' = v, v' = −x + μ (1 − x²) v.

use sysid_core::{Data, Unknown};
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::case::{Case, DataSource, Noise, Reference, grid};

/// x' = v, v' = −x + μ (1 − x²) v: states x, v; parameter mu.
#[derive(Clone, Debug)]
pub struct VanDerPol(Signature);

impl Default for VanDerPol {
    fn default() -> Self {
        Self(Signature::new(&["x", "v"], &["mu"]))
    }
}

impl System for VanDerPol {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let (x, v, mu) = (y[0], y[1], p[0]);
        dy[0] = v;
        dy[1] = -x + mu * (-(x * x) + 1.0) * v;
    }
}

/// `van-der-pol`: μ and both initial values from x measured every 0.2 on [0, 20], σ = 0.05.
pub fn van_der_pol() -> Case<VanDerPol> {
    Case {
        name: "van-der-pol",
        time_unit: "dimensionless",
        summary: "van der Pol oscillator, μ = 1: x at t = 0, 0.2, …, 20 with σ = 0.05; μ, x(0), v(0)",
        system: VanDerPol::default(),
        t0: 0.0,
        known: vec![],
        unknowns: vec![Unknown::new("mu", 1.5), Unknown::new("x", 1.5), Unknown::new("v", 0.5)],
        integrator: Integrator::dopri5(1e-8, 1e-10),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.2, 101),
            noise: vec![Noise::absolute("x", 0.05)],
        },
        truth: vec![("mu", 1.0), ("x", 2.0), ("v", 0.0)],
        reference: None,
    }
}

/// The three measurements of `van-der-pol-three-point` (from μ = 1, x(0) = 2, v(0) = 0).
pub const THREE_POINTS: ([f64; 3], [f64; 3]) =
    ([4.0, 6.0, 8.0], [-1.74176832436092, 1.27904202910906, 1.2132324426389]);

/// `van-der-pol-three-point`: as many data as unknowns, initial time inside the data.
pub fn van_der_pol_three_point() -> Case<VanDerPol> {
    Case {
        name: "van-der-pol-three-point",
        time_unit: "dimensionless",
        summary: "van der Pol through 3 points x(4), x(6), x(8), t0 = 4: x(4), v(4), μ; ε = 0 (Goodman's M = n)",
        system: VanDerPol::default(),
        t0: 4.0,
        known: vec![],
        unknowns: vec![Unknown::new("x", -1.5), Unknown::new("v", 0.3), Unknown::new("mu", 1.5)],
        integrator: Integrator::dopri5(1e-12, 1e-14),
        data: DataSource::Fixed(|| Data::discrete().series("x", &THREE_POINTS.0, &THREE_POINTS.1)),
        truth: vec![],
        reference: Some(Reference {
            values: vec![("x", -1.74176832436092), ("v", 0.624666163677364), ("mu", 1.0)],
            cost: 0.0,
            // The published values carry 15 significant digits.
            tolerance: 1e-8,
            source: "docs/catalogue.md: the trajectory of μ = 1, x(0) = 2, v(0) = 0 at t0 = 4",
        }),
    }
}
