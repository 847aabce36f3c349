//! Hairer's stiffness detection for DOPRI5: when to test a step, and when the tests add up
//! to a stiff problem. The estimate of h·λ itself comes from the scheme
//! ([`Stepper::stiffness_estimate`](crate::stepper::Stepper::stiffness_estimate)).

/// h·λ above which a DOPRI5 step counts as limited by stability rather than accuracy.
/// Hairer's DOPRI5 uses 3.25, just inside the stability boundary (≈3.3 on the negative real
/// axis); but his estimate of λ, a difference quotient of f, approaches it from below while
/// the step controller sits on the boundary (on Robertson's problem h·λ creeps from 2.4 to
/// 3.25 over four thousand steps). Accuracy-limited steps have h·λ ≈ (C·tol)^{1/5}, well
/// below 1 at the tolerances identification needs, so 2 still separates the two regimes
/// and decides after a few dozen steps instead of thousands.
pub(crate) const STIFF_H_LAMBDA: f64 = 2.0;
/// h·|λ|max, with the Jacobian's spectral radius ([`SpectralRadius`]), above which a DOPRI5
/// step counts as limited by stability. That estimate is not biased low as Hairer's is, so it
/// is held near the stability boundary (3.3 on the negative real axis, about as far along
/// the imaginary one): a fast mode with h·|λ| of 2 to 3 is still inside it, and on Crauste's
/// model DOPRI5 integrates there in 400 steps where Rodas5P's take 4.8 times as long.
pub(crate) const SPECTRAL_STIFF_H_LAMBDA: f64 = 3.0;
/// Consecutive stiff-looking steps that decide it (Hairer's DOPRI5).
const STIFF_STEPS: u32 = 15;
/// How often plain DOPRI5 tests a step while nothing looks stiff.
const STIFF_CHECK_EVERY: u64 = 64;

/// Hairer's stiffness detection for DOPRI5: fifteen accepted steps in a row with
/// h·λ > [`STIFF_H_LAMBDA`] (six non-stiff ones reset the count).
#[derive(Default)]
pub(crate) struct Stiffness {
    stiff: u32,
    non_stiff: u32,
}

impl Stiffness {
    /// Whether to test the next step, `steps` having been accepted so far. The automatic
    /// choice (`every_step`) tests every step; plain DOPRI5, whose test only explains a later
    /// failure, every 64th step and every step once one looked stiff, as Hairer's code does.
    #[inline]
    pub(crate) fn due(&self, every_step: bool, steps: u64) -> bool {
        every_step || self.suspected() || steps.is_multiple_of(STIFF_CHECK_EVERY)
    }

    /// Whether a recent test looked stiff.
    #[inline]
    fn suspected(&self) -> bool {
        self.stiff > 0
    }

    /// Records a step; true when the integration looks stiff.
    #[inline]
    pub(crate) fn observe(&mut self, h_lambda: f64) -> bool {
        if h_lambda > STIFF_H_LAMBDA {
            self.non_stiff = 0;
            self.stiff += 1;
        } else {
            self.non_stiff += 1;
            if self.non_stiff == 6 {
                self.stiff = 0;
            }
        }
        self.stiff >= STIFF_STEPS
    }
}

/// h·|λ|max below which a step of Rodas5P's size would be stable for DOPRI5 with a margin
/// (its boundary is near 3.3; a third of the way to it): the automatic choice then goes back
/// to DOPRI5.
pub(crate) const EXPLICIT_H_LAMBDA: f64 = 1.0;
/// Refreshes of [`SpectralRadius`] in a row below [`EXPLICIT_H_LAMBDA`] that decide it.
pub(crate) const EXPLICIT_REFRESHES: u32 = 2;

/// Accepted steps between two refreshes of [`SpectralRadius`]: each refresh costs two
/// evaluations of the right-hand side, against six or seven a DOPRI5 step.
pub(crate) const SPECTRAL_EVERY: u64 = 16;

/// The modulus of the Jacobian's dominant eigenvalue, by power iteration on difference
/// quotients of the states' right-hand side, one iteration per refresh, the vector kept from
/// refresh to refresh (it converges as the integration goes on).
///
/// Hairer's estimate measures f along the step's own direction. Once the stiff components
/// have decayed, that direction is the slow solution's, and the estimate falls to the slow
/// eigenvalues while the steps stay limited by the fast ones: on Fujita's model DOPRI5 took
/// 40 000 steps of h = 5.42e-5 in a row with Hairer's h·λ at 0.76, where a few hundred steps
/// earlier the same h had read 3.2. The power iteration finds the fast eigenvalue whatever
/// the solution is doing.
#[derive(Default)]
pub(crate) struct SpectralRadius {
    /// The iteration's vector over the states (unit length), empty before the first refresh.
    v: Vec<f64>,
    /// The point moved along v, and f there and at the point itself.
    moved: Vec<f64>,
    at_moved: Vec<f64>,
    at_point: Vec<f64>,
    /// The last estimate of |λ|max (0 before the first refresh).
    pub(crate) radius: f64,
}

impl SpectralRadius {
    /// One power iteration at the point `x` (its first `states` components the states; the
    /// others, sensitivities, are left as they are), `f` the right-hand side there, `step`
    /// the last step's size: |λ| ≈ ‖J v‖ with J v by a forward difference, then v ← J v / ‖J v‖.
    pub(crate) fn refresh(
        &mut self,
        x: &[f64],
        states: usize,
        step: f64,
        mut f: impl FnMut(&[f64], &mut [f64]),
    ) {
        let n = x.len();
        if self.v.len() != states {
            // A start that no eigenvector is orthogonal to in practice: alternating signs,
            // uneven sizes.
            self.v = (0..states)
                .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 } * (1.0 + (i % 7) as f64 / 7.0))
                .collect();
            let length = norm(&self.v);
            self.v.iter_mut().for_each(|v| *v /= length);
            self.moved = vec![0.0; n];
            self.at_moved = vec![0.0; n];
            self.at_point = vec![0.0; n];
        }
        f(x, &mut self.at_point);
        // A move small beside the states and beside what one step changes them by, so that
        // the quotient is the Jacobian's, and not so small that f's rounding swamps it.
        let scale = norm(&x[..states]).max(step.abs() * norm(&self.at_point[..states]));
        let eta = f64::EPSILON.sqrt() * if scale > 0.0 { scale } else { 1.0 };
        self.moved.copy_from_slice(x);
        for (m, v) in self.moved.iter_mut().zip(&self.v) {
            *m += eta * v;
        }
        f(&self.moved, &mut self.at_moved);
        // J v, in place of f at the moved point.
        let jv = &mut self.at_moved[..states];
        for (d, f) in jv.iter_mut().zip(&self.at_point) {
            *d = (*d - f) / eta;
        }
        let radius = norm(jv);
        if !(radius.is_finite() && radius > 0.0) {
            return;
        }
        for (v, d) in self.v.iter_mut().zip(jv.iter()) {
            *v = d / radius;
        }
        self.radius = radius;
    }
}

/// ‖v‖₂.
fn norm(v: &[f64]) -> f64 {
    v.iter().map(|v| v * v).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(x) = A x with A's eigenvalues −1, −30 and −1000 (A = Q diag Qᵀ, Q a rotation): the
    /// refreshes converge to 1000 as the power iteration does, by (30/1000)ᵏ, whatever the
    /// point; the components after the states (sensitivities) are carried along untouched.
    #[test]
    fn the_refreshes_converge_to_the_largest_eigenvalue() {
        let (c, s) = (0.6_f64, 0.8_f64);
        let q = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
        let lambda = [-1.0, -30.0, -1000.0];
        let a: Vec<[f64; 3]> = (0..3)
            .map(|i| std::array::from_fn(|j| (0..3).map(|k| q[i][k] * lambda[k] * q[j][k]).sum()))
            .collect();
        let f = |x: &[f64], dx: &mut [f64]| {
            for i in 0..3 {
                dx[i] = (0..3).map(|j| a[i][j] * x[j]).sum();
            }
            dx[3] = 7.0 * x[3];
        };
        let mut spectral = SpectralRadius::default();
        let x = [2.0, -1.0, 0.5, 9.0];
        let mut estimates = Vec::new();
        for _ in 0..8 {
            spectral.refresh(&x, 3, 1e-3, f);
            estimates.push(spectral.radius);
        }
        // Difference quotients of a linear f are exact to rounding of about √ε relative.
        assert!((estimates[7] - 1000.0).abs() <= 1e-6 * 1000.0, "{estimates:?}");
        assert!(estimates.windows(2).all(|w| w[1] >= w[0] * (1.0 - 1e-6)), "{estimates:?}");
    }
}
