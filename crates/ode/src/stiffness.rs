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
const STIFF_H_LAMBDA: f64 = 2.0;
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
