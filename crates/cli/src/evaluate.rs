//! `sysid evaluate`: the negative log-likelihood at one point, its gradient, and how long
//! one evaluation takes.

use std::borrow::Cow;
use std::time::Instant;

use anyhow::{anyhow, bail};
use clap::{Args, ValueEnum};
use sysid_core::Sensitivities;

use crate::Outcome;
use crate::options::{Format, IntegratorArgs, SourceArgs, count, once_each, parse_fix};
use crate::output::emit;
use crate::problem::{AnyProblem, with_integrator};

/// Arguments of `sysid evaluate`.
#[derive(Args, Debug)]
pub struct EvaluateArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// Also the gradient of the NLL with respect to each parameter's value.
    #[arg(long)]
    gradient: bool,
    /// How the gradient is computed: forward sensitivities of every parameter integrated
    /// with the states, one backward adjoint integration per condition, or per condition
    /// whichever of the two did less work at its first gradient (auto: that first evaluation
    /// computes both, counts each one's arithmetic, and is not timed; the same choice on
    /// every run; docs/methods.md). Experiments with samples before t0, or a state event at t0 or at
    /// their last sample, are integrated forward whatever is asked.
    #[arg(long, value_enum, default_value_t = How::Auto, requires = "gradient")]
    sensitivities: How,
    /// Skip the untimed evaluation at a tenth of rtol and atol that measures the integration
    /// error of the NLL and of the gradient (`nll_error` and `gradient_error` are then null):
    /// for scripts that evaluate many points and need only the values.
    #[arg(long)]
    no_integration_error: bool,
    /// Evaluate N times (at most 1 000 000) and report the median time of one evaluation.
    #[arg(long, default_value_t = 1, value_name = "N", value_parser = count)]
    repeat: usize,
    /// Set a parameter (an unknown or a noise scale) to a value instead of its nominal
    /// value or guess, e.g. --set k1=0.8. Repeat for several. Without it a PEtab problem is
    /// evaluated at its table's nominal values, those outside their bounds included (where
    /// positive on a log scale), though fits start from the bounds.
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = parse_fix, allow_hyphen_values = true)]
    set: Vec<(String, f64)>,
    /// Output format: a readable table, or the JSON object of docs/json.md.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    #[command(flatten)]
    integrator: IntegratorArgs,
}

/// `--sensitivities`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum How {
    /// Forward sensitivities of every parameter, integrated with the states.
    Forward,
    /// One backward adjoint integration per condition.
    Adjoint,
    /// Per condition, whichever of the two did less work at its first gradient.
    Auto,
}

impl How {
    fn sensitivities(self) -> Sensitivities {
        match self {
            How::Forward => Sensitivities::Forward,
            How::Adjoint => Sensitivities::Adjoint,
            How::Auto => Sensitivities::Auto,
        }
    }

    fn name(self) -> &'static str {
        match self {
            How::Forward => "forward",
            How::Adjoint => "adjoint",
            How::Auto => "auto",
        }
    }
}

/// One evaluation: the NLL, the priors' term, and the NLL's gradient.
struct Evaluation {
    nll: f64,
    prior: Option<f64>,
    gradient: Option<Vec<f64>>,
    /// How the gradient was asked for; None without it.
    how: Option<How>,
    /// The number of experiments.
    experiments: usize,
    /// With the gradient: the experiments whose gradient came from the adjoint, by name.
    by_adjoint: Option<Vec<String>>,
    /// With `--sensitivities adjoint` or `auto`: the experiments whose gradient came from
    /// forward sensitivities because the adjoint does not handle them or failed, by name.
    fell_back: Option<Vec<String>>,
    /// The work of its integrations.
    counts: sysid_ode::Counts,
}

/// The most evaluations `--repeat` times (their times are kept for the median).
const MAX_REPEAT: usize = 1_000_000;

/// Runs `sysid evaluate`.
pub fn run(args: &EvaluateArgs) -> anyhow::Result<Outcome> {
    args.integrator.validate()?;
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    if args.repeat > MAX_REPEAT {
        bail!("--repeat {}: at most {MAX_REPEAT} evaluations are timed", args.repeat);
    }
    let started = Instant::now();
    let (problem, context) = args.source.problem()?;
    let problem = with_integrator(problem, &args.integrator)?;
    let import_ms = started.elapsed().as_secs_f64() * 1e3;
    let parameters = problem.parameters();
    let names: Vec<String> = parameters.iter().map(|u| u.name.clone()).collect();
    // The user's names once each; a published nominal value outside its bounds comes first.
    once_each(&args.set, "--set")?;
    let set: Vec<(String, f64)> = context.nominal.iter().chain(&args.set).cloned().collect();
    let values = point(&problem, &parameters, &set)?;
    let k = problem.unknowns().len();
    let held = match problem.scales().is_empty() {
        true => Cow::Borrowed(&problem),
        false => Cow::Owned(problem.with_scales(&values[k..])),
    };
    let z = problem.unknowns().coordinates(&values[..k]);
    let how = args.gradient.then_some(args.sensitivities);
    // `auto` measures both ways at its first gradient: that evaluation is not timed.
    if how == Some(How::Auto) {
        evaluate(&held, &z, &parameters, &values, Some(How::Auto)).map_err(|e| context.blame(e))?;
    }
    let mut times = Vec::with_capacity(args.repeat);
    let mut result = None;
    for _ in 0..args.repeat {
        // Each evaluation solves what it needs (a steady state) afresh, not from the last.
        held.forget_cached();
        let t = Instant::now();
        let e = evaluate(&held, &z, &parameters, &values, how).map_err(|e| context.blame(e))?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        result = Some(e);
    }
    let e = result.expect("at least one evaluation");
    let (error, unchecked) = match args.no_integration_error {
        true => (None, None),
        false => match integration_error(&held, &z, &parameters, &values, &e) {
            Ok(error) => (error, None),
            Err(why) => (None, Some(why)),
        },
    };
    times.sort_by(f64::total_cmp);
    let ms = times[times.len() / 2];
    let text = match args.format {
        Format::Json => {
            let object = |v: &[f64]| -> serde_json::Map<String, serde_json::Value> {
                names.iter().cloned().zip(v.iter().map(|&x| serde_json::json!(x))).collect()
            };
            let record = serde_json::json!({
                "problem": context.name,
                "nll": e.nll,
                "prior": e.prior,
                "objective": e.nll + e.prior.unwrap_or(0.0),
                "nll_error": error.as_ref().map(|x| x.nll),
                "unchecked": unchecked,
                "gradient": e.gradient.as_deref().map(object),
                "gradient_error": error.as_ref().and_then(|x| x.gradient.as_deref()).map(object),
                "sensitivities": e.how.map(How::name),
                "adjoint_experiments": e.by_adjoint,
                "adjoint_fallbacks": e.fell_back,
                "parameters": object(&values),
                "evaluations": args.repeat,
                "ms_per_evaluation": ms,
                "import_ms": import_ms,
                "counts": e.counts,
            });
            format!("{}\n", serde_json::to_string_pretty(&record)?)
        }
        Format::Table => {
            let timing = (ms, import_ms, args.repeat);
            let checked = (error.as_ref(), unchecked.as_deref());
            table(&context.name, &names, &values, (&e, checked), timing)
        }
    };
    emit(&text)?;
    Ok(Outcome::Success)
}

/// The values of `parameters` (the problem's: the free unknowns, then the noise scales):
/// the guesses and the scales' values, with `set` applied (a PEtab problem's nominal values
/// outside their bounds, then `--set`).
fn point(
    problem: &AnyProblem,
    parameters: &[&sysid_core::Unknown],
    set: &[(String, f64)],
) -> anyhow::Result<Vec<f64>> {
    let mut values: Vec<f64> =
        problem.unknowns().guesses().into_iter().chain(problem.scale_values()).collect();
    for (name, value) in set {
        let (name, value) = (name.as_str(), *value);
        let Some(i) = parameters.iter().position(|u| u.name == name) else {
            let names: Vec<&str> = parameters.iter().map(|u| u.name.as_str()).collect();
            bail!(
                "--set {name}: not a parameter of the problem (parameters: {})",
                names.join(", ")
            );
        };
        // A noise scale is σ (its NLL took ln(−1) = NaN and blamed a residual).
        let scale = i >= problem.unknowns().len();
        if scale && value <= 0.0 {
            bail!("--set {name}: a noise scale is a σ: it must be positive, got {value}");
        }
        // Finite: the values are read by parse_fix, the published ones are numbers.
        if parameters[i].log && value <= 0.0 {
            bail!("--set {name}: {value} is not a positive number (it is on a log scale)");
        }
        values[i] = value;
    }
    Ok(values)
}

/// The integration error of an evaluation: |x − x′| for the NLL and for each entry of its
/// gradient, x′ from the same evaluation at a tenth of rtol and atol, as the certificate
/// measures a fit's (docs/methods.md, the certificate).
struct IntegrationError {
    nll: f64,
    gradient: Option<Vec<f64>>,
}

/// [`IntegrationError`] of `e`, the evaluation at z; None where no finer integration can
/// tell it (a fixed step; rtol already at the finest, 1e-12), and the finer one's error
/// where it fails. The digits of a point where the model is near a blow-up are not the
/// tolerances' to give (Crauste's ∂NLL/∂delta_EL at nominal: 7.35 forward and 14.9 adjoint
/// at rtol 1e-8, 2.107 and 2.182 at 1e-10, 2.0591 both at 1e-13), and this says so; where
/// the finer integration fails, the working one may have stepped over a singularity
/// (docs/methods.md, the certificate), and that is said too.
fn integration_error(
    problem: &AnyProblem,
    z: &[f64],
    parameters: &[&sysid_core::Unknown],
    values: &[f64],
    e: &Evaluation,
) -> Result<Option<IntegrationError>, String> {
    let Some(finer) = sysid_core::method::finer(problem.integrator()) else { return Ok(None) };
    let Ok(problem) = problem.clone().with_integrator(finer) else { return Ok(None) };
    let f = evaluate(&problem, z, parameters, values, e.how).map_err(|e| e.to_string())?;
    let gradient = e
        .gradient
        .as_ref()
        .zip(f.gradient.as_ref())
        .map(|(g, h)| g.iter().zip(h).map(|(a, b)| (a - b).abs()).collect());
    Ok(Some(IntegrationError { nll: (e.nll - f.nll).abs(), gradient }))
}

/// The NLL at z (and the priors' term), with its gradient with respect to the values when
/// `gradient` says how to compute it.
fn evaluate(
    problem: &AnyProblem,
    z: &[f64],
    parameters: &[&sysid_core::Unknown],
    values: &[f64],
    gradient: Option<How>,
) -> anyhow::Result<Evaluation> {
    let no_likelihood =
        || anyhow!("the problem's data are a continuous record: it has no likelihood");
    // Not only an integration that fails: a residual or a derivative too large for a float.
    let cannot = |e: sysid_ode::OdeError| anyhow!("the NLL cannot be evaluated at this point: {e}");
    let overflows = |nll: f64| {
        anyhow!(
            "the NLL cannot be evaluated at this point: it is {nll}, a residual too large for a float (a noise scale near 0, or values far from the data's)"
        )
    };
    let prior = problem.prior_nll_at(z);
    let Some(how) = gradient else {
        let (nll, counts) = problem.nll_and_counts(z).map_err(cannot)?.ok_or_else(no_likelihood)?;
        if !nll.is_finite() {
            return Err(overflows(nll));
        }
        return Ok(Evaluation {
            nll,
            prior,
            gradient: None,
            how: None,
            experiments: problem.experiments().len(),
            by_adjoint: None,
            fell_back: None,
            counts,
        });
    };
    let e =
        problem.nll_gradient(z, how.sensitivities()).map_err(cannot)?.ok_or_else(no_likelihood)?;
    if !e.nll.is_finite() {
        return Err(overflows(e.nll));
    }
    // ∂/∂value = ∂/∂z / (∂value/∂z).
    let g = e
        .gradient
        .into_iter()
        .zip(parameters.iter().zip(values))
        .map(|(g, (u, &v))| g / u.scale(u.coordinate(v)))
        .collect();
    let experiments = problem.experiments();
    let named = |list: &[usize]| -> Vec<String> {
        list.iter().map(|&i| experiments[i].name().to_string()).collect()
    };
    let fell_back = (how != How::Forward).then(|| named(&e.fell_back));
    Ok(Evaluation {
        nll: e.nll,
        prior,
        gradient: Some(g),
        how: Some(how),
        experiments: experiments.len(),
        by_adjoint: Some(named(&e.by_adjoint)),
        fell_back,
        counts: e.counts,
    })
}

/// An NLL for the table: ten decimals, as references are compared, but no more digits than
/// an f64 holds (17 significant: Alkan's 281515999.42949665 had 19), and in exponent form
/// outside [1e-4, 1e9) as every number the guide shows (an NLL of 1.2e302 was 303 digits).
fn ten_decimals(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() || a == 0.0 {
        return format!("{v:.10}");
    }
    if !(1e-4..1e9).contains(&a) {
        return sysid_core::format::shortest(v);
    }
    let before = a.log10().floor() as i64 + 1;
    let decimals = (17 - before).clamp(0, 10) as usize;
    format!("{v:.decimals$}")
}

/// The readable report.
fn table(
    name: &str,
    names: &[String],
    values: &[f64],
    (e, (error, unchecked)): (&Evaluation, (Option<&IntegrationError>, Option<&str>)),
    (ms, import_ms, repeat): (f64, f64, usize),
) -> String {
    let mut out = format!("{name}\n  NLL          {}", ten_decimals(e.nll));
    out += &match error {
        Some(x) => format!(" ± {:.1e} (integration)\n", x.nll),
        None => "\n".to_string(),
    };
    if let Some(why) = unchecked {
        out += &format!(
            "  unchecked    at a tenth of the tolerances {why}: these digits are confirmed by nothing (the integration may have stepped over a singularity)\n"
        );
    }
    if let Some(p) = e.prior {
        out += &format!(
            "  prior        {}\n  objective    {}\n",
            ten_decimals(p),
            ten_decimals(e.nll + p)
        );
    }
    out += &format!(
        "  time         {ms:.3} ms per evaluation (median of {repeat}){}; import {import_ms:.1} ms\n",
        if e.gradient.is_some() { " with the gradient" } else { "" }
    );
    let list = |names: &[String]| {
        let shown: Vec<&str> = names.iter().take(5).map(String::as_str).collect();
        let more = names.len().saturating_sub(shown.len());
        format!(
            "{}{}",
            shown.join(", "),
            if more > 0 { format!(" and {more} more") } else { String::new() }
        )
    };
    let c = &e.counts;
    out += &format!(
        "  work         {} steps ({} rejected), {} right-hand sides, {} factorisations, {} integration(s)\n",
        c.steps, c.rejected_steps, c.rhs_evaluations, c.jacobians, c.integrations
    );
    if let (Some(how), Some(by)) = (e.how, &e.by_adjoint) {
        out += &format!(
            "  gradient     {} ({} of {} experiment(s) by adjoint){}\n",
            how.name(),
            by.len(),
            e.experiments,
            if by.is_empty() { String::new() } else { format!(": {}", list(by)) }
        );
    }
    if let Some(names) = e.fell_back.as_ref().filter(|n| !n.is_empty()) {
        out += &format!(
            "  adjoint      {} experiment(s) by forward sensitivities instead: {}\n",
            names.len(),
            list(names)
        );
    }
    let width = sysid_core::format::column_width(names.iter().map(String::as_str), 9);
    out += &format!("\n  {:<width$}  {:>16}", "parameter", "value");
    let gradient_error = error.and_then(|x| x.gradient.as_ref());
    if e.gradient.is_some() {
        out += &format!("  {:>16}", "∂NLL/∂value");
        if gradient_error.is_some() {
            out += &format!("  {:>11}", "± (integr.)");
        }
    }
    out.push('\n');
    for (i, n) in names.iter().enumerate() {
        out += &format!("  {n:<width$}  {:>16.9e}", values[i]);
        if let Some(g) = &e.gradient {
            out += &format!("  {:>16.9e}", g[i]);
        }
        if let Some(err) = gradient_error {
            out += &format!("  {:>11.1e}", err[i]);
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::ten_decimals;

    #[test]
    fn an_nll_has_ten_decimals_within_what_a_float_holds() {
        assert_eq!(ten_decimals(138.22199767), "138.2219976700");
        assert_eq!(ten_decimals(-58622.91412236), "-58622.9141223600");
        assert_eq!(ten_decimals(281515999.42949665), "281515999.42949665");
        assert_eq!(ten_decimals(1.1870620432654152e302), "1.1870620432654152e302");
        assert_eq!(ten_decimals(2.5e-7), "2.5e-7");
        assert_eq!(ten_decimals(0.0), "0.0000000000");
        assert_eq!(ten_decimals(f64::INFINITY), "inf");
    }
}
