//! `sysid fit`.

use clap::Args;
use sysid_core::{Estimate, Problem, Termination};
use sysid_ode::System;

use crate::format::significant;
use crate::integrator::IntegratorArgs;
use crate::methods::{Common, METHODS, QlStart, method};
use crate::source::{Context, SourceArgs, WithProblem, with_problem};
use crate::{Format, Outcome};

/// Arguments of `sysid fit`.
#[derive(Args, Debug)]
pub struct FitArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// The method: goodman, goodman-halving, gauss-newton, gauss-newton-ls, gauss-newton-fd,
    /// quasilinearization, quasilinearization-data.
    #[arg(long, default_value = "goodman", value_name = "METHOD")]
    method: String,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    /// First trajectory of quasilinearization: the model from the guess, or the data.
    #[arg(long, value_enum, default_value_t = QlStart::Guess)]
    ql_start: QlStart,
    /// Most updates of the unknowns.
    #[arg(long, value_name = "N")]
    max_iterations: Option<usize>,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

impl FitArgs {
    /// The method's shared options.
    pub fn common(&self) -> Common {
        Common { max_iterations: self.max_iterations, ql_start: self.ql_start, ..Common::default() }
    }
}

/// Runs `sysid fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<Outcome> {
    with_problem(&args.source, FitProblem { args })
}

struct FitProblem<'a> {
    args: &'a FitArgs,
}

impl WithProblem for FitProblem<'_> {
    type Output = Outcome;

    fn run<S: System + Clone + Send + Sync + 'static>(
        self,
        problem: Problem<S>,
        context: Context,
    ) -> anyhow::Result<Outcome> {
        let args = self.args;
        let problem = args.integrator.apply(problem)?;
        let estimate = fit(&problem, &args.method, args.common())?;
        match args.format {
            Format::Json => {
                println!("{}", serde_json::to_string_pretty(&estimate.record(&context.name))?)
            }
            Format::Table => print!("{}", table(&context, &estimate)),
        }
        Ok(if estimate.converged() { Outcome::Success } else { Outcome::NotConverged })
    }
}

/// Fits with the named method. What is bad input rather than a method's failure is an
/// error: unknowns the data cannot tell apart, and a model that cannot be integrated from
/// the starting guess.
pub fn fit<S: System>(
    problem: &Problem<S>,
    name: &str,
    common: Common,
) -> anyhow::Result<Estimate> {
    let estimate = method::<S>(name, common)?.fit(problem)?;
    match &estimate.termination {
        Termination::SingularNormalMatrix { unknowns, condition } => anyhow::bail!(
            "the data cannot identify {} (singular normal matrix, condition {condition:.1e}): fix some of them or add data",
            unknowns.join(", ")
        ),
        Termination::IntegrationFailed { message } if estimate.iterations == 0 => {
            anyhow::bail!("the model cannot be integrated from the starting guess: {message}")
        }
        _ => Ok(estimate),
    }
}

/// The readable report: estimates next to the reference or truth, then the run.
fn table(context: &Context, e: &Estimate) -> String {
    let mut out = String::new();
    let describe = METHODS.iter().find(|m| m.0 == e.method).map_or("", |m| m.1);
    out += &format!("{}: {}\n", context.name, context.summary);
    out += &format!("method {}: {describe}\n\n", e.method);
    out += &format!(
        "  {:<10} {:>24} {:>14} {:>24}\n",
        "unknown", "estimate", "std. error", context.expected_label
    );
    for (i, name) in e.names.iter().enumerate() {
        let se = e.std_errors.as_ref().map_or("—".to_string(), |s| significant(s[i], 5));
        let expected = context.expected(name).map_or(String::new(), |v| format!("{v}"));
        out +=
            &format!("  {name:<10} {:>24} {se:>14} {expected:>24}\n", significant(e.values[i], 10));
    }
    out += "\n";
    out += &format!("  termination  {}\n", e.termination);
    out += &format!("  iterations   {}\n", e.iterations);
    let reference_cost = context
        .reference_cost
        .map_or(String::new(), |(cost, source)| format!("   (reference {cost}, {source})"));
    out += &format!("  cost ε       {}{reference_cost}\n", significant(e.cost, 10));
    out += &format!(
        "  work         {} integrations, {} steps ({} rejected), {} right-hand-side evaluations, {:.3} ms\n\n",
        e.counts.integrations,
        e.counts.steps,
        e.counts.rejected_steps,
        e.counts.rhs_evaluations,
        e.elapsed.as_secs_f64() * 1e3
    );
    out += &format!(
        "  {:>9} {:>24} {:>12} {:>12} {:>12}\n",
        "iteration", "cost ε", "|U|", "step", "condition"
    );
    for h in &e.history {
        let step = h.step_norm.map_or("—".to_string(), |s| format!("{s:.3e}"));
        let cond = h.condition.map_or("—".to_string(), |c| format!("{c:.3e}"));
        out += &format!(
            "  {:>9} {:>24} {:>12.3e} {step:>12} {cond:>12}\n",
            h.iteration,
            significant(h.cost, 10),
            h.gradient_norm
        );
    }
    out
}
