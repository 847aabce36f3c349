//! Bounds for an unconstrained solver: a smooth change of variables z = T(w) per unknown,
//! safe for every w (no overflow to ±∞, no NaN).
//!
//! argmin's Gauss–Newton knows nothing of bounds, so a bounded coordinate z is written as a
//! function of a free one w:
//! * lower bound only: z = lo + softplus(w), softplus(w) = ln(1 + eʷ), computed as
//!   max(w, 0) + ln(1 + e^{−|w|});
//! * upper bound only: z = hi − softplus(w);
//! * both: z = lo + (hi − lo) σ(w), σ the logistic function.
//!
//! Far from its bound z ≈ w (softplus is the identity plus e^{−w}), so the map does not
//! distort the problem where the bound does not matter; at the bound dz/dw → 0, and an
//! optimum on the bound is approached but not reached. The adapter
//! ([`GaussNewton`](crate::GaussNewton)) therefore holds an unknown on its bound where the
//! projected Gauss–Newton model holds it, and releases it where that model moves it inwards.

use sysid_core::Unknown;

/// The map of one coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Map {
    /// Unbounded: z = w.
    Free,
    /// z = lo + softplus(w).
    Lower(f64),
    /// z = hi − softplus(w).
    Upper(f64),
    /// z = lo + (hi − lo) σ(w).
    Interval(f64, f64),
}

/// ln(1 + eʷ) without overflow.
fn softplus(w: f64) -> f64 {
    w.max(0.0) + (-w.abs()).exp().ln_1p()
}

/// The logistic function 1/(1 + e^{−w}), in [0, 1] for every w.
fn sigmoid(w: f64) -> f64 {
    if w >= 0.0 {
        1.0 / (1.0 + (-w).exp())
    } else {
        let e = w.exp();
        e / (1.0 + e)
    }
}

/// The w with softplus(w) = d > 0: ln(eᵈ − 1).
fn softplus_inverse(d: f64) -> f64 {
    if d > 30.0 { d + (-(-d).exp()).ln_1p() } else { d.exp_m1().ln() }
}

impl Map {
    /// The map of an unknown's coordinate (its bounds in coordinates, log scale included).
    pub fn of(unknown: &Unknown) -> Self {
        let (lo, hi) = unknown.coordinate_bounds();
        match (lo.is_finite(), hi.is_finite()) {
            (false, false) => Map::Free,
            (true, false) => Map::Lower(lo),
            (false, true) => Map::Upper(hi),
            (true, true) => Map::Interval(lo, hi),
        }
    }

    /// z(w).
    pub fn z(self, w: f64) -> f64 {
        match self {
            Map::Free => w,
            Map::Lower(lo) => lo + softplus(w),
            Map::Upper(hi) => hi - softplus(w),
            Map::Interval(lo, hi) => lo + (hi - lo) * sigmoid(w),
        }
    }

    /// dz/dw.
    pub fn dz_dw(self, w: f64) -> f64 {
        match self {
            Map::Free => 1.0,
            Map::Lower(_) => sigmoid(w),
            Map::Upper(_) => -sigmoid(w),
            Map::Interval(lo, hi) => {
                let s = sigmoid(w);
                (hi - lo) * s * (1.0 - s)
            }
        }
    }

    /// The largest |dz/dw| the map has (where it is least curved): 1 for one bound or none,
    /// (hi − lo)/4 for two.
    pub fn dz_dw_far(self) -> f64 {
        match self {
            Map::Interval(lo, hi) => 0.25 * (hi - lo),
            _ => 1.0,
        }
    }

    /// w(z), for z moved strictly inside the bounds by a small margin if it lies on one.
    pub fn w(self, z: f64) -> f64 {
        let margin = |width: f64| 1e-8 * width.abs().max(1.0);
        match self {
            Map::Free => z,
            Map::Lower(lo) => softplus_inverse((z - lo).max(margin(lo))),
            Map::Upper(hi) => softplus_inverse((hi - z).max(margin(hi))),
            Map::Interval(lo, hi) => {
                let m = margin(hi - lo) / (hi - lo);
                let s = ((z - lo) / (hi - lo)).clamp(m, 1.0 - m);
                (s / (1.0 - s)).ln()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_ode::testing::assert_close;

    #[test]
    fn maps_round_trip_and_differentiate() {
        for map in [Map::Free, Map::Lower(-1.0), Map::Upper(2.0), Map::Interval(-1.0, 3.0)] {
            for z in [-0.5, 0.25, 1.5] {
                let w = map.w(z);
                assert_close(map.z(w), z, 1e-13);
                let h = 1e-6;
                let fd = (map.z(w + h) - map.z(w - h)) / (2.0 * h);
                assert_close(map.dz_dw(w), fd, 1e-8);
            }
        }
        // A start on a bound moves inside.
        assert!(Map::Lower(0.0).z(Map::Lower(0.0).w(0.0)) > 0.0);
    }

    #[test]
    fn no_w_overflows_or_gives_nan() {
        for map in [Map::Lower(-1.0), Map::Upper(2.0), Map::Interval(-1.0, 3.0)] {
            for w in [-1e308, -1e5, -800.0, -30.0, 0.0, 30.0, 800.0, 1e5, 1e308] {
                let (z, d) = (map.z(w), map.dz_dw(w));
                assert!(z.is_finite() && d.is_finite(), "{map:?} at {w}: {z} {d}");
            }
        }
        // Far from a one-sided bound the map is the identity plus a vanishing term.
        assert_close(Map::Lower(0.0).z(50.0), 50.0, 1e-15);
        // Tiny distances invert without underflow to −∞.
        assert!(Map::Lower(0.0).w(1e-300).is_finite());
    }
}
