//! Kinks of the objective where a switch time that moves with an unknown passes a sample
//! time of its experiment.
//!
//! A right-hand side that switches from g₋ to g₊ at τ(α) (`if(le(t, tau), a, b)` with τ
//! estimated) leaves the states continuous, but a sample at t_k depends on τ only while
//! τ < t_k: as τ passes t_k, ∂r_k/∂τ jumps between the switch's term and 0, and the
//! objective has a kink there along the unknown that moves τ (and at t0, before which the
//! switch has happened for every sample). Its other partial derivatives
//! do not jump (at τ = t_k both sides are the same function of them). A Gauss–Newton model
//! taken on one side predicts a step across it wrongly; a trust region whose trials cross a
//! kink again and again shrinks on every unknown, and the run stalls beside it (Beer's
//! `tau_typeIDT5_ExpID5`, whose minimum is on the sample time 155).
//!
//! So each kink bounds the steps on the side the unknown is on, and a step may overstep it
//! by a sliver, [`SLIVER`] of the time: it ends just past the kink, where the model taken
//! next is that side's, exact, and the step after may go back over. An unknown whose
//! minimum along its coordinate is the kink (the slopes on its two sides point at it) goes
//! to and fro within the sliver while the others converge. The certificate holds it there
//! ([`Bound::SwitchOnSample`](crate::Bound::SwitchOnSample)) when the descent direction
//! points over a kink within reach of the sliver, and the verdict on a returned point
//! checks the slope on the other side, from one more integration there.
//!
//! Only a switch moved by one free unknown (through its experiment's setting) is handled;
//! a switch time that is a function of several unknowns has a kink along a surface, not a
//! coordinate, and is left to the trust region.

use sysid_ode::{System, Wrt};

use crate::problem::Problem;

/// The sliver a step may overstep a kink by, relative to the sample time (at least 1 in the
/// time's units): far above the integrators' resolution (64ε of the time, where a switch
/// and a sample are merged into one stop) and far below any step a fit needs.
pub const SLIVER: f64 = 1e-9;

/// How much further than the sliver from a kink an unknown still counts as at it: a step
/// that ends on the box's limit is on it to the rounding of the maps between z and τ.
const AT_KINK: f64 = 1.5;

/// The kinks next to one unknown's coordinate z, and the box its steps keep to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Around {
    /// The nearest kink at or below z (−∞ without one).
    pub below: f64,
    /// The nearest kink at or above z (+∞ without one).
    pub above: f64,
    /// The lowest coordinate a step may reach: `below` overstepped by its sliver.
    pub lo: f64,
    /// The highest: `above` overstepped by its sliver.
    pub hi: f64,
}

impl Around {
    /// The kink a step from z along the sign of `direction` meets at once (within reach of
    /// the sliver), if any.
    pub fn at(&self, z: f64, direction: f64) -> Option<f64> {
        let (kink, sliver) = if direction < 0.0 {
            (self.below, self.below - self.lo)
        } else {
            (self.above, self.hi - self.above)
        };
        (kink.is_finite() && (z - kink).abs() <= AT_KINK * sliver).then_some(kink)
    }

    /// The point over the kink a step from z along the sign of `direction` meets at once
    /// ([`at`](Self::at)): as far past it as z is short of it, and at least the sliver.
    pub fn mirror(&self, z: f64, direction: f64) -> Option<f64> {
        let kink = self.at(z, direction)?;
        let sliver = if direction < 0.0 { self.below - self.lo } else { self.hi - self.above };
        let side = if direction < 0.0 { -1.0 } else { 1.0 };
        Some(kink + side * (z - kink).abs().max(sliver))
    }
}

impl<S: System> Problem<S> {
    /// Per free unknown, the kinks of the objective next to its coordinate at z where a
    /// switch time it moves passes a sample time (module docs); `None` for an unknown that
    /// moves no switch.
    pub fn kinks(&self, z: &[f64]) -> Vec<Option<Around>> {
        let mut out: Vec<Option<Around>> = vec![None; z.len()];
        let values = self.values_at(z);
        let mut index: Option<Vec<Option<usize>>> = None;
        for e in &self.experiments {
            if e.is_continuous() {
                continue;
            }
            let p = e.parameters_at(&values);
            let moving = e.system.moving_switches(&p);
            if moving.is_empty() {
                continue;
            }
            let free_index = index.get_or_insert_with(|| self.free_index());
            let jacobian = e.slot_jacobian(&values, free_index);
            // The sample times, and t0: with τ before it every sample is past the switch.
            let mut times = e.sampled().times.clone();
            if times.first().is_none_or(|&t| t > e.t0) {
                times.insert(0, e.t0);
            }
            for (which, &(tau, q, slope)) in moving.iter().enumerate() {
                let Some(slot) = e.slots.iter().position(|w| *w == Wrt::Parameter(q)) else {
                    continue;
                };
                // Moved by exactly one free unknown f, at the rate dτ/dv_f of its value.
                let &[(f, dp)] = jacobian[slot].as_slice() else { continue };
                let rate = slope * dp;
                if !(rate != 0.0 && rate.is_finite() && tau.is_finite()) {
                    continue;
                }
                let unknown = &self.unknowns.list()[f];
                // τ with unknown f at the value x, the others as at z.
                let tau_at = |x: f64| {
                    let mut moved = values.clone();
                    moved[self.free[f]] = x;
                    let p = e.parameters_at(&moved);
                    e.system.moving_switches(&p).get(which).map_or(f64::NAN, |m| m.0)
                };
                // A sample within the integrators' resolution of τ is on the kink (the
                // switch and the sample are one stop).
                let merged = |t: f64| (t - tau).abs() <= 64.0 * f64::EPSILON * t.abs().max(1.0);
                let v = values[self.free[f]];
                let coordinate = |t: f64| match merged(t) {
                    true => z[f],
                    false => unknown.coordinate(kink_value(v, tau, rate, t, &tau_at)),
                };
                let below = times.iter().rev().find(|&&t| t < tau || merged(t));
                let above = times.iter().find(|&&t| t > tau || merged(t));
                // The sliver in z at the kink: SLIVER of the time over dτ/dz there (dτ/dv
                // taken as at z, the map from z to the value at the kink).
                let mut sides = [below, above].map(|t| {
                    t.map(|&t| {
                        let kink = coordinate(t);
                        let sliver =
                            (SLIVER * t.abs().max(1.0) / (rate * unknown.scale(kink))).abs();
                        (kink, sliver)
                    })
                });
                // In z, "below" and "above" swap where τ falls as z_f grows.
                if rate < 0.0 {
                    sides.swap(0, 1);
                }
                let entry = out[f].get_or_insert(Around {
                    below: f64::NEG_INFINITY,
                    above: f64::INFINITY,
                    lo: f64::NEG_INFINITY,
                    hi: f64::INFINITY,
                });
                if let Some((kink, sliver)) = sides[0]
                    && kink.is_finite()
                    && kink <= z[f]
                    && kink > entry.below
                {
                    entry.below = kink;
                    entry.lo = kink - sliver;
                }
                if let Some((kink, sliver)) = sides[1]
                    && kink.is_finite()
                    && kink >= z[f]
                    && kink < entry.above
                {
                    entry.above = kink;
                    entry.hi = kink + sliver;
                }
            }
        }
        out
    }

    /// The box of corrections δ a step from z keeps to: the unknowns' own
    /// ([`Unknowns::step_box`](crate::Unknowns::step_box): bounds, Laplace priors' kinks),
    /// and for the unknowns `guarded` picks, within the kinks next to their coordinate,
    /// overstepped by the sliver (module docs).
    pub fn step_box(
        &self,
        z: &[f64],
        gradient: &[f64],
        guarded: &dyn Fn(usize) -> bool,
    ) -> (Vec<f64>, Vec<f64>) {
        let (mut lo, mut hi) = self.unknowns.step_box(z, gradient);
        if (0..z.len()).any(guarded) {
            self.keep_to_kinks(z, (&mut lo, &mut hi), guarded, true);
        }
        (lo, hi)
    }

    /// Narrows the corrections `lo`, `hi` from z to the kinks next to each coordinate that
    /// `pick` selects: over them by the sliver (`overstep`, the steps' box), or only up to them
    /// (differences, which must not cross one).
    pub(crate) fn keep_to_kinks(
        &self,
        z: &[f64],
        (lo, hi): (&mut [f64], &mut [f64]),
        pick: &dyn Fn(usize) -> bool,
        overstep: bool,
    ) {
        for (i, around) in self.kinks(z).into_iter().enumerate() {
            if let Some(a) = around.filter(|_| pick(i)) {
                let (down, up) = if overstep { (a.lo, a.hi) } else { (a.below, a.above) };
                lo[i] = lo[i].max(down - z[i]).min(0.0);
                hi[i] = hi[i].min(up - z[i]).max(0.0);
            }
        }
    }
}

/// The value x of an unknown (now v, where the switch is at τ and moves at the rate dτ/dv)
/// at which the switch τ(x) reaches the time t: from the rate, then by secants through τ at
/// the estimates (exact at once where τ is affine in the value, as a setting that is the
/// unknown itself makes it). Where a secant cannot be drawn the last estimate stands.
fn kink_value(v: f64, tau: f64, rate: f64, t: f64, tau_at: &dyn Fn(f64) -> f64) -> f64 {
    let (mut x0, mut t0) = (v, tau);
    let mut x1 = v + (t - tau) / rate;
    for _ in 0..8 {
        let t1 = tau_at(x1);
        if !t1.is_finite() || t1.to_bits() == t0.to_bits() || t1.to_bits() == t.to_bits() {
            break;
        }
        let next = x1 + (t - t1) * (x1 - x0) / (t1 - t0);
        if !next.is_finite() {
            break;
        }
        (x0, t0, x1) = (x1, t1, next);
        if (x1 - x0).abs() <= 4.0 * f64::EPSILON * x1.abs().max(1.0) {
            break;
        }
    }
    x1
}
