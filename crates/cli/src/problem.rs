//! The set-up of a fit: the problem from a catalogue system, a model file or a PEtab
//! problem, the command line's integrator and `--fix`ed unknowns applied, the method from the
//! registry, and one fit or a multistart, with a start that cannot be used refused as bad
//! input.

use std::rc::Rc;
use std::sync::Mutex;

use anyhow::Context as _;
use sysid_core::format::significant;
use sysid_core::observer::{self, IterateReport, TrialReport};
use sysid_core::{
    Estimate, Failure, FitRecord, Method, Problem, ProblemError, Termination, format::Expected,
};
use sysid_montecarlo::multistart::Starts;
use sysid_montecarlo::{MultistartOptions, StartDone};
use sysid_ode::OdeError;
use sysid_registry::{Boxed, Registry, Settings};
use sysid_systems::Case;

use crate::options::{IntegratorArgs, MethodArgs, SourceArgs, StartsArgs};
use crate::output::Watch;
use sysid_registry::any::{self, AnySystem};

/// What the commands work on: a problem of any system the command line fits.
pub type AnyProblem = Problem<AnySystem>;

/// What a report says about the problem besides the fit.
#[derive(Clone, Debug, Default)]
pub struct Context {
    /// The system's or model's name.
    pub name: String,
    /// One line describing it.
    pub summary: String,
    /// The reference answer or the truth, if known.
    pub expected: Option<Expected>,
    /// The files the problem was read from (none for a catalogue system): no command writes
    /// over them.
    pub inputs: Vec<std::path::PathBuf>,
    /// Nominal values the problem was published with outside their bounds, by name: the fits
    /// start from the bounds, `sysid evaluate` takes the NLL here.
    pub nominal: Vec<(String, f64)>,
}

/// The error of a command given neither a system nor a model file.
pub fn no_source() -> anyhow::Error {
    anyhow::anyhow!(
        "no problem given: name a catalogue system with --system NAME (`sysid systems` lists \
         them; e.g. --system falling-body) or a model file with --model FILE (e.g. --model \
         examples/kinetics/model.toml) or a PEtab problem with --petab FILE.yaml"
    )
}

/// The catalogue case `name`, or an error naming the systems there are.
pub fn case(name: &str) -> anyhow::Result<Case<AnySystem>> {
    any::case(name).ok_or_else(|| {
        anyhow::anyhow!("unknown system `{name}` (systems: {})", sysid_systems::NAMES.join(", "))
    })
}

impl SourceArgs {
    /// The problem of `--system` (with `--seed`), `--model` (with `--data`) or `--petab`, as
    /// its source defines it.
    pub fn problem(&self) -> anyhow::Result<(AnyProblem, Context)> {
        match (&self.system, self.file()) {
            (Some(name), _) => {
                let case = case(name)?;
                let problem =
                    case.problem(self.seed).with_context(|| format!("system {}", case.name))?;
                let context = Context {
                    name: case.name.into(),
                    summary: case.summary.into(),
                    expected: case.expectation(),
                    inputs: Vec::new(),
                    nominal: Vec::new(),
                };
                Ok((problem, context))
            }
            (None, Some(path)) => {
                let (model, nominal) = self.load_with_nominal(path)?;
                let problem = any::model_problem(model.problem(self.data.as_deref())?);
                let context = Context {
                    name: path.display().to_string(),
                    summary: self.kind().into(),
                    expected: None,
                    inputs: model.inputs().into_iter().chain(self.data.clone()).collect(),
                    nominal,
                };
                Ok((problem, context))
            }
            (None, None) => Err(no_source()),
        }
    }
}

/// The problem of `source` with the command line's integrator settings, `--fix`ed unknowns
/// and `--start` values.
pub fn problem(
    source: &SourceArgs,
    integrator: &IntegratorArgs,
    options: &MethodArgs,
) -> anyhow::Result<(AnyProblem, Context)> {
    let (problem, context) = source.problem()?;
    Ok((prepare(problem, integrator, options)?, context))
}

/// `problem` with the command line's integrator settings, `--fix`ed unknowns and `--start`
/// values.
pub fn prepare(
    problem: AnyProblem,
    integrator: &IntegratorArgs,
    options: &MethodArgs,
) -> anyhow::Result<AnyProblem> {
    let problem =
        with_integrator(problem, integrator)?.with_fixed(&options.fix).map_err(|e| match e {
            ProblemError::AllFixed(_)
            | ProblemError::NotAnUnknown { .. }
            | ProblemError::InvalidUnknown { .. } => {
                anyhow::anyhow!("--fix: {e}")
            }
            e => e.into(),
        })?;
    problem.with_start(&options.start).map_err(|e| anyhow::anyhow!("--start: {e}"))
}

/// `problem` with the command line's integrator settings, where any are given.
pub fn with_integrator(
    problem: AnyProblem,
    integrator: &IntegratorArgs,
) -> anyhow::Result<AnyProblem> {
    match integrator.given() {
        true => {
            let settings = integrator.apply_to(*problem.integrator())?;
            Ok(problem.with_integrator(settings)?)
        }
        false => Ok(problem),
    }
}

/// The registry's method called `name` (usable from several threads, as studies run them).
pub fn method(name: &str, settings: &Settings) -> anyhow::Result<Boxed<AnySystem>> {
    Ok(Registry::standard().build(name, settings)?)
}

/// The methods as they run under `settings`, by the names they report: `quasilinearization`
/// with `--ql-start data` is `quasilinearization-data` (compare's table said the one where its
/// JSON said the other, and the list could then hold one method twice).
pub fn as_run(names: &[String], settings: &Settings) -> anyhow::Result<Vec<String>> {
    let mut out: Vec<String> = Vec::with_capacity(names.len());
    for name in names {
        let actual = method(name, settings)?.name().to_string();
        if let Some(j) = out.iter().position(|m| *m == actual) {
            anyhow::bail!("--methods: `{}` and `{name}` are one method here, `{actual}`", names[j]);
        }
        out.push(actual);
    }
    Ok(out)
}

/// Fits with the named method. A start that cannot be used is bad input, not a result of the
/// method: a model that cannot be evaluated there, or unknowns the data cannot tell apart
/// there before any step was taken.
pub fn fit(problem: &AnyProblem, name: &str, settings: &Settings) -> anyhow::Result<Estimate> {
    let m = method(name, settings)?;
    let estimate = m.fit(problem)?;
    if let Some(message) = unusable_start(problem, &estimate, m.start_point()) {
        anyhow::bail!(message);
    }
    Ok(estimate)
}

/// Fits with the named method from the problem's guess, or from the starts of `--starts`
/// (the best fit, and what the starts found), telling `watch` how it goes: one fit with the
/// settings of `options`, each start with a start's ([`MethodArgs::settings_for`]).
/// The start is unusable only when every start is.
pub fn fit_from_starts(
    problem: &AnyProblem,
    name: &str,
    options: &MethodArgs,
    starts: &StartsArgs,
    watch: &Rc<Watch>,
) -> anyhow::Result<(Estimate, Option<Starts>)> {
    let drawn = starts.options()?;
    let settings = options.settings_for(drawn.as_ref());
    let Some(drawn) = drawn else {
        return Ok((watching(watch, || fit(problem, name, &settings))?, None));
    };
    let m = method(name, &settings)?;
    let (best, starts) = best_of_starts(problem, &*m, &drawn, watch)?;
    Ok((best, Some(starts)))
}

impl Context {
    /// `e` with the problem's file (or catalogue system) before its message, where the
    /// message does not begin with it: the errors found at run time (a model that cannot be
    /// integrated from the start, an NLL that cannot be evaluated) otherwise name no file.
    pub fn blame(&self, e: anyhow::Error) -> anyhow::Error {
        blame(&self.name, e)
    }

    /// The progress lines of a fit of this problem with `method`, every `every` seconds in a
    /// log ([`Watch`]), labelled by the problem's file name (or the system's) and the method.
    pub fn watch(&self, method: &str, every: f64) -> Rc<Watch> {
        let name = std::path::Path::new(&self.name)
            .file_stem()
            .map_or(self.name.clone(), |n| n.to_string_lossy().into_owned());
        Rc::new(Watch::new(format!("{name} {method}"), every))
    }
}

/// `f`, with the iterates of the fit it runs on this thread told to `watch`.
pub fn watching<R>(watch: &Rc<Watch>, f: impl FnOnce() -> R) -> R {
    let w = Rc::clone(watch);
    let said = move |p: &IterateReport<'_>| {
        w.say(&iterate_line(p));
        if let Some(trace) = w.trace() {
            trace.iterate(p);
        }
    };
    let out = match watch.trace() {
        Some(_) => {
            let w = Rc::clone(watch);
            let trial = move |t: &TrialReport<'_>| {
                if let Some(trace) = w.trace() {
                    trace.trial(t);
                }
            };
            observer::observe(said, || observer::observe_trials(trial, f))
        }
        None => observer::observe(said, f),
    };
    watch.finish();
    out
}

/// "iteration 17, objective -58.58392105, optimality 3.3e-7": an iterate for a progress
/// line (ten significant digits for the objective, two for the measure).
fn iterate_line(p: &IterateReport<'_>) -> String {
    let mut line = match p.objective {
        Some(v) => format!("iteration {}, objective {}", p.iteration, significant(v, 10)),
        None => format!("iteration {}, ε {}", p.iteration, significant(p.cost, 10)),
    };
    if let Some(m) = p.optimality {
        line += &format!(", optimality {}", significant(m, 2));
    }
    if p.coarse {
        line += " (coarse stage)";
    }
    line
}

/// `m` from the starts of `options`: the best fit and what the starts found, each start told
/// to `watch` as it ends. The start is unusable only when every start is.
pub fn best_of_starts<M>(
    problem: &AnyProblem,
    m: &M,
    options: &MultistartOptions,
    watch: &Watch,
) -> anyhow::Result<(Estimate, Starts)>
where
    M: Method<AnySystem> + Sync + ?Sized,
{
    // The starts done, the certified ones and the least objective so far, told under the
    // lock so that the lines come in order.
    let so_far = Mutex::new((0usize, 0usize, f64::INFINITY));
    let told = |s: StartDone| {
        let mut so_far = so_far.lock().unwrap_or_else(|e| e.into_inner());
        let (done, converged, best) = &mut *so_far;
        *done += 1;
        *converged += usize::from(s.converged);
        *best = s.objective.map_or(*best, |v| v.min(*best));
        let least = if best.is_finite() { significant(*best, 10) } else { "none".into() };
        watch.say(&format!(
            "{done}/{} starts done, {converged} certified, least objective {least}",
            s.total
        ));
    };
    let run = sysid_montecarlo::multistart_observed(m, problem, options, &told);
    watch.finish();
    let run = run?;
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

/// `e` with `source` (a file, or a catalogue system) before its message, where the message
/// does not begin with it ([`Context::blame`]).
pub fn blame(source: &str, e: anyhow::Error) -> anyhow::Error {
    match format!("{e:#}").starts_with(&format!("{source}: ")) {
        true => e,
        false => e.context(source.to_string()),
    }
}

/// The values of the unknowns at `at` ([`named_point`](sysid_core::format::named_point)).
fn point(problem: &AnyProblem, at: &[f64]) -> String {
    sysid_core::format::named_point(&problem.names(), at)
}

/// Why the start cannot be used, if it cannot; `start_point` is what the method integrates
/// from there ([`Method::start_point`]).
fn unusable_start(problem: &AnyProblem, e: &Estimate, start_point: &str) -> Option<String> {
    match &e.termination {
        Termination::StartFailed(Failure::Integration { error, at }) => {
            let mut message = format!(
                "the model cannot be integrated from {start_point} ({}): {error}",
                point(problem, at)
            );
            if let (OdeError::TooManySteps { .. }, Some(h)) =
                (error, problem.integrator().fixed_step)
            {
                message.push_str(&format!(
                    " (every step is the fixed step {h:e}: the span needs more than --max-steps {} of them)",
                    problem.integrator().max_steps
                ));
            }
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
        Termination::StartFailed(failure) => Some(match failure.at() {
            Some(at) => {
                format!("the starting guess cannot be used ({}): {failure}", point(problem, at))
            }
            None => format!("the starting guess cannot be used: {failure}"),
        }),
        Termination::Failed { failure: Failure::Singular { .. }, .. } if e.iterations == 0 => {
            let space = e.certificate.null_space.as_ref()?;
            Some(format!(
                "the data cannot identify {} at the starting guess (singular normal matrix, condition {:.1e}; the combination {} is not seen by the data): fix some of them or add data",
                space.unknowns.join(", "),
                space.condition,
                space.combination()
            ))
        }
        _ if e.iterations == 0 && e.certificate.plateau() && e.certificate.exact_fit => {
            Some(format!(
                "the data cannot identify {}: no measured value depends on {} (the data are matched whatever {}: measurements only where the model does not respond to the unknowns, such as known initial values at t0): add data, or fix them",
                e.names.join(", "),
                if e.names.len() == 1 { "it" } else { "them" },
                if e.names.len() == 1 { "its value is" } else { "their values are" }
            ))
        }
        _ if e.iterations == 0 && e.certificate.plateau() => Some(format!(
            "the starting guess cannot be used ({}): no measured value responds to any unknown there (a plateau, where no method can find a direction): move the guess",
            point(problem, &e.values)
        )),
        _ => None,
    }
}
