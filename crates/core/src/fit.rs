//! The interface every identification method implements, so that studies, reports and the
//! command line treat them alike.

use sysid_ode::System;

use crate::error::FitError;
use crate::estimate::Estimate;
use crate::problem::Problem;

/// An identification method: from a problem and a starting point to an [`Estimate`].
///
/// `Err` is for misuse (a start of the wrong length, data the method cannot handle); a run
/// that does not converge returns `Ok` with its [`Termination`](crate::Termination).
///
/// The trait is generic over the system so that the right-hand side is compiled into each
/// method (no dynamic dispatch in the integrator); for a given system type it is
/// object-safe: `Vec<Box<dyn Method<S>>>` holds any mix of methods.
pub trait Method<S: System> {
    /// The method's name as the command line spells it.
    fn name(&self) -> &str;

    /// What a fit integrates from at its start, as a message names it when the model cannot
    /// be integrated there: the starting guess, for the methods that shoot from it.
    fn start_point(&self) -> &str {
        "the starting guess"
    }

    /// Fits from `start` (values of the unknowns, in the problem's order).
    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError>;

    /// One run from `start`, as a multistart runs each of its starts. A method that runs
    /// again from the same start when its first run stalls on flat ground (the trust
    /// regions' cautious retry, [`Estimate::retried`]) does not here: among many starts, the
    /// next start is the retry. The default is [`fit_from`](Self::fit_from).
    fn fit_once_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.fit_from(problem, start)
    }

    /// Fits from the problem's starting guesses.
    fn fit(&self, problem: &Problem<S>) -> Result<Estimate, FitError> {
        self.fit_from(problem, &problem.guesses())
    }
}

/// Checks a starting point against a problem and returns its coordinates.
pub fn start_coordinates<S: System>(
    problem: &Problem<S>,
    start: &[f64],
) -> Result<Vec<f64>, FitError> {
    let k = problem.unknowns().len();
    if start.len() != k {
        return Err(FitError::InvalidStart(format!("{} values for {k} unknowns", start.len())));
    }
    for (u, &v) in problem.unknowns().list().iter().zip(start) {
        if !v.is_finite() || (u.log && v <= 0.0) {
            return Err(FitError::InvalidStart(format!("`{}` = {v}", u.name)));
        }
    }
    let mut z = problem.unknowns().coordinates(start);
    problem.unknowns().project(&mut z);
    Ok(z)
}

/// Runs `f`, turning a panic in it (a defect in sysid) into `Err` with the panic's message,
/// for callers that run many fits (multistart, studies, profiles) and keep the others' results
/// when one of them hits a defect. The message and its location also reach stderr through the
/// panic hook.
pub fn caught<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|m| m.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into())
    })
}
