//! The result of a fit: values, uncertainty, and how the method got there.

use std::fmt;
use std::time::Duration;

use nalgebra::DMatrix;
use serde::ser::{SerializeMap, SerializeStruct};
use serde::{Serialize, Serializer};
use sysid_ode::Counts;

/// Why a method stopped. Not converging is a result, not an error.
#[derive(Clone, Debug, PartialEq)]
pub enum Termination {
    /// A convergence test was met.
    Converged(Convergence),
    /// The iteration budget ran out.
    MaxIterations,
    /// The normal matrix is (nearly) singular: these unknowns cannot be told apart by the
    /// data, or do not influence it.
    SingularNormalMatrix {
        /// Names of the unknowns in the null space, in problem order.
        unknowns: Vec<String>,
        /// Condition number of the Jacobi-scaled normal matrix.
        condition: f64,
    },
    /// The model could not be integrated at an iterate.
    IntegrationFailed {
        /// The integrator's message, with the time it failed.
        message: String,
    },
    /// Step halving (or a line search) could not reduce the cost.
    NoDescent,
    /// The optimisation library stopped with an error of its own.
    SolverFailed {
        /// Its message.
        message: String,
    },
}

/// Which convergence test was met.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Convergence {
    /// The step fell below the step tolerance.
    Step,
    /// The gradient fell below the gradient tolerance.
    Gradient,
    /// The model passes through every data point (ε = 0).
    ExactFit,
    /// The change of the cost between iterations (argmin's rule), or the decrease the next
    /// step predicts (Goodman's cost tolerance), fell below the tolerance.
    CostChange,
}

impl Termination {
    /// Whether a convergence test was met.
    pub fn is_converged(&self) -> bool {
        matches!(self, Termination::Converged(_))
    }
}

impl fmt::Display for Termination {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Termination::Converged(Convergence::Step) => {
                write!(f, "converged: step below tolerance")
            }
            Termination::Converged(Convergence::Gradient) => {
                write!(f, "converged: gradient below tolerance")
            }
            Termination::Converged(Convergence::ExactFit) => {
                write!(f, "converged: the model passes through the data (ε = 0)")
            }
            Termination::MaxIterations => write!(f, "not converged: iteration limit reached"),
            Termination::SingularNormalMatrix { unknowns, condition } => write!(
                f,
                "singular normal matrix (condition {condition:.1e}): the data cannot tell apart {}",
                unknowns.join(", ")
            ),
            Termination::IntegrationFailed { message } => {
                write!(f, "integration failed: {message}")
            }
            Termination::NoDescent => write!(f, "not converged: no step reduced the cost"),
            Termination::SolverFailed { message } => write!(f, "solver error: {message}"),
            Termination::Converged(Convergence::CostChange) => {
                write!(f, "converged: cost change below tolerance")
            }
        }
    }
}

/// One row of the iteration history, for the iterate z_i.
#[derive(Clone, Debug, PartialEq)]
pub struct Iteration {
    /// i = number of updates before this iterate.
    pub iteration: usize,
    /// ε at the iterate.
    pub cost: f64,
    /// |U| (Euclidean norm of half the gradient of ε).
    pub gradient_norm: f64,
    /// Norm of the update that led here (None for the start).
    pub step_norm: Option<f64>,
    /// Condition number of the Jacobi-scaled normal matrix at the iterate.
    pub condition: Option<f64>,
    /// The unknowns at the iterate (values).
    pub values: Vec<f64>,
    /// Quasilinearization: ε of the linear family whose optimum gave this iterate (ε above
    /// is that of the nonlinear model re-integrated from the iterate). None for other methods.
    pub linear_cost: Option<f64>,
}

/// The estimate of the unknowns with its uncertainty and the record of the run.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The method that produced it.
    pub method: String,
    /// Names of the unknowns.
    pub names: Vec<String>,
    /// Estimated values.
    pub values: Vec<f64>,
    /// Standard errors, sqrt(diag Cov) (None when there is no residual variance: as many data
    /// as unknowns, or a record given as a function).
    pub std_errors: Option<Vec<f64>>,
    /// Covariance of the values: s² A⁻¹ with s² = ε/(N − k).
    pub covariance: Option<DMatrix<f64>>,
    /// ε at the estimate.
    pub cost: f64,
    /// Number of updates of the unknowns.
    pub iterations: usize,
    /// Why the method stopped.
    pub termination: Termination,
    /// One row per iterate, the start first.
    pub history: Vec<Iteration>,
    /// Wall-clock time of the fit.
    pub elapsed: Duration,
    /// Work done by all integrations of the fit.
    pub counts: Counts,
}

impl Estimate {
    /// Whether the method converged.
    pub fn converged(&self) -> bool {
        self.termination.is_converged()
    }
    /// Same as [`converged`](Self::converged).
    pub fn succeeded(&self) -> bool {
        self.converged()
    }
    /// The estimate of one unknown by name.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.names.iter().position(|n| n == name).map(|i| self.values[i])
    }

    /// The fit as the object of the `sysid fit --format json` contract (DESIGN.md), keys in
    /// the contract's order: serialise it with serde_json.
    pub fn record<'a>(&'a self, system: &'a str) -> FitRecord<'a> {
        FitRecord { system, estimate: self }
    }
}

/// The `sysid fit --format json` object: the contract keys in the contract's order, then the
/// extensions (termination, gradient norm and condition per iteration, work counts).
pub struct FitRecord<'a> {
    /// The system's name.
    pub system: &'a str,
    /// The fit.
    pub estimate: &'a Estimate,
}

/// Names paired with values, serialised as an object in their order.
struct Named<'a, T>(&'a [String], &'a [T]);
impl<T: Serialize> Serialize for Named<'_, T> {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in self.0.iter().zip(self.1) {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

/// A float that is written as null when it is not finite (JSON has no NaN).
struct Num(f64);
impl Serialize for Num {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        if self.0.is_finite() { s.serialize_f64(self.0) } else { s.serialize_none() }
    }
}

impl Serialize for Iteration {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        let mut st = s.serialize_struct("Iteration", 6)?;
        st.serialize_field("iteration", &self.iteration)?;
        st.serialize_field("cost", &Num(self.cost))?;
        st.serialize_field("step_norm", &self.step_norm.map(Num))?;
        st.serialize_field("gradient_norm", &Num(self.gradient_norm))?;
        st.serialize_field("condition", &self.condition.map(Num))?;
        if let Some(c) = self.linear_cost {
            st.serialize_field("linear_cost", &Num(c))?;
        }
        st.end()
    }
}

impl Serialize for FitRecord<'_> {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        let e = self.estimate;
        let mut st = s.serialize_struct("Fit", 12)?;
        st.serialize_field("system", self.system)?;
        st.serialize_field("method", &e.method)?;
        st.serialize_field("converged", &e.converged())?;
        st.serialize_field("iterations", &e.iterations)?;
        st.serialize_field("cost", &Num(e.cost))?;
        let values: Vec<Num> = e.values.iter().map(|&v| Num(v)).collect();
        st.serialize_field("estimates", &Named(&e.names, &values))?;
        let errors: Vec<Num> = match &e.std_errors {
            Some(se) => se.iter().map(|&v| Num(v)).collect(),
            None => e.names.iter().map(|_| Num(f64::NAN)).collect(),
        };
        st.serialize_field("std_errors", &Named(&e.names, &errors))?;
        st.serialize_field("history", &e.history)?;
        st.serialize_field("elapsed_ms", &(e.elapsed.as_secs_f64() * 1e3))?;
        st.serialize_field("termination", &e.termination.to_string())?;
        st.serialize_field("counts", &e.counts)?;
        st.end()
    }
}

impl fmt::Display for Estimate {
    /// A readable table: estimates with standard errors, then the run.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let width = self.names.iter().map(|n| n.chars().count()).max().unwrap_or(0).max(7);
        writeln!(f, "{:<width$}  {:>22}  {:>12}", "unknown", "estimate", "std. error")?;
        for (i, name) in self.names.iter().enumerate() {
            let se = match &self.std_errors {
                Some(s) => format!("{:.6e}", s[i]),
                None => "—".into(),
            };
            writeln!(f, "{name:<width$}  {:>22}  {se:>12}", format_value(self.values[i]))?;
        }
        writeln!(f)?;
        writeln!(f, "method       {}", self.method)?;
        writeln!(f, "termination  {}", self.termination)?;
        writeln!(f, "iterations   {}", self.iterations)?;
        writeln!(f, "cost ε       {}", format_value(self.cost))?;
        write!(
            f,
            "work         {} integrations, {} steps ({} rejected), {:.3} ms",
            self.counts.integrations,
            self.counts.steps,
            self.counts.rejected_steps,
            self.elapsed.as_secs_f64() * 1e3
        )
    }
}

/// Shortest representation that reads back to the same f64.
fn format_value(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e9).contains(&a) { format!("{v:e}") } else { format!("{v}") }
}
