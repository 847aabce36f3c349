//! The tolerance check used by every sysid test: one helper, so failures read the same.

/// Asserts |actual − expected| ≤ tol · max(|expected|, floor) with floor = 1e-300, i.e. a
/// relative tolerance; compare with 0 through [`assert_close_abs`].
#[track_caller]
pub fn assert_close(actual: f64, expected: f64, tol: f64) {
    let err = (actual - expected).abs();
    let bound = tol * expected.abs().max(1e-300);
    assert!(
        err <= bound,
        "{actual:e} differs from {expected:e} by {err:.3e} (relative {:.3e}), allowed {tol:.1e} relative",
        err / expected.abs().max(1e-300)
    );
}

/// Asserts |actual − expected| ≤ tol (an absolute tolerance).
#[track_caller]
pub fn assert_close_abs(actual: f64, expected: f64, tol: f64) {
    let err = (actual - expected).abs();
    assert!(err <= tol, "{actual:e} differs from {expected:e} by {err:.3e}, allowed {tol:.1e}");
}
