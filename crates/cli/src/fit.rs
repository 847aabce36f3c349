//! `sysid fit`.

use clap::Args;
use sysid_core::{Bound, Estimate, Failure, Problem, Termination};
use sysid_ode::System;

use crate::format::significant;
use crate::integrator::IntegratorArgs;
use crate::methods::{Common, MethodArgs, StartsArgs, describe_starts, method, methods};
use crate::source::{Context, SourceArgs, WithProblem, with_problem};
use crate::{Format, Outcome};
use sysid_montecarlo::MultistartOptions;
use sysid_montecarlo::multistart::Starts;

/// Arguments of `sysid fit`.
#[derive(Args, Debug)]
pub struct FitArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// The method: goodman, goodman-halving, gauss-newton, gauss-newton-ls, gauss-newton-fd,
    /// levenberg-marquardt, multiple-shooting, quasilinearization, quasilinearization-data.
    #[arg(long, default_value = "goodman", value_name = "METHOD")]
    method: String,
    /// Output format: a readable table, or the JSON object of docs/json.md (printed
    /// for every run past input checking, converged or not).
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    #[command(flatten)]
    options: MethodArgs,
    #[command(flatten)]
    starts: StartsArgs,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// Runs `sysid fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<Outcome> {
    args.options.validate()?;
    args.starts.options()?;
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
        let problem = prepare(problem, &args.integrator, &args.options)?;
        let (estimate, starts) =
            fit_from_starts(&problem, &args.method, args.options.common(), &args.starts)?;
        match args.format {
            Format::Json => {
                let record = with_starts(estimate.record(&context.name), starts.as_ref());
                crate::emit(&format!("{}\n", serde_json::to_string_pretty(&record)?))?
            }
            Format::Table => {
                let mut text = table(&problem, &context, &estimate);
                if let Some(s) = &starts {
                    text += &format!("\n  starts       {}\n", describe_starts(s));
                }
                crate::emit(&text)?
            }
        }
        Ok(if estimate.converged() { Outcome::Success } else { Outcome::NotConverged })
    }
}

/// The problem with the command line's integrator settings and `--fix`ed unknowns.
pub fn prepare<S: System>(
    problem: Problem<S>,
    integrator: &IntegratorArgs,
    options: &MethodArgs,
) -> anyhow::Result<Problem<S>> {
    Ok(integrator.apply(problem)?.with_fixed(&options.fix)?)
}

/// Fits with the named method. A start that cannot be used is bad input, not a result of the
/// method: a model that cannot be evaluated there, or unknowns the data cannot tell apart
/// there before any step was taken.
pub fn fit<S: System>(
    problem: &Problem<S>,
    name: &str,
    common: Common,
) -> anyhow::Result<Estimate> {
    let estimate = method::<S>(name, &common)?.fit(problem)?;
    if let Some(message) = unusable_start(problem, &estimate) {
        anyhow::bail!(message);
    }
    Ok(estimate)
}

/// Fits with the named method from the problem's guess, or from the starts of `--starts`
/// (the best fit, and what the starts found). The start is unusable only when every start is.
pub fn fit_from_starts<S: System + Sync>(
    problem: &Problem<S>,
    name: &str,
    common: Common,
    starts: &StartsArgs,
) -> anyhow::Result<(Estimate, Option<Starts>)> {
    let Some(options) = starts.options()? else {
        return Ok((fit(problem, name, common)?, None));
    };
    let (best, starts) = best_of_starts(problem, &*method::<S>(name, &common)?, &options)?;
    Ok((best, Some(starts)))
}

/// `m` from the starts of `options`: the best fit and what the starts found. The start is
/// unusable only when every start is.
pub fn best_of_starts<S, M>(
    problem: &Problem<S>,
    m: &M,
    options: &MultistartOptions,
) -> anyhow::Result<(Estimate, Starts)>
where
    S: System + Sync,
    M: sysid_core::Method<S> + Sync + ?Sized,
{
    let run = sysid_montecarlo::multistart(m, problem, options)?;
    if let Some(message) = unusable_start(problem, &run.best) {
        anyhow::bail!("every start fails; the best: {message}");
    }
    Ok((run.best, run.starts))
}

/// A fit's JSON object with the `starts` object of a multistart run.
pub fn with_starts(
    record: sysid_core::FitRecord<'_>,
    starts: Option<&Starts>,
) -> serde_json::Value {
    let mut value = serde_json::to_value(record).expect("a fit record serialises");
    if let (Some(s), Some(map)) = (starts, value.as_object_mut()) {
        map.insert("starts".into(), serde_json::to_value(s).expect("starts serialise"));
    }
    value
}

/// Why the start cannot be used, if it cannot.
pub fn unusable_start<S: System>(problem: &Problem<S>, e: &Estimate) -> Option<String> {
    match &e.termination {
        Termination::StartFailed(Failure::Integration { error, .. }) => {
            Some(format!("the model cannot be integrated from the starting guess: {error}"))
        }
        Termination::StartFailed(failure) => {
            Some(format!("the starting guess cannot be used: {failure}"))
        }
        Termination::Failed { failure: Failure::Singular { .. }, .. } if e.iterations == 0 => {
            let space = e.certificate.null_space.as_ref()?;
            Some(format!(
                "the data cannot identify {} at the starting guess (singular normal matrix, condition {:.1e}; the combination {} is not seen by the data): fix some of them or add data",
                space.unknowns.join(", "),
                space.condition,
                space.combination(problem)
            ))
        }
        _ => None,
    }
}

/// The readable report: estimates next to the reference or truth, then the run.
fn table<S: System>(problem: &Problem<S>, context: &Context, e: &Estimate) -> String {
    let mut out = String::new();
    let describe = methods().into_iter().find(|m| m.0 == e.method).map_or("", |m| m.1);
    out += &format!("{}: {}\n", context.name, context.summary);
    out += &format!("method {}: {describe}\n\n", e.method);
    out += &format!(
        "  {:<10} {:>24} {:>14} {:>34} {:>24}\n",
        "unknown", "estimate", "std. error", "95 % interval (Student's t)", context.expected_label
    );
    for (i, name) in e.names.iter().enumerate() {
        let on_bound = e.certificate.active[i].is_some();
        let se = match &e.std_errors {
            _ if on_bound => "on bound".to_string(),
            Some(s) => significant(s[i], 5),
            None => "—".to_string(),
        };
        let interval = match &e.intervals {
            _ if on_bound => "—".to_string(),
            Some(list) => {
                format!("[{}, {}]", significant(list[i][0], 6), significant(list[i][1], 6))
            }
            None => "—".to_string(),
        };
        let expected = context.expected(name).map_or(String::new(), |v| format!("{v}"));
        let bound = match e.certificate.active[i] {
            Some(Bound::Lower) => "   on its lower bound",
            Some(Bound::Upper) => "   on its upper bound",
            None => "",
        };
        out += &format!(
            "  {name:<10} {:>24} {se:>14} {interval:>34} {expected:>24}{bound}\n",
            significant(e.values[i], 10)
        );
    }
    out += "\n";
    out += &format!("  converged    {}\n", e.verdict());
    out += &format!("  termination  {}\n", e.termination);
    if let Some(at) = e.failed_at() {
        out += &format!("  failed at    {at}\n");
    }
    if let Some(space) = &e.certificate.null_space {
        out += &format!(
            "  identifiability  the data cannot identify {} here (condition {:.1e}): the combination {} is not seen by the data\n",
            space.unknowns.join(", "),
            space.condition,
            space.combination(problem)
        );
    }
    let reported = if e.best_iteration == e.iterations {
        String::new()
    } else {
        format!(" (the best, iterate {}, is reported)", e.best_iteration)
    };
    out += &format!("  iterations   {}{reported}\n", e.iterations);
    let reference_cost = context
        .reference_cost
        .map_or(String::new(), |(cost, source)| format!("   (reference {cost}, {source})"));
    out += &format!("  cost ε       {}{reference_cost}\n", significant(e.cost, 10));
    let dof = e.dof.map_or("—".to_string(), |d| d.to_string());
    out += &format!("  dof          {dof} (measured values − unknowns not held on a bound)\n");
    out += &format!(
        "  work         {} integrations, {} steps ({} rejected), {} right-hand-side evaluations, {:.3} ms\n\n",
        e.counts.integrations,
        e.counts.steps,
        e.counts.rejected_steps,
        e.counts.rhs_evaluations,
        e.elapsed.as_secs_f64() * 1e3
    );
    // Multiple shooting's matching defect, where the method has one.
    let shooting = e.history.iter().any(|h| h.defect.is_some());
    out += &format!(
        "  {:>9} {:>24} {:>12} {:>12} {:>12} {:>12}{}\n",
        "iteration",
        "cost ε",
        "|U|",
        "step",
        "condition",
        "optimality",
        if shooting { format!(" {:>12}", "defect") } else { String::new() }
    );
    let dash = |v: Option<f64>| {
        v.filter(|v| v.is_finite()).map_or("—".to_string(), |v| format!("{v:.3e}"))
    };
    for h in &e.history {
        out += &format!(
            "  {:>9} {:>24} {:>12} {:>12} {:>12} {:>12}{}\n",
            h.iteration,
            significant(h.cost, 10),
            dash(Some(h.gradient_norm)),
            dash(h.step_norm),
            dash(h.condition),
            dash(h.optimality),
            if shooting { format!(" {:>12}", dash(h.defect)) } else { String::new() }
        );
    }
    out
}
