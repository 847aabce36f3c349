//! Why a run ended, as data: the stopping rule that fired (judged by the certificate), the
//! budget that ran out, or the failure with the iteration and the point where it happened.
//!
//! Every termination has a stable snake_case [`code`](Termination::code), the
//! `termination_code` of the JSON report; docs/terminations.md lists them.

use std::fmt;

use serde::Serialize;
use sysid_ode::OdeError;

/// A method's own stopping rule. It says when to stop iterating, not whether the point is a
/// minimum: the [`Certificate`](crate::Certificate) says that, and decides between
/// [`Termination::Converged`] and [`Termination::Stalled`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// The (projected) step fell below the step tolerance: ‖δz‖ ≤ tol·(‖z‖ + tol).
    Step,
    /// The first-order optimality measure fell below the gradient tolerance.
    Gradient,
    /// The decrease of ε the next step predicts fell below a fraction of ε (MINPACK's ftol,
    /// Goodman's cost tolerance).
    PredictedDecrease,
    /// ‖r‖ changed by less than the tolerance between two iterates (argmin's rule).
    CostChange,
    /// No step along the search direction reduced the cost (step halving, line search).
    NoDescent,
    /// ε is exactly 0: the model passes through every data point.
    ExactFit,
    /// ε fell by less than [`PROGRESS`] of itself over the last [`PROGRESS_WINDOW`]
    /// iterations (the driver's rule, for every method): a crawl along a sloppy direction.
    Progress,
    /// The certificate's measure is within gtol and ε fell by less than [`SETTLE`] of itself
    /// over the last [`SETTLE_WINDOW`] iterations (the driver's rule, for every method): the
    /// point is a minimum to the promised accuracy and further steps no longer lower the
    /// cost. It stops the run where the certificate then holds, and otherwise only once the
    /// extra steps after an earlier rule are used up (then the run is stalled).
    Settled,
}

/// The iterations over which [`Rule::Progress`] measures the fall of ε.
pub const PROGRESS_WINDOW: usize = 100;

/// The fall of ε, relative to ε, below which [`PROGRESS_WINDOW`] iterations made no progress.
pub const PROGRESS: f64 = 1e-6;

/// The iterations over which [`Rule::Settled`] measures the fall of ε.
pub const SETTLE_WINDOW: usize = 10;

/// The fall of ε, relative to ε, below which a certified run has settled over
/// [`SETTLE_WINDOW`] iterations (fides' default `frtol` is this per iteration).
pub const SETTLE: f64 = 1e-8;

impl Rule {
    /// The rule's snake_case name.
    pub fn code(self) -> &'static str {
        match self {
            Rule::Step => "step",
            Rule::Gradient => "gradient",
            Rule::PredictedDecrease => "predicted_decrease",
            Rule::CostChange => "cost_change",
            Rule::NoDescent => "no_descent",
            Rule::ExactFit => "exact_fit",
            Rule::Progress => "progress",
            Rule::Settled => "settled",
        }
    }
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Rule::Step => "step below tolerance",
            Rule::Gradient => "gradient below tolerance",
            Rule::PredictedDecrease => "predicted decrease of the cost below tolerance",
            Rule::CostChange => "cost change below tolerance",
            Rule::NoDescent => "no step along the search direction reduced the cost",
            Rule::ExactFit => "the model passes through the data (ε = 0)",
            Rule::Progress => "the cost fell by less than 1e-6 of itself over 100 iterations",
            Rule::Settled => {
                "optimality within gtol, and the cost fell by less than 1e-8 of itself over 10 iterations"
            }
        })
    }
}

/// What went wrong at a point. Values are the unknowns' values (not coordinates).
#[derive(Clone, Debug, PartialEq)]
pub enum Failure {
    /// The model could not be integrated at `at` (including a solution that blows up).
    Integration {
        /// The integrator's error, with its time.
        error: OdeError,
        /// The unknowns where it failed.
        at: Vec<f64>,
    },
    /// The model integrated, but ε, its gradient or the normal matrix is not finite there
    /// (overflow), or a residual's square overflows.
    NonFinite {
        /// What is not finite, as a clause ("ε is not finite"), with the residual row when one
        /// overflows.
        what: String,
        /// The unknowns where it happened.
        at: Vec<f64>,
    },
    /// The (method's) normal matrix is singular at the iterate the step starts from.
    Singular {
        /// Names of the unknowns in the near null space, in problem order.
        unknowns: Vec<String>,
        /// Condition number of the Jacobi-scaled matrix.
        condition: f64,
    },
    /// The hard budget of model integrations is used up: another evaluation, which
    /// integrates every experiment once, would exceed it.
    Budget {
        /// The budget.
        integrations: u64,
    },
    /// The optimisation library stopped with an error of its own.
    Solver(String),
}

impl Failure {
    /// A singular matrix, its unknowns (indices into `names`) named.
    pub fn singular(singular: &crate::linalg::Singular, names: &[String]) -> Self {
        Failure::Singular {
            unknowns: singular.unknowns.iter().map(|&i| names[i].clone()).collect(),
            condition: singular.condition,
        }
    }

    /// Where it happened, when it is a point.
    pub fn at(&self) -> Option<&[f64]> {
        match self {
            Failure::Integration { at, .. } | Failure::NonFinite { at, .. } => Some(at),
            _ => None,
        }
    }

    fn code(&self) -> &'static str {
        match self {
            Failure::Integration { error: OdeError::BlowUp { .. }, .. } => "blow_up",
            Failure::Integration { .. } => "integration_failed",
            Failure::NonFinite { .. } => "non_finite",
            Failure::Singular { .. } => "singular",
            Failure::Budget { .. } => "integration_budget",
            Failure::Solver(_) => "solver_failed",
        }
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Failure::Integration { error, .. } => write!(f, "{error}"),
            Failure::NonFinite { what, .. } => write!(f, "{what}"),
            Failure::Singular { unknowns, condition } => write!(
                f,
                "singular normal matrix (condition {condition:.1e}) involving {}",
                unknowns.join(", ")
            ),
            Failure::Budget { integrations } => {
                write!(f, "the budget of {integrations} model integrations is used up")
            }
            Failure::Solver(message) => write!(f, "solver error: {message}"),
        }
    }
}

/// Why a method stopped. Not converging is a result, not an error; whether the returned
/// point is a minimum is the certificate's verdict ([`Estimate::converged`](crate::Estimate::converged)).
///
/// Each has a stable code (the JSON's `termination_code`, docs/terminations.md) and a
/// sentence for people:
///
/// ```
/// use sysid_core::{Rule, Termination};
///
/// let done = Termination::Converged(Rule::Step);
/// assert_eq!(done.code(), "converged_step");
/// assert_eq!(Termination::Converged(Rule::ExactFit).code(), "exact_fit");
/// let limit = Termination::MaxIterations {
///     fell: Some(0.25),
///     moving: vec!["k".into()],
///     unresolved_gradient: None,
/// };
/// assert_eq!(limit.code(), "max_iterations");
/// assert!(done.failure().is_none());
/// println!("{done}"); // converged: step below tolerance
/// ```
#[derive(Clone, Debug, PartialEq)]
pub enum Termination {
    /// A stopping rule fired and the certificate holds at the returned point.
    Converged(Rule),
    /// A stopping rule fired at an iterate that fails the certificate: the method stopped
    /// where the cost is not stationary. The best iterate is reported.
    Stalled {
        /// The rule that stopped the method.
        rule: Rule,
        /// The iterate it stopped at.
        iteration: usize,
        /// The certificate's measure there.
        optimality: f64,
        /// The measure's integration error there (the certificate's `error`; 0 where not
        /// measured).
        error: f64,
        /// Whether the point is a plateau: the model responds to no unknown there.
        plateau: bool,
        /// The unknowns the model does not respond to there, off their bounds: the data do
        /// not determine them ([`Certificate::undetermined`](crate::Certificate::undetermined)).
        undetermined: Vec<String>,
        /// After [`Rule::Progress`]: the unknowns still moving over its window, most first
        /// (those whose coordinate moved at least a tenth of the most any did, at most 5).
        moving: Vec<String>,
        /// Where the point passes the first-order test at the working integration but the
        /// integration that measures its error (at a tenth of the tolerances; for a fixed
        /// step, with error control) fails there: that failure
        /// ([`Certificate::unchecked`](crate::Certificate::unchecked)).
        unchecked: Option<String>,
        /// Where the integration does not resolve the model at the point
        /// ([`Certificate::unresolved`](crate::Certificate::unresolved)): ε's integration
        /// error and ε. The unknowns are then named neither undetermined nor moving.
        unresolved: Option<(f64, f64)>,
        /// Where the method's last trial before the stop could not be integrated: its
        /// error. A trust region that shrinks to nothing because every step towards a lower
        /// cost fails to integrate has stopped at the edge of where the model has a solution
        /// (a blow-up), not at a minimum.
        blocked: Option<String>,
    },
    /// The iteration budget ran out.
    MaxIterations {
        /// How much the cost (the history's: under noise-scale profiling, the profile's)
        /// fell over the last [`PROGRESS_WINDOW`] iterations of the last round: what the next
        /// iterations may still gain. Absent for a shorter round, or where the fall is at most
        /// [`PROGRESS`] of the cost (what the progress rule counts as none).
        fell: Option<f64>,
        /// The unknowns that moved most over that window, most first (those whose coordinate
        /// moved at least a tenth of the most any did, at most 5), as after [`Rule::Progress`].
        moving: Vec<String>,
        /// Where the point returned is not certified and its measure is within the measure's
        /// integration error: the measure and that error. The gradient there is then mostly
        /// the integration's error (Crauste_CellSystems2017 from a random start: ∂NLL/∂ln δ_NE
        /// 9.1e3 at rtol 1e-8, 1.16e6 at 1e-10), and says nothing of how far a minimum is.
        unresolved_gradient: Option<(f64, f64)>,
    },
    /// The hard budget of model integrations ran out.
    IntegrationBudget {
        /// The budget (the fit's whole `max_integrations`).
        integrations: u64,
    },
    /// The wall-clock limit ([`DriverOptions::max_seconds`](crate::DriverOptions::max_seconds))
    /// ran out; it is read between iterations, so the last one may end after it.
    TimeLimit {
        /// The limit, in seconds.
        seconds: f64,
    },
    /// The caller asked the fit to stop ([`stop_when`](crate::observer::stop_when): Python's
    /// Ctrl-C, a progress callback that raised); it is read between iterations, as the time
    /// limit is.
    Interrupted,
    /// Stepping from iterate `iteration` failed; the best iterate so far is reported.
    Failed {
        /// The iterate the step started from.
        iteration: usize,
        /// What went wrong, and where.
        failure: Failure,
    },
    /// The starting point itself cannot be evaluated: not a result of the method, but a
    /// start (or data) to change.
    StartFailed(Failure),
    /// The fit panicked with this message: a defect in sysid, not a result of the method or
    /// a property of the start. Only a caller that runs many fits forms it
    /// ([`Estimate::panicked`](crate::Estimate::panicked)): a multistart reports the start so
    /// and keeps the others.
    Panicked(String),
}

impl Termination {
    /// The stable snake_case tag of the JSON report's `termination_code`.
    pub fn code(&self) -> String {
        match self {
            Termination::Converged(Rule::ExactFit) => "exact_fit".into(),
            Termination::Converged(rule) => format!("converged_{}", rule.code()),
            Termination::Stalled { rule, .. } => format!("stalled_{}", rule.code()),
            Termination::MaxIterations { .. } => "max_iterations".into(),
            Termination::IntegrationBudget { .. } => "integration_budget".into(),
            Termination::TimeLimit { .. } => "time_limit".into(),
            Termination::Interrupted => "interrupted".into(),
            Termination::Failed { failure, .. } => failure.code().into(),
            Termination::StartFailed(_) => "start_failed".into(),
            Termination::Panicked(_) => "panicked".into(),
        }
    }

    /// The failure, if the run ended on one.
    pub fn failure(&self) -> Option<&Failure> {
        match self {
            Termination::Failed { failure, .. } | Termination::StartFailed(failure) => {
                Some(failure)
            }
            _ => None,
        }
    }
}

impl fmt::Display for Termination {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.sentence(f)?;
        match self {
            Termination::Stalled { blocked: Some(why), .. } => write!(
                f,
                "; its last trial step could not be integrated ({why}): it stopped at the edge of where the model can be integrated"
            ),
            _ => Ok(()),
        }
    }
}

impl Termination {
    /// The sentence for people, without what a stall's last trial met.
    fn sentence(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Termination::Converged(rule) => write!(f, "converged: {rule}"),
            Termination::Stalled { rule, iteration, unresolved: Some((error, cost)), .. } => {
                write!(
                    f,
                    "stalled at iteration {iteration}: {rule}, where the integration does not resolve the model: ε = {cost:.3e} there moves by {error:.3e} in the integration that checks it, so nothing the point's sensitivities say holds (no minimum, no flat direction); a finer integration (smaller --rtol and --atol: a state far below --atol is controlled only where the model starts it there, not where it starts at 0 or at a steady state) may go on from it"
                )
            }
            Termination::Stalled { rule, iteration, plateau: true, .. } => write!(
                f,
                "stalled at iteration {iteration}: {rule}, on a plateau: the model responds to no unknown there, so no test can tell it from a minimum"
            ),
            Termination::Stalled { rule, iteration, undetermined, .. }
                if !undetermined.is_empty() =>
            {
                write!(
                    f,
                    "stalled at iteration {iteration}: {rule}, but {} {} not determined: the model does not respond to {} there, and the cost may fall further as {} (a flat direction, not a minimum)",
                    undetermined.join(", "),
                    if undetermined.len() == 1 { "is" } else { "are" },
                    if undetermined.len() == 1 { "it" } else { "them" },
                    if undetermined.len() == 1 { "it moves" } else { "they move" }
                )
            }
            Termination::Stalled { rule, iteration, optimality, unchecked: Some(why), .. } => {
                write!(
                    f,
                    "stalled at iteration {iteration}: {rule}; the first-order test passes at the working integration (optimality {optimality:.2e}), but the evaluation that checks it (integrated again at a tenth of the tolerances; for a fixed step, with error control) fails there ({why}): the point's figures are not confirmed, and it is not a certified minimum"
                )
            }
            Termination::Stalled { rule, iteration, optimality, moving, .. }
                if !moving.is_empty() =>
            {
                write!(
                    f,
                    "stalled at iteration {iteration}: {rule}, along a sloppy direction: {} still {} (first-order optimality {optimality:.2e}: not a certified minimum)",
                    moving.join(", "),
                    if moving.len() == 1 { "moves" } else { "move" }
                )
            }
            // A measure within its own integration error says nothing either way.
            Termination::Stalled { rule, iteration, optimality, error, .. }
                if error > optimality && error.is_finite() =>
            {
                write!(
                    f,
                    "stalled at iteration {iteration}: {rule}, but the point is not certified: its first-order optimality {optimality:.2e} is within its integration error {error:.2e}, so the test cannot tell"
                )
            }
            Termination::Stalled { rule, iteration, optimality, .. } => write!(
                f,
                "stalled at iteration {iteration}: {rule}, but the point is not a minimum (first-order optimality {optimality:.2e})"
            ),
            Termination::MaxIterations { fell, moving, unresolved_gradient } => {
                let falling = fell.filter(|_| !moving.is_empty());
                match falling {
                    Some(fell) => write!(
                        f,
                        "iteration limit reached while the cost still falls: by {fell:.3e} over the last {PROGRESS_WINDOW} iterations, most along {}",
                        moving.join(", ")
                    )?,
                    None => write!(f, "iteration limit reached")?,
                }
                match unresolved_gradient {
                    Some((optimality, error)) => write!(
                        f,
                        "; its first-order optimality {optimality:.2e} is within its integration error {error:.2e}: the gradient there is mostly the integration's error, which a finer integration (smaller --rtol and --atol) resolves"
                    ),
                    None if falling.is_some() => {
                        write!(f, " (a larger iteration budget goes on from there)")
                    }
                    None => Ok(()),
                }
            }
            Termination::IntegrationBudget { integrations } => {
                write!(f, "the budget of {integrations} model integrations is used up")
            }
            Termination::TimeLimit { seconds } => {
                write!(f, "the time limit of {seconds} s ran out")
            }
            Termination::Interrupted => {
                write!(f, "interrupted: the run was asked to stop (Ctrl-C, a signal or the caller)")
            }
            Termination::Failed {
                iteration,
                failure: Failure::Singular { unknowns, condition },
            } => {
                write!(
                    f,
                    "singular normal matrix at iteration {iteration} (condition {condition:.1e}, involving {})",
                    unknowns.join(", ")
                )
            }
            Termination::Failed { iteration, failure } => {
                write!(f, "failed stepping from iteration {iteration}: {failure}")
            }
            Termination::StartFailed(failure) => write!(f, "the start cannot be used: {failure}"),
            Termination::Panicked(message) => write!(
                f,
                "the fit panicked, a defect in sysid (please report it with the command): {message}"
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stall at a point that passed the first-order test with a check that could not be
    /// integrated says so, with the check's error, and keeps the rule's code.
    #[test]
    fn an_unchecked_stall_names_the_failing_check() {
        let t = Termination::Stalled {
            rule: Rule::Step,
            iteration: 6,
            optimality: 7.8e-9,
            error: 0.0,
            plateau: false,
            undetermined: vec![],
            moving: vec!["k1".into()],
            unchecked: Some("too many steps: 120 steps taken".into()),
            unresolved: None,
            blocked: None,
        };
        assert_eq!(t.code(), "stalled_step");
        let said = t.to_string();
        for needle in [
            "optimality 7.80e-9",
            "the evaluation that checks it (integrated again",
            "too many steps: 120",
        ] {
            assert!(said.contains(needle), "`{needle}` not in {said}");
        }
        assert!(!said.contains("last trial"), "{said}");
        // A stall whose last trial could not be integrated ends with that trial's error,
        // whatever else it says.
        let t = Termination::Stalled {
            rule: Rule::Step,
            iteration: 13,
            optimality: 0.3,
            error: 0.0,
            plateau: false,
            undetermined: vec!["rho_E".into()],
            moving: vec![],
            unchecked: None,
            unresolved: None,
            blocked: Some("the solution blows up".into()),
        };
        let said = t.to_string();
        assert!(said.contains("rho_E is not determined"), "{said}");
        let end =
            "(the solution blows up): it stopped at the edge of where the model can be integrated";
        assert!(said.ends_with(end), "{said}");
    }

    /// A stall where the integration does not resolve the model says that first, with ε and
    /// its error, and names no unknown undetermined or moving, whatever the lists hold.
    #[test]
    fn an_unresolved_stall_claims_nothing_of_the_unknowns() {
        let t = Termination::Stalled {
            rule: Rule::Step,
            iteration: 41,
            optimality: 0.96,
            error: 0.04,
            plateau: false,
            undetermined: vec![],
            moving: vec!["init_Bac".into()],
            unchecked: None,
            unresolved: Some((4.19e15, 1.09e8)),
            blocked: None,
        };
        assert_eq!(t.code(), "stalled_step");
        let said = t.to_string();
        for needle in ["does not resolve the model", "ε = 1.090e8", "moves by 4.190e15", "--atol"]
        {
            assert!(said.contains(needle), "`{needle}` not in {said}");
        }
        assert!(!said.contains("init_Bac"), "{said}");
        // A measure below its own integration error is not said to show a point that is not
        // a minimum.
        let t = Termination::Stalled {
            rule: Rule::Step,
            iteration: 3,
            optimality: 1.34e-9,
            error: 3.17e-6,
            plateau: false,
            undetermined: vec![],
            moving: vec![],
            unchecked: None,
            unresolved: None,
            blocked: None,
        };
        let said = t.to_string();
        assert!(
            said.contains("optimality 1.34e-9 is within its integration error 3.17e-6"),
            "{said}"
        );
        assert!(!said.contains("not a minimum"), "{said}");
    }

    /// An iteration limit names the falling cost and where it went, or, where the gradient at
    /// the point is mostly integration error, says so.
    #[test]
    fn an_iteration_limit_says_when_the_gradient_is_integration_error() {
        let moving = vec!["k".to_string()];
        let falling = Termination::MaxIterations {
            fell: Some(0.25),
            moving: moving.clone(),
            unresolved_gradient: None,
        };
        assert!(falling.to_string().ends_with("(a larger iteration budget goes on from there)"));
        let blurred = Termination::MaxIterations {
            fell: Some(0.25),
            moving,
            unresolved_gradient: Some((6.7e-4, 3.5e-2)),
        };
        let said = blurred.to_string();
        assert!(said.starts_with("iteration limit reached while the cost still falls"), "{said}");
        assert!(said.contains("6.70e-4 is within its integration error 3.50e-2"), "{said}");
        assert!(!said.contains("larger iteration budget"), "{said}");
        assert_eq!(blurred.code(), "max_iterations");
    }

    /// docs/terminations.md is the contract: every code the driver can form has its row
    /// there (a code in backticks at the start of a table row, alone or in a list).
    #[test]
    fn every_termination_code_is_documented() {
        let doc = include_str!("../../../docs/terminations.md");
        let rows: Vec<&str> = doc.lines().filter(|l| l.starts_with("| `")).collect();
        let documented = |code: &str| {
            rows.iter().any(|r| {
                let first = r.split(" | ").next().unwrap_or("");
                first.contains(&format!("`{code}`"))
            })
        };
        let failure = |f: Failure| Termination::Failed { iteration: 1, failure: f };
        let mut terminations = vec![
            Termination::MaxIterations { fell: None, moving: vec![], unresolved_gradient: None },
            Termination::IntegrationBudget { integrations: 3 },
            Termination::TimeLimit { seconds: 1.0 },
            Termination::Interrupted,
            failure(Failure::NonFinite { what: "ε is not finite".into(), at: vec![] }),
            failure(Failure::Singular { unknowns: vec![], condition: 1e13 }),
            failure(Failure::Solver("argmin".into())),
            failure(Failure::Integration {
                error: OdeError::StepSizeTooSmall { t: 1.0, h: 1e-20 },
                at: vec![],
            }),
            failure(Failure::Integration {
                error: OdeError::BlowUp {
                    t: 1.0,
                    what: "x".into(),
                    value: 1e7,
                    start: 1.0,
                    steps: 10,
                },
                at: vec![],
            }),
            Termination::StartFailed(Failure::Solver("start".into())),
            Termination::Panicked("a finite move".into()),
        ];
        let rules = [
            Rule::Step,
            Rule::Gradient,
            Rule::PredictedDecrease,
            Rule::CostChange,
            Rule::NoDescent,
            Rule::Progress,
            Rule::Settled,
        ];
        for rule in rules {
            terminations.push(Termination::Converged(rule));
            terminations.push(Termination::Stalled {
                rule,
                iteration: 1,
                optimality: 1.0,
                error: 0.0,
                plateau: false,
                undetermined: vec![],
                moving: vec![],
                unchecked: None,
                unresolved: None,
                blocked: None,
            });
        }
        terminations.push(Termination::Converged(Rule::ExactFit));
        for t in terminations {
            assert!(documented(&t.code()), "{} is not in docs/terminations.md", t.code());
        }
    }
}
