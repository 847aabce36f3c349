//! One trial: a noise realisation and a start drawn from the trial's own random stream, a
//! reference fit from the truth, and every method from the start, on the same data.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sysid_core::{DriverOptions, Estimate, Failure, Method, Rule, Termination, Unknown};
use sysid_ode::System;

use crate::error::StudyError;
use crate::multistart::guarded;
use crate::scenario::Scenario;

/// A method a study runs on many threads at once.
pub type SharedMethod<S> = Box<dyn Method<S> + Send + Sync>;

/// The name of the reference fit's lines in the results.
pub const REFERENCE: &str = "reference";

/// A method succeeds on a trial when it reports convergence and its cost is within
/// `SUCCESS_RTOL`·ε_ref + `SUCCESS_ATOL` of the reference fit's cost ε_ref.
pub const SUCCESS_RTOL: f64 = 1e-6;
/// See [`SUCCESS_RTOL`].
pub const SUCCESS_ATOL: f64 = 1e-12;

/// Everything a study's results depend on. Written to `study.json`; a resumed study and the
/// shards of a merge must have the same.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StudySpec {
    /// The catalogue system or model file.
    pub system: String,
    /// The methods, in the order the results list them.
    pub methods: Vec<String>,
    /// The method of the reference fit from the truth.
    pub reference: String,
    /// Number of trials.
    pub trials: usize,
    /// Noise level as a multiple of the system's σ.
    pub noise: f64,
    /// ρ: each unknown starts at truth·(1 + ρu), u uniform on [−1, 1] (truth·(1 + ρ)^u for
    /// log-scale unknowns, truth + ρu for a truth of 0), clamped to its bounds.
    pub perturb: f64,
    /// Seed of the random streams: trial i draws from ChaCha8(seed) stream i.
    pub seed: u64,
    /// Unknowns held at a value in every fit (`--fix`), not estimated.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fixed: Vec<(String, f64)>,
    /// The iteration driver's budgets and tolerances of every fit (the certificate's gtol
    /// decides what converged means).
    #[serde(default)]
    pub driver: DriverOptions,
    /// Whatever else decides the trials' results, by name: method options beyond the
    /// driver's (`ql_start`), the SHA-256 of a model file and of its data. `--resume` and
    /// `merge` refuse a study whose settings differ, naming the setting.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub settings: BTreeMap<String, String>,
}

/// The most trials one study runs (their records are held for the summary: some 10 GB of
/// memory at the limit with every method).
pub const MAX_TRIALS: usize = 1_000_000;

impl StudySpec {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), StudyError> {
        if self.methods.is_empty() {
            return Err(StudyError::Setup("no methods to study".into()));
        }
        if self.trials == 0 {
            return Err(StudyError::Setup("--trials must be at least 1".into()));
        }
        if self.trials > MAX_TRIALS {
            return Err(StudyError::Setup(format!(
                "--trials {} is above the limit of {MAX_TRIALS} per study (each trial's \
                 records are kept for the summary): run several studies with other --seed",
                self.trials
            )));
        }
        if self.noise.is_nan() || self.noise <= 0.0 {
            return Err(StudyError::Setup(format!(
                "--noise must be a positive multiple of σ, got {}: without noise every trial \
                 fits the truth's own data, whose Cramér–Rao bound is zero",
                self.noise
            )));
        }
        if !(1e-150..=1e150).contains(&self.noise) {
            return Err(StudyError::Setup(format!(
                "--noise must lie between 1e-150 and 1e150 (a multiple of σ), got {:e}: beyond them the weights 1/(noise·σ)² overflow or vanish",
                self.noise
            )));
        }
        // 1.7e308 drew infinite starts, which trials.jsonl wrote as null and its own
        // --resume and merge then refused.
        if !(0.0..=MAX_PERTURB).contains(&self.perturb) {
            return Err(StudyError::Setup(format!(
                "--perturb must lie between 0 and {MAX_PERTURB:e} (a start up to a million times the truth), got {}",
                self.perturb
            )));
        }
        if let Some(m) = self.methods.iter().find(|m| *m == REFERENCE) {
            return Err(StudyError::Setup(format!("`{m}` is reserved for the reference fit")));
        }
        Ok(())
    }
}

/// One line of `trials.jsonl`: one method (or the reference fit) on one trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialRecord {
    /// Trial index.
    pub trial: usize,
    /// Method name, or `reference`.
    pub method: String,
    /// The start (values of the unknowns): the truth for the reference fit.
    pub start: Vec<f64>,
    /// Whether the method reported convergence.
    pub converged: bool,
    /// Whether it reached the reference fit's minimum (none for the reference itself and
    /// when the reference fit failed).
    pub success: Option<bool>,
    /// `success`, `reference`, or why not: `other_minimum` (converged elsewhere),
    /// `diverged`, `max_iterations`, `singular`, `integration_failed` (at the start),
    /// `no_descent`, `stalled` (a stopping rule where the certificate fails),
    /// `integration_budget`, `solver_failed`, `panicked` (a defect in sysid), `no_reference`,
    /// `error`.
    pub outcome: String,
    /// The method's termination, as it reports it.
    pub termination: String,
    /// Final ε (none when the model could not be integrated there).
    pub cost: Option<f64>,
    /// Final values of the unknowns.
    pub values: Vec<f64>,
    /// The fit's own standard errors, where it has them (none for an unknown held on a
    /// bound).
    pub std_errors: Option<Vec<Option<f64>>>,
    /// The fit's own 95 % intervals (Student's t for N − k degrees of freedom), where it has
    /// them (none for an unknown held on a bound).
    #[serde(default)]
    pub intervals: Option<Vec<Option<[f64; 2]>>>,
    /// Updates of the unknowns.
    pub iterations: usize,
    /// Accepted integration steps.
    pub steps: u64,
    /// Right-hand-side evaluations.
    pub rhs_evaluations: u64,
    /// Wall-clock time of the fit (the only field that differs between identical runs).
    pub time_ms: f64,
}

/// A study: the scenario, the methods, and the settings.
pub struct Study<S> {
    spec: StudySpec,
    scenario: Scenario<S>,
    methods: Vec<SharedMethod<S>>,
    reference: SharedMethod<S>,
}

impl<S: System + Clone + Send + Sync> Study<S> {
    /// A study of `methods` (named as in `spec.methods`) against `reference` fits from the
    /// truth.
    pub fn new(
        spec: StudySpec,
        scenario: Scenario<S>,
        methods: Vec<SharedMethod<S>>,
        reference: SharedMethod<S>,
    ) -> Result<Self, StudyError> {
        spec.validate()?;
        if methods.len() != spec.methods.len() {
            return Err(StudyError::Setup(format!(
                "{} methods for {} names",
                methods.len(),
                spec.methods.len()
            )));
        }
        Ok(Self { spec, scenario, methods, reference })
    }

    /// The settings.
    pub fn spec(&self) -> &StudySpec {
        &self.spec
    }

    /// The scenario.
    pub fn scenario(&self) -> &Scenario<S> {
        &self.scenario
    }

    /// The random stream of trial `index`: it depends on the seed and the index only.
    pub fn rng(&self, index: usize) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::seed_from_u64(self.spec.seed);
        rng.set_stream(index as u64);
        rng
    }

    /// The start of trial `index` and its data: the start's draws come first in the stream,
    /// then the noise, sample after sample (experiment after experiment).
    pub fn draw(&self, index: usize) -> (Vec<f64>, Vec<sysid_core::Data>) {
        let mut rng = self.rng(index);
        let problem = self.scenario.problem();
        let start = problem
            .unknowns()
            .list()
            .iter()
            .zip(self.scenario.truth())
            .map(|(u, &truth)| perturb(u, truth, self.spec.perturb, rng.random_range(-1.0..=1.0)))
            .collect();
        let data = self.scenario.noisy_data(self.spec.noise, &mut rng);
        (start, data)
    }

    /// Runs trial `index`: the reference fit's line first, then one line per method.
    pub fn trial(&self, index: usize) -> Result<Vec<TrialRecord>, StudyError> {
        let (start, data) = self.draw(index);
        let problem = self.scenario.with_data(data)?;
        let truth = self.scenario.truth();
        let reference = guarded(&*self.reference, &problem, truth);
        let mut records = Vec::with_capacity(1 + self.methods.len());
        records.push(record(index, REFERENCE, truth, &reference, None));
        records.extend(self.fit_methods(&problem, index, &start, reference_cost(&reference)));
        Ok(records)
    }

    /// The cost of the reference fit from the truth on `problem`'s data, if it converged.
    pub fn reference_fit(&self, problem: &sysid_core::Problem<S>) -> Option<f64> {
        reference_cost(&guarded(&*self.reference, problem, self.scenario.truth()))
    }

    /// Every method from `start` on `problem`, judged against the reference cost.
    pub fn fit_methods(
        &self,
        problem: &sysid_core::Problem<S>,
        index: usize,
        start: &[f64],
        reference: Option<f64>,
    ) -> Vec<TrialRecord> {
        self.spec
            .methods
            .iter()
            .zip(&self.methods)
            .map(|(name, method)| {
                record(index, name, start, &guarded(&**method, problem, start), Some(reference))
            })
            .collect()
    }
}

fn reference_cost(fit: &Result<Estimate, sysid_core::FitError>) -> Option<f64> {
    match fit {
        Ok(e) if e.converged() && e.cost.is_finite() => Some(e.cost),
        _ => None,
    }
}

/// The largest start perturbation ρ a study takes.
pub const MAX_PERTURB: f64 = 1e6;

/// The start of one unknown: truth·(1 + ρu), truth·(1 + ρ)^u on a log scale, truth + ρu for a
/// truth of 0; inside the unknown's bounds, and finite (a truth near the largest float times
/// 1 + ρ is held at it).
pub fn perturb(unknown: &Unknown, truth: f64, rho: f64, u: f64) -> f64 {
    let v = if unknown.log {
        truth * (1.0 + rho).powf(u)
    } else if truth == 0.0 {
        rho * u
    } else {
        truth * (1.0 + rho * u)
    };
    v.clamp(unknown.min.unwrap_or(f64::NEG_INFINITY), unknown.max.unwrap_or(f64::INFINITY))
        .clamp(-f64::MAX, f64::MAX)
}

/// The record of one fit. `reference` is `None` for the reference fit itself, and
/// `Some(None)` when the reference fit failed.
fn record(
    trial: usize,
    method: &str,
    start: &[f64],
    fit: &Result<Estimate, sysid_core::FitError>,
    reference: Option<Option<f64>>,
) -> TrialRecord {
    let e = match fit {
        Ok(e) => e,
        Err(error) => {
            return TrialRecord {
                trial,
                method: method.into(),
                start: start.to_vec(),
                converged: false,
                success: reference.map(|_| false),
                outcome: "error".into(),
                termination: error.to_string(),
                cost: None,
                values: start.to_vec(),
                std_errors: None,
                intervals: None,
                iterations: 0,
                steps: 0,
                rhs_evaluations: 0,
                time_ms: 0.0,
            };
        }
    };
    let cost = e.cost.is_finite().then_some(e.cost);
    let (success, outcome) = match reference {
        None => (None, if e.converged() { "reference".to_string() } else { failure(e) }),
        Some(None) => (None, "no_reference".to_string()),
        Some(Some(best)) => {
            let within =
                cost.is_some_and(|c| (c - best).abs() <= SUCCESS_RTOL * best.abs() + SUCCESS_ATOL);
            match (e.converged(), within) {
                (true, true) => (Some(true), "success".to_string()),
                (true, false) => (Some(false), "other_minimum".to_string()),
                _ => (Some(false), failure(e)),
            }
        }
    };
    TrialRecord {
        trial,
        method: method.into(),
        start: start.to_vec(),
        converged: e.converged(),
        success,
        outcome,
        termination: e.termination.to_string(),
        cost,
        values: e.values.clone(),
        std_errors: e.std_errors.as_ref().map(|list| list.iter().map(|&v| finite(v)).collect()),
        intervals: e.intervals.as_ref().map(|list| {
            list.iter().map(|&[a, b]| (a.is_finite() && b.is_finite()).then_some([a, b])).collect()
        }),
        iterations: e.iterations,
        steps: e.counts.steps,
        rhs_evaluations: e.counts.rhs_evaluations,
        time_ms: e.elapsed.as_secs_f64() * 1e3,
    }
}

/// Why a run that did not converge failed. It diverged when its iterates left the region
/// where the model can be evaluated, or ran out of iterations with the cost above where it
/// started.
fn failure(e: &Estimate) -> String {
    let first = e.history.first().map(|h| h.cost);
    let last = e.history.last().map(|h| h.cost);
    match &e.termination {
        Termination::Converged(_) => "converged",
        Termination::Stalled { rule: Rule::NoDescent, .. } => "no_descent",
        Termination::Stalled { .. } => "stalled",
        Termination::StartFailed(_) => "integration_failed",
        Termination::Failed { failure, .. } => match failure {
            Failure::Integration { .. } | Failure::NonFinite { .. } => "diverged",
            Failure::Singular { .. } => "singular",
            Failure::Budget { .. } => "integration_budget",
            Failure::Solver(_) => "solver_failed",
        },
        Termination::IntegrationBudget { .. } => "integration_budget",
        Termination::TimeLimit { .. } => "time_limit",
        Termination::Interrupted => "interrupted",
        Termination::Panicked(_) => "panicked",
        Termination::MaxIterations { .. } => match (first, last) {
            (Some(a), Some(b)) if b > a || b.is_nan() => "diverged",
            _ => "max_iterations",
        },
    }
    .to_string()
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}
