//! Goodman's example (1966, Section IV): a body falling freely in vacuo near an earthlike
//! planet, y' = v, v' = g, with the position observed.

use sysid_core::{Data, Unknown};
use sysid_ode::{Integrator, Scalar, Signature, System};

use crate::case::{Case, DataSource, Reference};

/// y' = v, v' = g: states y (position) and v (velocity), parameter g.
#[derive(Clone, Debug)]
pub struct FallingBody(Signature);

impl Default for FallingBody {
    fn default() -> Self {
        Self(Signature::new(&["y", "v"], &["g"]))
    }
}

impl System for FallingBody {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = y[1];
        dy[1] = p[0];
    }
}

/// The paper's start c* = (0, 0, 32), eq. (29).
fn paper_start() -> Vec<Unknown> {
    vec![Unknown::new("y", 0.0), Unknown::new("v", 0.0), Unknown::new("g", 32.0)]
}

/// Table I of the paper: positions at t = 0, 1, 2, 3.
pub const TABLE_I: ([f64; 4], [f64; 4]) = ([0.0, 1.0, 2.0, 3.0], [0.0, 15.0, 65.0, 145.0]);

/// `falling-body`: the discrete case of the paper, Table I.
pub fn falling_body() -> Case<FallingBody> {
    Case {
        name: "falling-body",
        time_unit: "s",
        summary: "Goodman 1966 §IV: falling body y' = v, v' = g; y at t = 0..3 (Table I); y(0), v(0), g",
        system: FallingBody::default(),
        t0: 0.0,
        known: vec![],
        unknowns: paper_start(),
        integrator: Integrator::default(),
        data: DataSource::Fixed(|| Data::discrete().series("y", &TABLE_I.0, &TABLE_I.1)),
        truth: vec![],
        reference: Some(Reference {
            values: vec![("y", -0.25), ("v", -0.25), ("g", 32.5)],
            cost: 1.25,
            // The model is linear: one step is exact up to rounding.
            tolerance: 1e-10,
            source: "Goodman 1966, eq. (28)",
        }),
    }
}

/// The continuous record of `falling-body-continuous`: b(t) = 16.25t² − 0.25t − 0.25 + 0.5 sin 5t.
pub fn continuous_record(t: f64) -> f64 {
    16.25 * t * t - 0.25 * t - 0.25 + 0.5 * (5.0 * t).sin()
}

/// `falling-body-continuous`: the continuous case (Section III) on [0, 3].
// The reference digits are kept exactly as published, beyond what an f64 holds.
#[allow(clippy::excessive_precision)]
pub fn falling_body_continuous() -> Case<FallingBody> {
    Case {
        name: "falling-body-continuous",
        time_unit: "s",
        summary: "Goodman 1966 §III: falling body, continuous record b(t) = 16.25t² − 0.25t − 0.25 + 0.5 sin 5t on [0, 3]",
        system: FallingBody::default(),
        t0: 0.0,
        known: vec![],
        unknowns: paper_start(),
        integrator: Integrator::default(),
        data: DataSource::Fixed(|| {
            Data::continuous(0.0, 3.0).function("y", 1.0, continuous_record)
        }),
        truth: vec![],
        reference: Some(Reference {
            values: vec![
                ("y", 0.14500913909107217),
                ("v", -0.90222481175330339),
                ("g", 32.927989561533896),
            ],
            cost: 0.31497118786884043,
            tolerance: 1e-8,
            source: "least-squares projection of b(t) on {1, t, t²/2} over [0, 3] (docs/catalogue.md)",
        }),
    }
}
