//! Geodesic acceleration of a step on the Levenberg curve (Transtrum & Sethna 2012,
//! arXiv:1201.5885; Transtrum, Machta & Sethna, Phys. Rev. E 83, 2011, 036701).
//!
//! The step v = δ(λ) of the curve is the first-order term of a path z(t) = z + vt + ½at² along
//! which the residuals change as the linear model says they do. Where the cost's valley is
//! narrow and curved (an unknown drifting towards where the data stop seeing it, with others
//! following it), the straight step leaves the valley floor after a short distance: the trust
//! region keeps it there, and the iteration creeps along the floor for hundreds of iterations
//! with the model predicting twice the decrease it gets. The second-order term bends the step
//! along the floor:
//!
//!   (A + λD²) a = −Jᵀ r″,   r″ ≈ (2/h)·((r(z + hv) − r(z))/h − Jv),  h = [`GEODESIC_H`],
//!
//! the directional second derivative of the weighted residuals by one more plain integration,
//! and the step taken is v + ½a, in the box. It is accepted only while 2‖Da‖ ≤ α‖Dv‖ (α =
//! [`GEODESIC_RATIO`]): past that the path's curvature is too large for a second-order
//! expansion to hold, and the caller shortens v instead (no linearization spent). The
//! bounds: a is solved on the unknowns v leaves free; those on a bound of the step stay there.

use nalgebra::DVector;
use sysid_ode::System;

use crate::evaluate::Linearization;
use crate::evaluations::Evaluations;
use crate::termination::Failure;
use crate::trust::{Curve, CurveStep};

/// The finite-difference step along v, as a fraction of v (Transtrum & Sethna's h).
pub const GEODESIC_H: f64 = 0.1;

/// The largest 2‖Da‖/‖Dv‖ at which the accelerated step is taken (their α).
pub const GEODESIC_RATIO: f64 = 0.75;

/// A second difference of the residuals counts as curvature only above this many times the
/// integration's own error in them.
const NOISE_MULTIPLE: f64 = 10.0;

/// What acceleration made of a step.
#[derive(Clone, Debug)]
pub enum Accelerated {
    /// v + ½a.
    Step(CurveStep),
    /// The path bends too much over v (2‖Da‖ > α‖Dv‖, or z + hv cannot be integrated): a
    /// shorter v is wanted.
    TooCurved,
    /// No acceleration here (no residual rows, a singular system, or no decrease predicted
    /// for v + ½a): v as it is.
    Unavailable,
}

/// The plain residuals at the current iterate, kept while the iterate stays.
#[derive(Clone, Debug, Default)]
pub struct Geodesic {
    at: Option<(Vec<f64>, DVector<f64>)>,
}

impl Geodesic {
    /// The accelerated step from the iterate `lin` (whose model gave the step `v` on `curve`).
    pub fn accelerate<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        lin: &Linearization,
        curve: &Curve,
        v: &CurveStep,
        max_condition: f64,
    ) -> Result<Accelerated, Failure> {
        let Some(rows) = &lin.residuals else { return Ok(Accelerated::Unavailable) };
        if !(v.scaled_norm > 0.0 && v.scaled_norm.is_finite()) {
            return Ok(Accelerated::Unavailable);
        }
        let problem = ev.problem();
        let unknowns = problem.unknowns();
        // A step off the kink of a Laplace prior: its row, √|d| there, has no second
        // derivative to bend along (its second difference grows as h^(−3/2)).
        let leaves_kink = |(u, (&z, &d)): (&crate::Unknown, (&f64, &f64))| d != 0.0 && u.at_kink(z);
        if unknowns.list().iter().zip(lin.z.iter().zip(v.delta.iter())).any(leaves_kink) {
            return Ok(Accelerated::Unavailable);
        }
        if self.at.as_ref().is_none_or(|(z, _)| *z != lin.z) {
            let r = match ev.residuals(&lin.z) {
                Ok(r) => r,
                Err(budget @ Failure::Budget { .. }) => return Err(budget),
                Err(_) => return Ok(Accelerated::Unavailable),
            };
            self.at = Some((lin.z.clone(), r));
        }
        let (_, r0) = self.at.as_ref().expect("just set");
        let near = unknowns.moved(&lin.z, v.delta.as_slice(), GEODESIC_H);
        let r1 = match ev.residuals(&near) {
            Ok(r) => r,
            Err(budget @ Failure::Budget { .. }) => return Err(budget),
            Err(_) => return Ok(Accelerated::TooCurved),
        };
        // The two plain integrations' error, measured against the linearization's residuals
        // at the same point: a second difference below it is noise, not curvature.
        let noise = (r0 - &rows.r).norm();
        let bend = (r1 - r0) - &rows.jacobian * &v.delta * GEODESIC_H;
        if !(bend.norm() > NOISE_MULTIPLE * noise && bend.norm().is_finite()) {
            return Ok(Accelerated::Unavailable);
        }
        let second = bend * (2.0 / (GEODESIC_H * GEODESIC_H));
        let force = rows.jacobian.tr_mul(&second);
        let (lo, hi) = curve.step_box(problem, lin, true);
        let k = v.delta.len();
        let Some(a) = curve.correction(lin, v, &-force, (&lo, &hi), max_condition) else {
            return Ok(Accelerated::Unavailable);
        };
        let ratio = 2.0 * curve.scaled_norm(a.as_slice()) / v.scaled_norm;
        if !(ratio <= GEODESIC_RATIO && ratio.is_finite()) {
            return Ok(Accelerated::TooCurved);
        }
        let delta = DVector::from_fn(k, |i, _| (v.delta[i] + 0.5 * a[i]).clamp(lo[i], hi[i]));
        let predicted = lin.predicted_decrease(&delta);
        if !(predicted > 0.0 && predicted.is_finite()) {
            return Ok(Accelerated::Unavailable);
        }
        Ok(Accelerated::Step(CurveStep {
            scaled_norm: curve.scaled_norm(delta.as_slice()),
            delta,
            predicted,
            lambda: v.lambda,
            condition: v.condition.clone(),
        }))
    }
}
