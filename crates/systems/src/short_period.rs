//! The longitudinal short-period motion of an aircraft, excited by an elevator doublet:
//! α' = Zα α + q + Zδ δe, q' = Mα α + Mq q + Mδ δe.

use sysid_core::Unknown;
use sysid_ode::{Inputs, Integrator, Scalar, Side, Signal, Signature, System};

use crate::case::{Case, DataSource, Noise, grid};

/// States alpha (angle of attack, rad) and q (pitch rate, rad/s); stability and control
/// derivatives Za, Ma, Mq, Zd, Md; input de (elevator deflection, rad).
#[derive(Clone, Debug)]
pub struct ShortPeriod {
    signature: Signature,
    inputs: Inputs,
}

impl ShortPeriod {
    /// The model driven by the elevator signal `de`.
    pub fn new(de: Signal) -> Self {
        Self {
            signature: Signature::new(&["alpha", "q"], &["Za", "Ma", "Mq", "Zd", "Md"])
                .with_inputs(&["de"]),
            inputs: Inputs::new(vec![de]),
        }
    }

    /// The catalogue's doublet: +0.05 rad on [1, 2) s, −0.05 rad on [2, 3) s, else 0.
    pub fn doublet() -> Signal {
        Signal::steps(0.0, &[(1.0, 0.05), (2.0, -0.05), (3.0, 0.0)]).expect("a valid doublet")
    }
}

impl Default for ShortPeriod {
    fn default() -> Self {
        Self::new(Self::doublet())
    }
}

impl System for ShortPeriod {
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], u: &[f64], dy: &mut [T]) {
        let (alpha, q, de) = (y[0], y[1], u[0]);
        let (za, ma, mq, zd, md) = (p[0], p[1], p[2], p[3], p[4]);
        dy[0] = za * alpha + q + zd * de;
        dy[1] = ma * alpha + mq * q + md * de;
    }
    fn input_values(&self, t: f64, side: Side, u: &mut [f64]) {
        self.inputs.eval(t, side, u);
    }
    fn discontinuities(&self) -> &[f64] {
        self.inputs.jumps()
    }
}

/// `short-period`: five derivatives from α and q every 0.05 s on [0, 10] s.
pub fn short_period() -> Case<ShortPeriod> {
    Case {
        name: "short-period",
        time_unit: "s",
        summary: "aircraft short period with an elevator doublet: α (σ = 0.002), q (σ = 0.005) every 0.05 s on [0, 10]; Za, Ma, Mq, Zd, Md",
        system: ShortPeriod::default(),
        t0: 0.0,
        known: vec![("alpha", 0.0), ("q", 0.0)],
        unknowns: vec![
            Unknown::new("Za", -1.0),
            Unknown::new("Ma", -3.0),
            Unknown::new("Mq", -1.0),
            Unknown::new("Zd", -0.1),
            Unknown::new("Md", -6.0),
        ],
        integrator: Integrator::dopri5(1e-8, 1e-10),
        data: DataSource::Synthetic {
            times: grid(0.0, 0.05, 201),
            noise: vec![Noise::absolute("alpha", 0.002), Noise::absolute("q", 0.005)],
        },
        truth: vec![("Za", -1.2), ("Ma", -4.5), ("Mq", -1.8), ("Zd", -0.15), ("Md", -8.0)],
        reference: None,
    }
}
