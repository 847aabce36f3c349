//! `sysid fit`.

use anyhow::{Context, anyhow};
use clap::Args;
use sysid_core::Estimate;
use sysid_ode::System;
use sysid_systems::{Case, Visit};

use crate::format::significant;
use crate::methods::{Common, METHODS, QlStart, method};
use crate::{Format, Outcome};

/// Arguments of `sysid fit`.
#[derive(Args, Debug)]
pub struct FitArgs {
    /// The catalogue system to identify (`sysid systems` lists them).
    #[arg(long, value_name = "NAME")]
    system: String,
    /// The method: goodman, goodman-halving, gauss-newton, gauss-newton-ls, gauss-newton-fd,
    /// quasilinearization, quasilinearization-data.
    #[arg(long, default_value = "goodman", value_name = "METHOD")]
    method: String,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    /// Seed of the synthetic data (systems with fixed data ignore it).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// First trajectory of quasilinearization: the model from the guess, or the data.
    #[arg(long, value_enum, default_value_t = QlStart::Guess)]
    ql_start: QlStart,
    /// Most updates of the unknowns.
    #[arg(long, value_name = "N")]
    max_iterations: Option<usize>,
    /// Relative tolerance of the integrator (default: the system's).
    #[arg(long, value_name = "RTOL", allow_negative_numbers = true)]
    rtol: Option<f64>,
    /// Absolute tolerance of the integrator (default: the system's).
    #[arg(long, value_name = "ATOL", allow_negative_numbers = true)]
    atol: Option<f64>,
}

/// Runs `sysid fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<Outcome> {
    sysid_systems::visit(&args.system, FitCase { args }).ok_or_else(|| {
        anyhow!("unknown system `{}` (systems: {})", args.system, sysid_systems::NAMES.join(", "))
    })?
}

struct FitCase<'a> {
    args: &'a FitArgs,
}

impl Visit for FitCase<'_> {
    type Output = anyhow::Result<Outcome>;

    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        let args = self.args;
        let method = method::<S>(
            &args.method,
            Common { max_iterations: args.max_iterations, ql_start: args.ql_start },
        )?;
        let mut problem =
            case.problem(args.seed).with_context(|| format!("system {}", case.name))?;
        if args.rtol.is_some() || args.atol.is_some() {
            let mut integrator = *problem.integrator();
            integrator.rtol = args.rtol.unwrap_or(integrator.rtol);
            integrator.atol = args.atol.unwrap_or(integrator.atol);
            problem = problem.with_integrator(integrator)?;
        }
        let estimate = method.fit(&problem)?;
        match args.format {
            Format::Json => {
                println!("{}", serde_json::to_string_pretty(&estimate.record(case.name))?)
            }
            Format::Table => print!("{}", table(&case, &estimate)),
        }
        Ok(if estimate.converged() { Outcome::Success } else { Outcome::NotConverged })
    }
}

/// The readable report: estimates next to the reference or truth, then the run.
fn table<S>(case: &Case<S>, e: &Estimate) -> String
where
    S: System + Clone,
{
    let mut out = String::new();
    let describe = METHODS.iter().find(|m| m.0 == e.method).map_or("", |m| m.1);
    out += &format!("{}: {}\n", case.name, case.summary);
    out += &format!("method {}: {describe}\n\n", e.method);
    let expected_label = match &case.reference {
        Some(_) => "reference",
        None if !case.truth.is_empty() => "truth",
        None => "",
    };
    out += &format!(
        "  {:<10} {:>24} {:>14} {:>24}\n",
        "unknown", "estimate", "std. error", expected_label
    );
    for (i, name) in e.names.iter().enumerate() {
        let se = e.std_errors.as_ref().map_or("—".to_string(), |s| significant(s[i], 5));
        let expected = case.expected(name).map_or(String::new(), |v| format!("{v}"));
        out +=
            &format!("  {name:<10} {:>24} {se:>14} {expected:>24}\n", significant(e.values[i], 10));
    }
    out += "\n";
    out += &format!("  termination  {}\n", e.termination);
    out += &format!("  iterations   {}\n", e.iterations);
    let reference_cost = case
        .reference
        .as_ref()
        .map_or(String::new(), |r| format!("   (reference {}, {})", r.cost, r.source));
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
