//! Bounds for an unconstrained solver: a smooth change of variables z = T(w) per unknown.
//!
//! argmin's Gauss–Newton knows nothing of bounds, so a bounded coordinate z is written as a
//! function of a free one w:
//! * lower bound only: z = lo + eʷ;
//! * upper bound only: z = hi − eʷ;
//! * both: z = lo + (hi − lo) σ(w), σ the logistic function.
//!
//! The solver works on w; residuals are evaluated at T(w) and the Jacobian picks up dz/dw.
//! An optimum on a bound is approached but not reached (w → ±∞).

use sysid_core::Unknown;

/// The map of one coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Map {
    /// Unbounded: z = w.
    Free,
    /// z = lo + eʷ.
    Lower(f64),
    /// z = hi − eʷ.
    Upper(f64),
    /// z = lo + (hi − lo) σ(w).
    Interval(f64, f64),
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
            Map::Lower(lo) => lo + w.exp(),
            Map::Upper(hi) => hi - w.exp(),
            Map::Interval(lo, hi) => lo + (hi - lo) / (1.0 + (-w).exp()),
        }
    }

    /// dz/dw.
    pub fn dz_dw(self, w: f64) -> f64 {
        match self {
            Map::Free => 1.0,
            Map::Lower(_) => w.exp(),
            Map::Upper(_) => -w.exp(),
            Map::Interval(lo, hi) => {
                let s = 1.0 / (1.0 + (-w).exp());
                (hi - lo) * s * (1.0 - s)
            }
        }
    }

    /// w(z), for z moved strictly inside the bounds by a small margin if it lies on one.
    pub fn w(self, z: f64) -> f64 {
        let margin = |width: f64| 1e-8 * width.abs().max(1.0);
        match self {
            Map::Free => z,
            Map::Lower(lo) => (z - lo).max(margin(lo)).ln(),
            Map::Upper(hi) => (hi - z).max(margin(hi)).ln(),
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
}
