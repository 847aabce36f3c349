//! The set-up of a fit: the problem from a catalogue system or a model file, the command
//! line's integrator and `--fix`ed unknowns applied, the method from the registry, and one
//! fit or a multistart, with a start that cannot be used refused as bad input.

use anyhow::Context as _;
use sysid_core::{Estimate, Expected, Failure, FitRecord, Method, Problem, Termination};
use sysid_montecarlo::MultistartOptions;
use sysid_montecarlo::multistart::Starts;
use sysid_ode::{OdeError, System};
use sysid_registry::{Boxed, Registry, Settings};
use sysid_systems::{Case, Visit};

use crate::options::{IntegratorArgs, MethodArgs, SourceArgs, StartsArgs};

/// What a report says about the problem besides the fit.
#[derive(Clone, Debug, Default)]
pub struct Context {
    /// The system's or model's name.
    pub name: String,
    /// One line describing it.
    pub summary: String,
    /// The reference answer or the truth, if known.
    pub expected: Option<Expected>,
}

/// Something to do with a problem of any system type.
pub trait WithProblem {
    /// What it produces.
    type Output;
    /// Does it.
    fn run<S: System + Clone + Send + Sync + 'static>(
        self,
        problem: Problem<S>,
        context: Context,
    ) -> anyhow::Result<Self::Output>;
}

struct Catalogue<W> {
    seed: u64,
    with: W,
}

impl<W: WithProblem> Visit for Catalogue<W> {
    type Output = anyhow::Result<W::Output>;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        let problem = case.problem(self.seed).with_context(|| format!("system {}", case.name))?;
        let context = Context {
            name: case.name.into(),
            summary: case.summary.into(),
            expected: case.expectation(),
        };
        self.with.run(problem, context)
    }
}

/// The error of a command given neither a system nor a model file.
pub fn no_source() -> anyhow::Error {
    anyhow::anyhow!(
        "no problem given: name a catalogue system with --system NAME (`sysid systems` lists \
         them; e.g. --system falling-body) or a model file with --model FILE (e.g. --model \
         examples/kinetics/model.toml) or a PEtab problem with --petab FILE.yaml"
    )
}

/// The catalogue system `name` handed to `visit`, or an error naming the systems there are.
pub fn visit_system<V: Visit>(name: &str, visit: V) -> anyhow::Result<V::Output> {
    sysid_systems::visit(name, visit).ok_or_else(|| {
        anyhow::anyhow!("unknown system `{name}` (systems: {})", sysid_systems::NAMES.join(", "))
    })
}

/// Builds the problem of `source` and hands it to `with`.
pub fn with_problem<W: WithProblem>(source: &SourceArgs, with: W) -> anyhow::Result<W::Output> {
    match (&source.system, source.file()) {
        (Some(name), _) => visit_system(name, Catalogue { seed: source.seed, with })?,
        (None, Some(path)) => {
            let model = source.load(path)?;
            let problem = model.problem(source.data.as_deref())?;
            let context = Context {
                name: path.display().to_string(),
                summary: source.kind().into(),
                ..Context::default()
            };
            with.run(problem, context)
        }
        (None, None) => Err(no_source()),
    }
}

/// The problem with the command line's integrator settings and `--fix`ed unknowns.
pub fn prepare<S: System>(
    problem: Problem<S>,
    integrator: &IntegratorArgs,
    options: &MethodArgs,
) -> anyhow::Result<Problem<S>> {
    let problem = match integrator.given() {
        true => {
            let settings = integrator.apply_to(*problem.integrator())?;
            problem.with_integrator(settings)?
        }
        false => problem,
    };
    Ok(problem.with_fixed(&options.fix)?)
}

/// The registry's method called `name` (usable from several threads, as studies run them).
pub fn method<S: System>(name: &str, settings: &Settings) -> anyhow::Result<Boxed<S>> {
    Ok(Registry::standard().build(name, settings)?)
}

/// Fits with the named method. A start that cannot be used is bad input, not a result of the
/// method: a model that cannot be evaluated there, or unknowns the data cannot tell apart
/// there before any step was taken.
pub fn fit<S: System>(
    problem: &Problem<S>,
    name: &str,
    settings: &Settings,
) -> anyhow::Result<Estimate> {
    let m = method::<S>(name, settings)?;
    let estimate = m.fit(problem)?;
    if let Some(message) = unusable_start(problem, &estimate, m.start_point()) {
        anyhow::bail!(message);
    }
    Ok(estimate)
}

/// Fits with the named method from the problem's guess, or from the starts of `--starts`
/// (the best fit, and what the starts found). The start is unusable only when every start is.
pub fn fit_from_starts<S: System + Sync>(
    problem: &Problem<S>,
    name: &str,
    settings: &Settings,
    starts: &StartsArgs,
) -> anyhow::Result<(Estimate, Option<Starts>)> {
    let Some(options) = starts.options()? else {
        return Ok((fit(problem, name, settings)?, None));
    };
    let (best, starts) = best_of_starts(problem, &*method::<S>(name, settings)?, &options)?;
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
    M: Method<S> + Sync + ?Sized,
{
    let run = sysid_montecarlo::multistart(m, problem, options)?;
    if let Some(message) = unusable_start(problem, &run.best, m.start_point()) {
        anyhow::bail!("every start fails; the best: {message}");
    }
    Ok((run.best, run.starts))
}

/// A fit's JSON object with the `starts` object of a multistart run.
pub fn with_starts(record: FitRecord<'_>, starts: Option<&Starts>) -> serde_json::Value {
    let mut value = serde_json::to_value(record).expect("a fit record serialises");
    if let (Some(s), Some(map)) = (starts, value.as_object_mut()) {
        map.insert("starts".into(), serde_json::to_value(s).expect("starts serialise"));
    }
    value
}

/// Why the start cannot be used, if it cannot; `start_point` is what the method integrates
/// from there ([`Method::start_point`]).
fn unusable_start<S: System>(
    problem: &Problem<S>,
    e: &Estimate,
    start_point: &str,
) -> Option<String> {
    match &e.termination {
        Termination::StartFailed(Failure::Integration { error, at }) => {
            let mut message = format!("the model cannot be integrated from {start_point}: {error}");
            // Steps that shrink to nothing with the sensitivities, where the model alone
            // integrates at the same tolerances: say so, and what usually causes it.
            if matches!(error, OdeError::StepSizeTooSmall { .. })
                && problem.residuals(&problem.unknowns().coordinates(at)).is_ok()
            {
                message.push_str(
                    " (the model alone integrates there, its sensitivities do not: this happens where the right-hand side switches on a state, with min, max, abs or a comparison of states, since the integrators do not locate such switches and the sensitivities change abruptly there)",
                );
            }
            Some(message)
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
                space.combination()
            ))
        }
        _ => None,
    }
}
