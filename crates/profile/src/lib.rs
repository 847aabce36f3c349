//! Profile likelihoods (Raue et al., Bioinformatics 25, 2009): for each unknown θ_i,
//! PL(θ_i) = min over the other unknowns of the negative log-likelihood, traced from the
//! optimum in both directions, each point re-optimised by the chosen method and warm-started
//! from its neighbour; unknowns in parallel (rayon).
//!
//! **Steps** are taken in the unknown's coordinate (ln θ on a log scale) and adapt to the
//! profile: each aims at a rise of the NLL of a tenth of the threshold ([`ProfileOptions`]),
//! a step that rises by more than twice that is retried at half the length, and no step is
//! longer than [`MAX_STEP`] times the coordinate's scale. A side ends past the threshold, at
//! the unknown's bound, or after `max_steps` points.
//!
//! **The crossing** of the threshold is then located between the last point below and the
//! first above by regula falsi with bisection as a safeguard (Illinois), until the bracket is
//! within `locate` of the distance from the optimum (1e-6 by default): never linear
//! interpolation between far points.
//!
//! **A point below the optimum** (by more than 1e-6 relative) means the fit was not at the
//! optimum: the profile stops and reports it ([`Outcome::BetterOptimum`]), for the caller
//! to fit again from there.
//!
//! **Verdicts**: `identifiable` when both sides cross; `structurally_non_identifiable` when
//! the profile rises by less than 1e-3 of the threshold over the whole range walked, each
//! side to the unknown's bound or with its steps at their longest, from an optimum whose
//! certificate holds but for undetermined unknowns (from one whose first-order test fails,
//! or a plateau, such a profile is `practically_non_identifiable`);
//! `practically_non_identifiable` when a side stays below the threshold up to the unknown's
//! bound (a side from an optimum on the bound is there at once, and walks no point), or until
//! the point budget ran out with its steps at their longest ([`MAX_STEP`]: the profile too
//! flat for them to reach a rise of a tenth of the threshold), whatever the other side did;
//! `undecided` when a side's budget ran out before either (its steps still shorter: the
//! profile was rising, and more points may cross) and the other side did not stay below the
//! threshold either, which a larger budget decides. The budget counts points walked: a step retried at
//! half its length is the same point.
//!
//! **A stopped run** ([`stop_when`](sysid_core::observer::stop_when); Ctrl-C in the command
//! line and in Python) fits no further point: each profile keeps the points fitted before
//! the stop, and those not finished are labelled `stopped` (no verdict; an interval bound
//! that was not reached is None, as on a side that did not cross).
//!
//! **A fit that panics** (a defect in sysid) ends its side there: the profile keeps the points
//! walked before it, its other side is still traced, its verdict is `failed` with the panic's
//! message ([`Profile::failed`]), and the other unknowns' profiles stand.
//!
//! The NLL is the fit's `nll` (the likelihood of its noise model; for data with known
//! weights, ε/2 plus a constant, so that ΔNLL = Δε/2).

use rayon::prelude::*;
use serde::Serialize;
use sysid_core::{Estimate, FitError, FitRecord, Method, Problem, ProblemError};
use sysid_ode::System;

/// Why profiling could not run.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// A fit along the profile could not run.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// An unknown could not be held at a value (the problem says why).
    #[error(transparent)]
    Problem(#[from] ProblemError),
    /// The profiles kept finding points below the optimum: the fits along them do not reach
    /// the minimum.
    #[error(
        "the profiles found a better optimum {MAX_RESTARTS} times over: the fits along them do not reach the minimum (the last fit from such a point: {verdict}; {termination}). Raise the iteration budget, or try another method"
    )]
    NoOptimum {
        /// The last fit's verdict.
        verdict: String,
        /// How it ended.
        termination: String,
    },
    /// A fit panicked (a defect in sysid) where no profile could keep the others' results:
    /// the fit again from a better point.
    #[error("a fit panicked, a defect in sysid (please report it with the command): {0}")]
    Panicked(String),
    /// What the profiles were asked for cannot be traced: an option out of its range, an
    /// unknown the problem does not have, an optimum of another problem.
    #[error("{0}")]
    Invalid(String),
    /// The caller asked the profiles to stop
    /// ([`stop_when`](sysid_core::observer::stop_when)) in a round whose profiles found a
    /// better point than the optimum: that round's profiles are not kept, and the fit from
    /// the point is not made. (Elsewhere the profiles stop with the points they have,
    /// labelled [`Label::Stopped`]; stopped during the fit from a better point, they are
    /// traced around that fit's best point, its termination `interrupted`.)
    #[error(
        "interrupted: the run was asked to stop after a profile found a better point than the optimum"
    )]
    Interrupted,
}

/// How many times [`profile_from_optimum`] fits again from a better point a profile found.
pub const MAX_RESTARTS: usize = 5;

/// What [`profile_from_optimum`] found.
#[derive(Clone, Debug)]
pub struct Profiled {
    /// Whether the fit given converged (its certificate held).
    pub certified: bool,
    /// The optimum the profiles are around: the fit given, or the last fit from a better
    /// point.
    pub optimum: Estimate,
    /// The better points the profiles found, each followed by a fit from there.
    pub better: Vec<Point>,
    /// The profiles.
    pub profiles: Vec<Profile>,
}

/// What [`profile_from_optimum`] tells while it runs.
#[derive(Clone, Copy, Debug)]
pub enum Progress<'a> {
    /// A profile is traced (from the thread that traced it): the unknown's index, and how
    /// many of this round's profiles are done, of how many.
    Traced {
        /// The unknown's index.
        unknown: usize,
        /// The profiles of this round done, this one included.
        done: usize,
        /// The profiles of the round.
        total: usize,
    },
    /// A point of a profile is fitted (from the thread that traces it): the unknown's
    /// index, the point, and its rise above the optimum's objective (ΔNLL), which the
    /// profile's side walks up to the threshold. A profile takes tens of fits; a long one
    /// is seen moving by these.
    Point {
        /// The unknown's index.
        unknown: usize,
        /// The point fitted.
        point: &'a Point,
        /// Its objective less the optimum's.
        rise: f64,
    },
    /// A profile found a point below the optimum, with the NLL it improves on; a fit from
    /// there follows, and the profiles are traced again from its end.
    Better {
        /// The point.
        point: &'a Point,
        /// The optimum's NLL.
        was: f64,
    },
}

/// [`profile`], fitting again with `method` from any point a profile finds below the
/// optimum (at most [`MAX_RESTARTS`] times), until the profiles start from the lowest point
/// they see. `on_progress` hears of each point fitted, each profile traced and each better
/// point.
pub fn profile_from_optimum<S, M>(
    method: &M,
    problem: &Problem<S>,
    optimum: Estimate,
    only: &[usize],
    options: &ProfileOptions,
    on_progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Profiled, ProfileError>
where
    S: System + Sync,
    M: Method<S> + Sync + ?Sized,
{
    let certified = optimum.converged();
    let mut optimum = optimum;
    let mut better = Vec::new();
    loop {
        match profile_observed(method, problem, &optimum, only, options, on_progress)? {
            Outcome::Profiles(profiles) => {
                return Ok(Profiled { certified, optimum, better, profiles });
            }
            // Stopped: the profiles that found it are gone, and the fit from it would stop.
            Outcome::BetterOptimum(_) if sysid_core::observer::stop_requested() => {
                return Err(ProfileError::Interrupted);
            }
            Outcome::BetterOptimum(point) if better.len() < MAX_RESTARTS => {
                on_progress(Progress::Better { point: &point, was: objective(&optimum) });
                optimum = sysid_core::caught(|| method.fit_from(problem, &point.estimates))
                    .map_err(ProfileError::Panicked)??;
                better.push(point);
            }
            Outcome::BetterOptimum(_) => {
                return Err(ProfileError::NoOptimum {
                    verdict: optimum.verdict().to_string(),
                    termination: optimum.termination.to_string(),
                });
            }
        }
    }
}

/// χ²₁(0.95)/2: the pointwise 95 % threshold of ΔNLL.
pub const POINTWISE_95: f64 = 3.841_458_820_694_124 / 2.0;

/// The threshold of ΔNLL for 95 % confidence: pointwise, χ²₁(0.95)/2 ([`POINTWISE_95`]);
/// simultaneous for `k` unknowns, χ²ₖ(0.95)/2 (the region of all k at once, as
/// Data2Dynamics' `ple` offers).
pub fn threshold_95(simultaneous: Option<usize>) -> f64 {
    use cdflib::ChiSquared;
    use cdflib::traits::{Continuous, ContinuousCdf};
    match simultaneous {
        Some(k) if k > 1 => {
            let chi = ChiSquared::new(k as f64);
            let Ok(mut q) = chi.inverse_cdf(0.95) else { return POINTWISE_95 };
            // cdflib's inverse is a search to about 1e-9 relative (χ²₂: 5.99146455 where
            // −2 ln 0.05 = 5.99146454711); Newton's steps on the CDF, whose own accuracy is
            // near the last digit, take it to that.
            for _ in 0..3 {
                let next = q - (chi.cdf(q) - 0.95) / chi.pdf(q);
                if !next.is_finite() {
                    break;
                }
                q = next;
            }
            0.5 * q
        }
        _ => POINTWISE_95,
    }
}

/// The longest step, in units of the coordinate's scale (1 for ln θ: a factor e).
pub const MAX_STEP: f64 = 1.0;

/// How a profile is traced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProfileOptions {
    /// ΔNLL at which a side ends (default [`POINTWISE_95`]).
    pub threshold: f64,
    /// Most points per side (default 60).
    pub max_steps: usize,
    /// The crossing is located to this fraction of its distance from the optimum (1e-6).
    pub locate: f64,
}

impl Default for ProfileOptions {
    fn default() -> Self {
        Self { threshold: POINTWISE_95, max_steps: 60, locate: 1e-6 }
    }
}

impl ProfileOptions {
    /// Checks the options: a threshold that is finite and positive (at −1 every profile was
    /// "identifiable" with a zero-width interval), at least one point a side, and a locating
    /// fraction in (0, 1).
    pub fn validate(&self) -> Result<(), ProfileError> {
        let invalid = |what: String| Err(ProfileError::Invalid(what));
        if !(self.threshold > 0.0 && self.threshold.is_finite()) {
            return invalid(format!(
                "the threshold must be a finite positive ΔNLL, got {}",
                self.threshold
            ));
        }
        if self.max_steps == 0 {
            return invalid("max_steps must be at least 1".into());
        }
        if !(self.locate > 0.0 && self.locate < 1.0) {
            return invalid(format!("locate must lie in (0, 1), got {}", self.locate));
        }
        Ok(())
    }
}

/// One point of a profile.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Point {
    /// θ_i.
    pub value: f64,
    /// The NLL minimised over the others.
    pub nll: f64,
    /// Whether that fit converged (its certificate).
    pub converged: bool,
    /// Every unknown's value there, θ_i included, in the problem's order.
    pub estimates: Vec<f64>,
}

/// The identifiability verdict of one unknown.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Label {
    /// Both sides cross the threshold.
    Identifiable,
    /// A side reaches a bound without crossing, or the step budget with its steps at their
    /// longest (the profile flat).
    PracticallyNonIdentifiable,
    /// A side's step budget ran out while its steps were still shorter than the longest:
    /// the profile was rising and had not crossed; more points decide.
    Undecided,
    /// The profile is flat: it rises by less than 1e-3 of the threshold over the range
    /// walked, from an optimum whose certificate holds but for undetermined unknowns.
    StructurallyNonIdentifiable,
    /// A fit along the profile panicked (a defect in sysid): no verdict
    /// ([`Profile::failed`] holds the message).
    Failed,
    /// The run was stopped before the profile was done
    /// ([`stop_when`](sysid_core::observer::stop_when)): no verdict; its points are those
    /// fitted before the stop.
    Stopped,
}

impl Label {
    /// The verdict in words: "practically non-identifiable".
    pub fn words(self) -> &'static str {
        match self {
            Label::Identifiable => "identifiable",
            Label::PracticallyNonIdentifiable => "practically non-identifiable",
            Label::Undecided => "undecided (the point budget ran out before the threshold)",
            Label::StructurallyNonIdentifiable => "structurally non-identifiable",
            Label::Failed => "failed (a fit along it panicked)",
            Label::Stopped => "stopped (the run was stopped before the profile was done)",
        }
    }
}

/// The profile of one unknown.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Profile {
    /// The unknown.
    pub name: String,
    /// Where the profile crosses the threshold, below and above the optimum (None: no
    /// crossing on that side).
    pub interval: [Option<f64>; 2],
    /// The verdict.
    pub label: Label,
    /// The points, by value, the optimum included.
    pub points: Vec<Point>,
    /// The message of the panic (a defect in sysid) that ended a side's tracing, where one
    /// did ([`Label::Failed`]); the points walked before it are kept.
    pub failed: Option<String>,
}

impl Profile {
    /// The profile as the JSON of `sysid profile` has it under its name: `interval`,
    /// `label`, `points`, `failed`.
    pub fn record(&self) -> Record<'_> {
        Record {
            interval: self.interval,
            label: self.label,
            points: &self.points,
            failed: self.failed.as_deref(),
        }
    }
}

impl Profiled {
    /// The JSON object of `sysid profile --format json` (docs/json.md) for the problem
    /// called `system`, the profiles ended at ΔNLL `threshold`.
    pub fn record<'a>(&'a self, system: &'a str, threshold: f64) -> ProfiledRecord<'a> {
        ProfiledRecord {
            optimum: self.optimum.record(system),
            from_certified_optimum: self.certified && self.better.is_empty(),
            better_optimum_found: &self.better,
            threshold,
            profiles: &self.profiles,
        }
    }
}

/// The JSON of `sysid profile` ([`Profiled::record`]): the profiles by name.
#[derive(Serialize)]
pub struct ProfiledRecord<'a> {
    optimum: FitRecord<'a>,
    from_certified_optimum: bool,
    better_optimum_found: &'a [Point],
    threshold: f64,
    #[serde(serialize_with = "by_name")]
    profiles: &'a [Profile],
}

/// The profiles as an object: name → [`Profile::record`], in their order.
fn by_name<S: serde::Serializer>(profiles: &&[Profile], s: S) -> Result<S::Ok, S::Error> {
    s.collect_map(profiles.iter().map(|p| (&p.name, p.record())))
}

/// A profile without its name ([`Profile::record`]).
#[derive(Serialize)]
pub struct Record<'a> {
    interval: [Option<f64>; 2],
    label: Label,
    points: &'a [Point],
    failed: Option<&'a str>,
}

/// What profiling found.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The profile of each unknown asked for.
    Profiles(Vec<Profile>),
    /// A point with a lower NLL than the optimum's: the fit was not at the optimum.
    BetterOptimum(Point),
}

/// Why a side ended.
enum End {
    Crossed(f64),
    Open,
    /// The step budget ran out below the threshold with steps shorter than the longest.
    Budget,
    Better(Point),
    /// A fit panicked, with this message.
    Failed(String),
    /// The caller asked the run to stop.
    Stopped,
}

/// What a profile traces of a fit: the objective it minimises, the negative log-likelihood
/// plus the priors' term where there are priors (the profile posterior, as pyPESTO traces
/// it), or ε/2 where there is no likelihood ([`Estimate::objective`]). The likelihood alone
/// would put a fit with an informative prior above points the prior pulls less, and every
/// profile would find a "better optimum" there.
pub fn objective(e: &Estimate) -> f64 {
    e.objective()
}

/// Profiles the unknowns `only` (indices; every unknown when empty) of `problem` around
/// `optimum` (a fit of it), re-optimising with `method`.
pub fn profile<S, M>(
    method: &M,
    problem: &Problem<S>,
    optimum: &Estimate,
    only: &[usize],
    options: &ProfileOptions,
) -> Result<Outcome, ProfileError>
where
    S: System + Sync,
    M: Method<S> + Sync + ?Sized,
{
    profile_observed(method, problem, optimum, only, options, &|_| {})
}

/// [`profile`], telling `on_progress` of each point fitted ([`Progress::Point`]) and each
/// profile as it ends ([`Progress::Traced`]), from the threads that trace them.
pub fn profile_observed<S, M>(
    method: &M,
    problem: &Problem<S>,
    optimum: &Estimate,
    only: &[usize],
    options: &ProfileOptions,
    on_progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Outcome, ProfileError>
where
    S: System + Sync,
    M: Method<S> + Sync + ?Sized,
{
    options.validate()?;
    let k = problem.unknowns().len();
    if let Some(&i) = only.iter().find(|&&i| i >= k) {
        return Err(ProfileError::Invalid(format!(
            "unknown {i} to profile: the problem has {k} ({})",
            problem.unknowns().names().join(", ")
        )));
    }
    if optimum.names != problem.unknowns().names() || optimum.values.len() != k {
        return Err(ProfileError::Invalid(format!(
            "the optimum is a fit of other unknowns ({}) than the problem's ({})",
            optimum.names.join(", "),
            problem.unknowns().names().join(", ")
        )));
    }
    // In the problem's order, whatever the order asked for (the JSON's objects keyed by
    // unknown list the unknowns so).
    let which: Vec<usize> = (0..k).filter(|i| only.is_empty() || only.contains(i)).collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    // The caller's stop flag, handed to the threads that trace.
    let stop = sysid_core::observer::current_stop();
    let results: Vec<Result<Result<Profile, Point>, ProfileError>> = which
        .par_iter()
        .map(|&i| {
            let tracer = Tracer { method, problem, optimum, i, options, on_progress };
            let profile = sysid_core::observer::stop_within(stop.clone(), || tracer.profile());
            let count = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
            on_progress(Progress::Traced { unknown: i, done: count, total: which.len() });
            profile
        })
        .collect();
    let mut profiles = Vec::with_capacity(results.len());
    for result in results {
        match result? {
            Ok(p) => profiles.push(p),
            Err(better) => return Ok(Outcome::BetterOptimum(better)),
        }
    }
    Ok(Outcome::Profiles(profiles))
}

/// The tracing of one unknown's profile.
struct Tracer<'a, S, M: ?Sized> {
    method: &'a M,
    problem: &'a Problem<S>,
    optimum: &'a Estimate,
    i: usize,
    options: &'a ProfileOptions,
    on_progress: &'a (dyn Fn(Progress<'_>) + Sync),
}

impl<S: System + Sync, M: Method<S> + Sync + ?Sized> Tracer<'_, S, M> {
    fn profile(&self) -> Result<Result<Profile, Point>, ProfileError> {
        let base = objective(self.optimum);
        let at = Point {
            value: self.optimum.values[self.i],
            nll: base,
            converged: self.optimum.converged(),
            estimates: self.optimum.values.clone(),
        };
        let mut points = vec![at.clone()];
        let mut interval = [None, None];
        let (mut open, mut budget, mut failed, mut stopped) = (false, false, None, false);
        for (side, direction) in [-1.0, 1.0].into_iter().enumerate() {
            let (walked, end) = self.side(&at, direction)?;
            points.extend(walked);
            match end {
                End::Crossed(value) => interval[side] = Some(value),
                End::Open => open = true,
                End::Budget => budget = true,
                End::Better(point) => return Ok(Err(point)),
                End::Failed(message) => failed = failed.or(Some(message)),
                End::Stopped => stopped = true,
            }
        }
        points.sort_by(|a, b| a.value.total_cmp(&b.value));
        let rise = points.iter().map(|p| p.nll - base).fold(0.0, f64::max);
        // A side whose budget ran out with its steps still short decides nothing, flat or
        // not: with `--max-points 2` no point was walked, the rise was 0, and an identifiable
        // unknown was called structurally non-identifiable.
        // A side open at a bound or flat decides practical non-identifiability whatever the
        // other side's budget left undecided (it said `undecided` where --max-points 5 ran
        // out on the side away from the bound).
        let label = if failed.is_some() {
            Label::Failed
        } else if stopped {
            Label::Stopped
        } else if !budget && rise < 1e-3 * self.options.threshold && self.at_a_minimum() {
            // Flat from a minimum: a property of the model there. From a point that is not
            // one (a plateau where the model responds to nothing, a fit stopped short),
            // flatness says only that the data do not constrain the unknown over the range
            // walked: practically non-identifiable, below.
            Label::StructurallyNonIdentifiable
        } else if open {
            Label::PracticallyNonIdentifiable
        } else if budget {
            Label::Undecided
        } else {
            Label::Identifiable
        };
        let name = self.problem.names()[self.i].clone();
        Ok(Ok(Profile { name, interval, label, points, failed }))
    }

    /// Whether the optimum passes the certificate but for unknowns it finds undetermined
    /// (the model does not respond to them there, the clearest structural case): the
    /// first-order test holds, checked by an integration that resolves the model, the noise
    /// scales have settled, and the point is no plateau.
    fn at_a_minimum(&self) -> bool {
        self.optimum.certificate.holds_but_for_undetermined()
    }

    /// Whether `p` lies below the optimum by more than 1e-6 relative: the fit was not at it.
    fn below_optimum(&self, p: &Point) -> bool {
        let base = objective(self.optimum);
        p.nll < base - 1e-6 * base.abs().max(1.0)
    }

    /// The profile's point at coordinate `z`: the fit with θ_i held there, from the point
    /// `from`. A panic in it becomes [`ProfileError::Panicked`], which ends the side
    /// ([`End::Failed`]); `Interrupted` where the caller asked the run to stop, before the
    /// fit or while it ran (its point is not the profile's then), which ends it
    /// ([`End::Stopped`]).
    fn fit_at(&self, z: f64, from: &Point) -> Result<Point, ProfileError> {
        if sysid_core::observer::stop_requested() {
            return Err(ProfileError::Interrupted);
        }
        let point = sysid_core::caught(|| self.fit_at_unguarded(z, from))
            .map_err(ProfileError::Panicked)?;
        if sysid_core::observer::stop_requested() {
            return Err(ProfileError::Interrupted);
        }
        if let Ok(point) = &point {
            let rise = point.nll - objective(self.optimum);
            (self.on_progress)(Progress::Point { unknown: self.i, point, rise });
        }
        point
    }

    fn fit_at_unguarded(&self, z: f64, from: &Point) -> Result<Point, ProfileError> {
        let unknown = &self.problem.unknowns().list()[self.i];
        let value = unknown.value(z);
        if self.problem.unknowns().len() == 1 {
            return Ok(self.likelihood_at(z));
        }
        let name = unknown.name.clone();
        let fixed = self.problem.clone().with_fixed(&[(name, value)])?;
        let start: Vec<f64> = from
            .estimates
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != self.i)
            .map(|(_, v)| *v)
            .collect();
        let e = self.method.fit_from(&fixed, &start)?;
        let mut estimates = e.values.clone();
        estimates.insert(self.i, value);
        Ok(Point { value, nll: objective(&e), converged: e.converged(), estimates })
    }

    /// The profile of the only unknown: nothing is re-optimised (but the noise scales set in
    /// closed form), so the profile is the likelihood itself; ∞ where the model cannot be
    /// integrated.
    fn likelihood_at(&self, z: f64) -> Point {
        let value = self.problem.unknowns().list()[self.i].value(z);
        let problem = match self.problem.scales().is_empty() {
            true => Some(self.problem.clone()),
            false => self.problem.optimal_scales(&[value]).map(|s| self.problem.with_scales(&s)),
        };
        // As [`objective`] has it: the likelihood plus the priors' term, or ε/2 where there
        // is no likelihood (a continuous record).
        let nll = problem
            .and_then(|p| match p.nll_at(&[z]) {
                Ok(Some(v)) => Some(v + p.prior_nll_at(&[z]).unwrap_or(0.0)),
                Ok(None) => p.cost(&[z]).ok().map(|(cost, _)| 0.5 * cost),
                Err(_) => None,
            })
            .filter(|v| !v.is_nan())
            .unwrap_or(f64::INFINITY);
        Point { value, nll, converged: nll.is_finite(), estimates: vec![value] }
    }

    /// Walks one side from the optimum `at` (direction ±1 in the coordinate).
    fn side(&self, at: &Point, direction: f64) -> Result<(Vec<Point>, End), ProfileError> {
        let unknown = &self.problem.unknowns().list()[self.i];
        let (lo, hi) = unknown.coordinate_bounds();
        let z0 = self.problem.unknowns().coordinates(&at.estimates)[self.i];
        let scale = unknown.coordinate_scale(z0);
        let threshold = self.options.threshold;
        let target = 0.1 * threshold;
        let mut points: Vec<Point> = Vec::new();
        let (mut z, mut previous) = (z0, at.clone());
        let limit = if direction > 0.0 { hi } else { lo };
        // An optimum on the bound this side walks to: the side is open there, and a fit
        // held at the bound would repeat the optimum's point (with the last digits of a new
        // fit, a hair below it as often as above).
        if if direction > 0.0 { z0 >= limit } else { z0 <= limit } {
            return Ok((points, End::Open));
        }
        let mut h = 0.01 * scale;
        // The budget counts the points walked: a step retried at half its length is the same
        // point (counting it had left a side of `--max-points 1` with none).
        while points.len() < self.options.max_steps {
            let mut next_z = z + direction * h;
            let at_bound = if direction > 0.0 { next_z >= limit } else { next_z <= limit };
            if at_bound {
                next_z = limit;
            }
            let point = match self.fit_at(next_z, &previous) {
                Err(ProfileError::Panicked(message)) => return Ok((points, End::Failed(message))),
                Err(ProfileError::Interrupted) => return Ok((points, End::Stopped)),
                other => other?,
            };
            if self.below_optimum(&point) {
                return Ok((points, End::Better(point)));
            }
            let rise = point.nll - previous.nll;
            if rise > 2.0 * target && h > 1e-12 * scale && !at_bound {
                h *= 0.5;
                continue;
            }
            if point.nll - at.nll > threshold {
                points.push(point.clone());
                // The points fitted while locating go into `points` as they are fitted: a
                // panic or a stop keeps those before it.
                let crossing = self.locate((z, &previous), (next_z, &point), z0, &mut points);
                let crossing = match crossing {
                    Err(ProfileError::Panicked(message)) => {
                        return Ok((points, End::Failed(message)));
                    }
                    // Bracketed, not located.
                    Err(ProfileError::Interrupted) => return Ok((points, End::Stopped)),
                    other => other?,
                };
                return Ok(match crossing {
                    Ok(value) => (points, End::Crossed(value)),
                    Err(better) => (points, End::Better(better)),
                });
            }
            points.push(point.clone());
            if at_bound {
                return Ok((points, End::Open));
            }
            let grow = if rise > 0.0 { (target / rise).sqrt().clamp(0.5, 2.0) } else { 2.0 };
            h = (h * grow).min(MAX_STEP * scale);
            (z, previous) = (next_z, point);
        }
        // Out of steps: open where they had grown to the longest (the profile flat), else
        // undecided.
        Ok((points, if h >= MAX_STEP * scale { End::Open } else { End::Budget }))
    }

    /// The value where the profile crosses the threshold between `a` (below) and `b`
    /// (above), the points evaluated on the way pushed onto `located` as they come; or a
    /// point below the optimum.
    fn locate(
        &self,
        (mut za, a): (f64, &Point),
        (mut zb, b): (f64, &Point),
        z0: f64,
        located: &mut Vec<Point>,
    ) -> Result<Result<f64, Point>, ProfileError> {
        let level = objective(self.optimum) + self.options.threshold;
        let (mut fa, mut fb) = (a.nll - level, b.nll - level);
        let (mut from, mut side) = (a.clone(), 0i8);
        let unknown = &self.problem.unknowns().list()[self.i];
        for _ in 0..100 {
            if (zb - za).abs() <= self.options.locate * (0.5 * (za + zb) - z0).abs() {
                break;
            }
            // Regula falsi, bisection where it would not shrink the bracket.
            let mut z = zb - fb * (zb - za) / (fb - fa);
            if !(z.is_finite() && (z - za) * (z - zb) < 0.0) {
                z = 0.5 * (za + zb);
            }
            let p = self.fit_at(z, &from)?;
            if self.below_optimum(&p) {
                return Ok(Err(p));
            }
            let f = p.nll - level;
            if f > 0.0 {
                (zb, fb) = (z, f);
                // Illinois: halve the value kept twice on the same side.
                if side == 1 {
                    fa *= 0.5;
                }
                side = 1;
            } else {
                (za, fa) = (z, f);
                if side == -1 {
                    fb *= 0.5;
                }
                side = -1;
                from = p.clone();
            }
            located.push(p);
        }
        let z = zb - fb * (zb - za) / (fb - fa);
        let z = if z.is_finite() && (z - za) * (z - zb) <= 0.0 { z } else { 0.5 * (za + zb) };
        Ok(Ok(unknown.value(z)))
    }
}
