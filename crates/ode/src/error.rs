//! Errors of the ODE crate. Each variant carries the data needed to act on it.

use thiserror::Error;

/// Growth of the largest component, relative to the largest magnitude at the start (at
/// least 1), beyond which a failed integration is reported as [`OdeError::BlowUp`].
pub const BLOW_UP_GROWTH: f64 = 1e6;

/// The shortest representation that reads back to the same f64, in exponent form outside
/// [1e-4, 1e9): for numbers in messages and tables (a step size underflow at t = 1e-300
/// printed three hundred zeros). `sysid_core::format::shortest` is this one.
pub fn shortest(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e9).contains(&a) { format!("{v:e}") } else { format!("{v}") }
}

/// A time of an error's message, by [`shortest`].
fn time(t: &f64) -> String {
    shortest(*t)
}

/// Why an integration stopped before reaching its end.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum OdeError {
    /// The step size fell below what the floating-point resolution of t allows: the solution
    /// is singular near t, or the problem is too stiff for the method.
    #[error("step size underflow at t = {}: step {h:e} is below the resolution of t", time(.t))]
    StepSizeTooSmall {
        /// Where the integration stopped.
        t: f64,
        /// The step size that was rejected.
        h: f64,
    },
    /// A state or sensitivity became NaN or infinite.
    #[error("{what} became non-finite at t = {}", time(.t))]
    NonFinite {
        /// Where the integration stopped (the start of the step that produced the value).
        t: f64,
        /// Which quantity: "state y", "sensitivity ∂y/∂g", or "component 7" at the raw level.
        what: String,
    },
    /// A quantity computed from a finite solution cannot be represented: the square of a
    /// residual whose weight is near ∞ overflows, a σ lies below what the likelihood's rows
    /// hold. The model integrated; the value does not exist.
    #[error("{what} (at t = {})", time(.t))]
    Unrepresentable {
        /// Where (the sample's time).
        t: f64,
        /// What, as a clause with the numbers that make it.
        what: String,
    },
    /// The step budget was used up.
    #[error("too many steps: {steps} steps taken by t = {} without reaching {}", time(.t), time(.t_end))]
    TooManySteps {
        /// Where the integration stopped.
        t: f64,
        /// The end it was heading for.
        t_end: f64,
        /// Steps taken (the budget).
        steps: usize,
    },
    /// Requested output times must be non-decreasing.
    #[error("output times out of order: t[{index}] = {time} comes after {previous}")]
    TimesOutOfOrder {
        /// Position of the offending time.
        index: usize,
        /// The time before it.
        previous: f64,
        /// The offending time.
        time: f64,
    },
    /// A time, initial value or parameter is NaN or infinite before integrating.
    #[error("invalid input: {what} is {value}")]
    InvalidInput {
        /// What was invalid.
        what: String,
        /// Its value.
        value: f64,
    },
    /// The explicit integrator ran out of steps on a problem that its stiffness test
    /// flagged: the steps were limited by stability, not accuracy.
    #[error(
        "too many steps ({steps}) at t = {}: the problem is stiff from t = {} on (the explicit scheme's steps are limited by stability, not accuracy); use the rodas5p or auto integrator",
        time(.t),
        time(.since)
    )]
    Stiff {
        /// Where the budget ran out.
        t: f64,
        /// Where stiffness was first detected.
        since: f64,
        /// The budget.
        steps: usize,
    },
    /// The solution grows without bound: the integration failed (step size, step budget or
    /// overflow) after a component grew to more than [`BLOW_UP_GROWTH`] times the largest
    /// magnitude at the start (at least 1). A finite-time singularity, or exponential growth
    /// faster than the integrator can follow.
    #[error(
        "the solution blows up: {what} reaches {value:.3e} at t = {} (it started at most {start:.3e} in magnitude)",
        time(.t)
    )]
    BlowUp {
        /// Where the integration stopped.
        t: f64,
        /// The component that grew most.
        what: String,
        /// Its value there (infinite when it overflowed).
        value: f64,
        /// The largest magnitude at the start (at least 1).
        start: f64,
        /// The steps taken until then, accepted and rejected.
        steps: usize,
    },
    /// The implicit integrator's iteration matrix is singular.
    #[error("the implicit step matrix is singular at t = {}", time(.t))]
    SingularJacobian {
        /// Where.
        t: f64,
    },
    /// Invalid integrator settings or sensitivity columns.
    #[error("{0}")]
    InvalidSetup(String),
    /// The initial state has the wrong length.
    #[error("dimension mismatch: {what} has length {actual}, expected {expected}")]
    Dimension {
        /// Which vector.
        what: &'static str,
        /// Its length.
        actual: usize,
        /// The length the system requires.
        expected: usize,
    },
}

/// Invalid names in a [`Signature`](crate::Signature).
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum SignatureError {
    /// A system needs at least one state.
    #[error("a system needs at least one state")]
    NoStates,
    /// Empty names are not allowed.
    #[error("empty name")]
    EmptyName,
    /// Names are unique across states, parameters, inputs and outputs.
    #[error("name `{name}` is used twice")]
    Duplicate {
        /// The repeated name.
        name: String,
    },
    /// `t` is the time variable.
    #[error("name `{name}` is reserved for time")]
    Reserved {
        /// The reserved name.
        name: String,
    },
}

/// Invalid samples of a [`Signal`](crate::Signal).
#[derive(Clone, Debug, Error, PartialEq)]
pub enum SignalError {
    /// Times and values differ in length.
    #[error("{times} sample times but {values} values")]
    LengthMismatch {
        /// Number of times.
        times: usize,
        /// Number of values.
        values: usize,
    },
    /// A signal needs at least one sample.
    #[error("a signal needs at least one sample")]
    Empty,
    /// A time or value is NaN or infinite.
    #[error("sample {index} is not a finite number")]
    NonFinite {
        /// Index of the sample.
        index: usize,
    },
    /// Sample times must strictly increase.
    #[error("sample times must increase: t[{index}] = {time} after {previous}")]
    NotIncreasing {
        /// Index of the offending sample.
        index: usize,
        /// The time before it.
        previous: f64,
        /// The offending time.
        time: f64,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Times far from 1 are written in exponent form (a step size underflow near t = 1e-271
    /// printed 270 zeros), the others as they are.
    #[test]
    fn times_in_messages_are_short() {
        let tiny = OdeError::StepSizeTooSmall { t: 2.5e-271, h: 3.9e-286 };
        assert_eq!(
            tiny.to_string(),
            "step size underflow at t = 2.5e-271: step 3.9e-286 is below the resolution of t"
        );
        let plain = OdeError::NonFinite { t: 4.968, what: "state y".into() };
        assert_eq!(plain.to_string(), "state y became non-finite at t = 4.968");
        let zero = OdeError::NonFinite { t: 0.0, what: "state y".into() };
        assert_eq!(zero.to_string(), "state y became non-finite at t = 0");
        let far = OdeError::TooManySteps { steps: 10, t: 3e11, t_end: 1e12 };
        assert_eq!(
            far.to_string(),
            "too many steps: 10 steps taken by t = 3e11 without reaching 1e12"
        );
    }
}
