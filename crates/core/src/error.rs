//! Errors for misuse and bad input. A method that does not converge is not an error: see
//! [`Termination`](crate::Termination).

use thiserror::Error;

/// An identification problem that cannot be set up as given.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum ProblemError {
    /// A known value or unknown names nothing in the system.
    #[error(
        "`{name}` is not a state or parameter of the system (states: {states}; parameters: {parameters})"
    )]
    UnknownName {
        /// The name given.
        name: String,
        /// The system's states, comma-separated.
        states: String,
        /// The system's parameters, comma-separated.
        parameters: String,
    },
    /// A name was given a value or made unknown more than once.
    #[error("`{name}` is given twice (as {first} and as {second})")]
    SpecifiedTwice {
        /// The name.
        name: String,
        /// How it was given first ("known", "unknown").
        first: &'static str,
        /// How it was given again.
        second: &'static str,
    },
    /// A state's initial value or a parameter is neither known nor unknown.
    #[error("{kind} `{name}` is neither known nor unknown: give it a value or make it an unknown")]
    NotSpecified {
        /// "state" or "parameter".
        kind: &'static str,
        /// Its name.
        name: String,
    },
    /// A number that must be finite (and maybe positive) is not.
    #[error("invalid value for {what}: {value}")]
    InvalidValue {
        /// What it is.
        what: String,
        /// The value.
        value: f64,
    },
    /// Bounds or scale of an unknown are inconsistent.
    #[error("unknown `{name}`: {message}")]
    InvalidUnknown {
        /// The unknown.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// `--fix` (or [`Problem::with_fixed`](crate::Problem::with_fixed)) names something that
    /// is not an unknown.
    #[error("`{name}` is not an unknown of the problem (unknowns: {unknowns})")]
    NotAnUnknown {
        /// The name given.
        name: String,
        /// The unknowns, comma-separated.
        unknowns: String,
    },
    /// There is nothing to identify.
    #[error("no unknowns: name at least one parameter or initial value to identify")]
    NoUnknowns,
    /// Every unknown is held at a fixed value: nothing is left to identify.
    #[error(
        "every unknown is held at a fixed value ({0}): nothing is left to identify; fix fewer of them"
    )]
    AllFixed(String),
    /// No data were given.
    #[error("no measurements: give at least one measured series or record")]
    NoData,
    /// A measured series names something that is neither a state nor an output.
    #[error(
        "measured series `{name}` is not a state or output of the system (observable: {observable})"
    )]
    UnknownSeries {
        /// The series name.
        name: String,
        /// The observable names, comma-separated.
        observable: String,
    },
    /// A series is malformed.
    #[error("measured series `{name}`: {message}")]
    InvalidSeries {
        /// The series.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// Synthetic data could not be simulated.
    #[error("could not simulate the data: {0}")]
    Simulation(String),
    /// The integrator settings are invalid.
    #[error("integrator: {0}")]
    Integrator(sysid_ode::InvalidSetting),
    /// The experiments, their settings or the unknowns they use do not fit together.
    #[error("{0}")]
    Experiments(String),
}

/// Misuse of a method: a start of the wrong length, data the method cannot handle.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum FitError {
    /// The starting point has the wrong length or a non-finite entry.
    #[error("invalid start: {0}")]
    InvalidStart(String),
    /// The method does not support this kind of problem.
    #[error("{method} does not support {what}")]
    Unsupported {
        /// The method.
        method: String,
        /// What it cannot do.
        what: String,
    },
    /// The method's options are invalid. The options error is in the message and not also
    /// the `source`, which a report of the whole chain (anyhow's `{:#}`) would print again.
    #[error("invalid options: {0}")]
    InvalidOptions(crate::options::OptionsError),
}

impl From<crate::options::OptionsError> for FitError {
    fn from(e: crate::options::OptionsError) -> Self {
        FitError::InvalidOptions(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::options::OptionsError;

    /// The error and its sources as anyhow's `{:#}` prints them.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut out = e.to_string();
        let mut source = e.source();
        while let Some(s) = source {
            out += &format!(": {s}");
            source = s.source();
        }
        out
    }

    #[test]
    fn an_invalid_option_is_told_once() {
        let e = FitError::from(OptionsError::Zero { name: "max_iterations" });
        assert_eq!(chain(&e), "invalid options: max_iterations must be at least 1");
    }
}
