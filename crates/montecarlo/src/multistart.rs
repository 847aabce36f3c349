//! Multistart: one method from many starts on one problem, the best fit kept, the minima the
//! starts found, and every start's outcome (the waterfall).
//!
//! The starts are drawn (ChaCha8 seeded by [`MultistartOptions::seed`]) as the field draws
//! them (pyPESTO, Data2Dynamics, PEtab.jl): [`Sampling::Uniform`], each unknown uniformly on
//! its own scale within its bounds (between the logs of the bounds on a log scale), every
//! unknown and every start independently. [`Sampling::LatinHypercube`] cuts each unknown's
//! range into N strata of equal width instead, one start in each. An unknown without two
//! finite bounds spreads ±ρ around its guess under either sampling, as a study's starts
//! spread around the truth: guess·(1 + ρu) with u on [−1, 1], guess·(1 + ρ)^u on a log
//! scale, ρu for a guess of 0, then moved onto a one-sided bound it falls outside of. The
//! An unknown with an [`Initialization`](sysid_core::Initialization) (PEtab's
//! `initializationPriorType`) is drawn from it instead, at the same uniform or stratified
//! quantile, and moved into its bounds. The problem's own guess is the first start unless [`MultistartOptions::guess`] is false, so
//! that N starts never do worse than one.
//!
//! The fits run on rayon. A fit that panics (a defect in sysid) does not take the others
//! down: its start is reported with [`Termination::Panicked`] (not converged, no objective)
//! and the panic's message, and the multistart goes on. A drawn start whose fit cannot even begin (the model cannot be
//! integrated there, or its cost overflows) is redrawn, uniformly over the same ranges, up
//! to [`MAX_REDRAWS`] times; the redraws are counted (`redrawn`). Fits are ranked by what
//! they minimise: the negative log-likelihood (with the priors' term where there are
//! priors) where there is one (with noise scales estimated, ε ends every fit at about the
//! number of data and ranks nothing), else ε/2. The best fit is the converged one with the
//! least objective, unless a fit that did not converge ended lower (by more than
//! [`SAME_MINIMUM_RTOL`] of ε): a certified point is then not reported as the best when a
//! lower one was found (a corner of the box where every bound is active is a certified point
//! of the bounded problem, and often a poor one), and the lowest is reported, not converged.
//! With none converged, the least objective of all. A start *reached the best* when its fit
//! converged to an objective within [`REACHED`] of the best's (the field's threshold for a
//! successful start); the distinct minima are the converged fits grouped by
//! [`SAME_MINIMUM_RTOL`], least first.
//!
//! When every start has run (and the time budget is not spent), the start that ran out of
//! iterations lowest is fitted on once from where it stopped, with the method's budget again,
//! where it ended below every converged start (or none converged): its crawl was going where
//! no other start went. Where the continuation ends no higher it is kept: its row says
//! `continued`, and its iterations, time, evaluations and history are both fits' as one.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicUsize, Ordering};
use sysid_core::format::significant;
use sysid_core::{Estimate, FitError, Method, Problem, Termination, Unknown};
use sysid_ode::System;

/// Two converged costs within this relative distance are one minimum.
pub const SAME_MINIMUM_RTOL: f64 = 1e-6;

/// The most times one drawn start is redrawn when its fit cannot begin there.
pub const MAX_REDRAWS: usize = 10;

/// A start reached the best when its fit converged to an objective (negative log-likelihood)
/// within this of the best's: the threshold the field counts successful starts by (Hass et
/// al., Bioinformatics 2019; Fröhlich and Sorger, PLoS Comput. Biol. 2022).
pub const REACHED: f64 = 0.1;

/// The most starts one multistart takes: a million, far beyond what the field draws (tens to
/// thousands), and a bound on the memory of their draws and outcomes (a count of 10¹² asked
/// for 8 TB and aborted the process).
pub const MAX_STARTS: usize = 1_000_000;

/// How the starts after the guess are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Sampling {
    /// Each unknown uniformly on its scale within its bounds, independently (the field's
    /// default: pyPESTO, Data2Dynamics).
    #[default]
    Uniform,
    /// A Latin hypercube: each unknown's range cut into N strata, one start in each.
    LatinHypercube,
}

impl Sampling {
    /// Its name on the command line and in the JSON.
    pub fn name(self) -> &'static str {
        match self {
            Sampling::Uniform => "uniform",
            Sampling::LatinHypercube => "latin-hypercube",
        }
    }
}

/// How many starts, drawn how.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MultistartOptions {
    /// N, the number of starts (the guess included when [`guess`](Self::guess)).
    pub starts: usize,
    /// Seed of the draws.
    pub seed: u64,
    /// ρ, the spread around the guess of unknowns without two bounds.
    pub spread: f64,
    /// How the starts are drawn.
    pub sampling: Sampling,
    /// Whether the problem's guess is the first start (else all N are drawn).
    pub guess: bool,
    /// Wall-clock time after which no further start begins (None: all N run). The starts
    /// are taken in order, so those fitted are always the first ones; the first always runs,
    /// and a fit already begun runs to its end.
    pub budget: Option<std::time::Duration>,
}

impl Default for MultistartOptions {
    fn default() -> Self {
        Self {
            starts: 10,
            seed: 1,
            spread: 0.5,
            sampling: Sampling::Uniform,
            guess: true,
            budget: None,
        }
    }
}

impl MultistartOptions {
    /// Checks the options, naming the first that cannot be used by its field.
    pub fn validate(&self) -> Result<(), sysid_core::OptionsError> {
        if self.starts == 0 {
            return Err(sysid_core::OptionsError::Zero { name: "starts" });
        }
        if self.starts > MAX_STARTS {
            let (value, most) = (self.starts, MAX_STARTS);
            return Err(sysid_core::OptionsError::TooMany { name: "starts", value, most });
        }
        if let Some(budget) = self.budget {
            sysid_core::OptionsError::positive("budget", budget.as_secs_f64())?;
        }
        sysid_core::OptionsError::positive("spread", self.spread)
    }
}

/// The outcome of a multistart run.
#[derive(Clone, Debug)]
pub struct Multistart {
    /// The best fit.
    pub best: Estimate,
    /// What the starts found.
    pub starts: Starts,
}

/// What the starts found: the `starts` object of the fit JSON.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Starts {
    /// The starts fitted: N, unless the time budget (or the caller's stop) left some out.
    pub count: usize,
    /// Starts drawn but not fitted because the time budget had run out (0 without one), or
    /// because the caller stopped the run ([`stopped`](Self::stopped)).
    pub not_started: usize,
    /// Whether the caller stopped the run ([`stop_when`](sysid_core::observer::stop_when);
    /// Ctrl-C or SIGTERM in the command line): its running fits ended `interrupted`, and
    /// `not_started` counts the starts it did not begin.
    pub stopped: bool,
    /// The draws' seed.
    pub seed: u64,
    /// ρ.
    pub spread: f64,
    /// How the starts were drawn.
    pub sampling: Sampling,
    /// Whether start 0 is the problem's guess.
    pub guess: bool,
    /// The start of the best fit (0 is the problem's guess).
    pub best_start: usize,
    /// Starts whose fit converged.
    pub converged: usize,
    /// Starts whose fit converged to within [`REACHED`] of the best objective.
    pub reached_best: usize,
    /// Drawn starts replaced because the fit could not begin there (each at most
    /// [`MAX_REDRAWS`] times).
    pub redrawn: usize,
    /// The distinct minima the converged fits reached, least objective first.
    pub minima: Vec<Minimum>,
    /// Wall-clock time of all the fits, in milliseconds.
    pub elapsed_ms: f64,
    /// Converged fits per minute of wall-clock time (the field's measure of a multistart's
    /// efficiency, with `reached_best`).
    pub converged_per_minute: f64,
    /// Every start's outcome, least objective first (the waterfall plot's data).
    pub waterfall: Vec<Outcome>,
}

/// One start's outcome: a row of the waterfall.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Outcome {
    /// The start (0 is the guess when the guess is a start).
    pub start: usize,
    /// The objective the starts are ranked by: the negative log-likelihood plus the priors'
    /// term where there is a likelihood, else ε/2 (null where the fit could not begin).
    pub objective: Option<f64>,
    /// ε at the fit's end (null where it is not finite: the fit could not begin).
    pub cost: Option<f64>,
    /// Whether the fit converged.
    pub converged: bool,
    /// Its termination code (docs/terminations.md).
    pub termination_code: String,
    /// Its iterations.
    pub iterations: usize,
    /// Wall-clock time of the fit (redraws included), in milliseconds.
    pub elapsed_ms: f64,
    /// Where the fit began, by name (the last draw where the start was redrawn), the noise
    /// scales set in closed form last: `--start` NAME=VALUE for each of them fits this start
    /// again.
    pub start_values: serde_json::Map<String, serde_json::Value>,
    /// Where it ended, by name.
    pub estimates: serde_json::Map<String, serde_json::Value>,
    /// Whether it was fitted on once more after every start had run and the continuation
    /// kept (the module's docs): its `iterations` and `elapsed_ms` then count both fits.
    pub continued: bool,
}

impl std::fmt::Display for Starts {
    /// "20 starts in 31.2 ms (…): 18 converged, 12 reached the best (start 0); 2 distinct
    /// minima: ε = …, nll … (12 starts), ε = …, nll … (6 starts)".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let plural = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
        let minima: Vec<String> = self
            .minima
            .iter()
            .map(|m| {
                let nll =
                    m.nll.map(|v| format!(", nll {}", significant(v, 10))).unwrap_or_default();
                format!("ε = {}{nll} ({})", significant(m.cost, 10), plural(m.count, "start"))
            })
            .collect();
        write!(
            f,
            "{} in {:.1} ms ({}{}, seed {}, ρ {}): {} converged ({:.1} per minute), {} reached the best to within {REACHED} (start {}); {}: {}",
            plural(self.count, "start"),
            self.elapsed_ms,
            if self.guess { "the guess, then " } else { "" },
            match self.sampling {
                Sampling::Uniform => "uniform on each scale",
                Sampling::LatinHypercube => "a Latin hypercube",
            },
            self.seed,
            self.spread,
            self.converged,
            self.converged_per_minute,
            self.reached_best,
            self.best_start,
            match self.minima.len() {
                1 => "1 distinct minimum".to_string(),
                n => format!("{n} distinct minima"),
            },
            if minima.is_empty() { "none".to_string() } else { minima.join(", ") }
        )?;
        if self.redrawn > 0 {
            write!(f, "; {} redrawn where the fit could not begin", plural(self.redrawn, "start"))?;
        }
        if self.not_started > 0 {
            let why =
                if self.stopped { ": the run was stopped" } else { " within the time budget" };
            write!(f, "; {} more drawn, not begun{why}", self.not_started)?;
        }
        if let Some(o) = self.waterfall.iter().find(|o| o.continued) {
            write!(f, "; start {} fitted on from the iteration limit", o.start)?;
        }
        let mut panicked: Vec<usize> = self
            .waterfall
            .iter()
            .filter(|o| o.termination_code == "panicked")
            .map(|o| o.start)
            .collect();
        if !panicked.is_empty() {
            panicked.sort_unstable();
            let list: Vec<String> = panicked.iter().map(usize::to_string).collect();
            write!(
                f,
                "; {} panicked, a defect in sysid (please report it with the command; the message is on stderr): {} {}",
                plural(panicked.len(), "fit"),
                if panicked.len() == 1 { "start" } else { "starts" },
                list.join(", ")
            )?;
        }
        Ok(())
    }
}

/// One minimum the starts reached.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Minimum {
    /// ε of the fit with the least objective among those that reached it.
    pub cost: f64,
    /// Its negative log-likelihood, the objective the minima are ranked by (null for a
    /// continuous record, ranked by ε).
    pub nll: Option<f64>,
    /// How many starts reached it.
    pub count: usize,
    /// The start of that fit (the least objective among those that reached it; the earliest
    /// of equal ones).
    pub start: usize,
    /// The estimates of that fit, by name, in the problem's order.
    pub estimates: serde_json::Map<String, serde_json::Value>,
}

/// The N starts of `problem` (values, in the problem's order), the guess first where
/// [`MultistartOptions::guess`].
pub fn starts<S: System>(problem: &Problem<S>, options: &MultistartOptions) -> Vec<Vec<f64>> {
    let n = options.starts.max(1);
    let drawn = if options.guess { n - 1 } else { n };
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let unknowns = problem.unknowns().list();
    let columns: Vec<Vec<f64>> = unknowns
        .iter()
        .map(|u| {
            let fractions: Vec<f64> = match options.sampling {
                Sampling::Uniform => (0..drawn).map(|_| rng.random::<f64>()).collect(),
                Sampling::LatinHypercube => {
                    let mut strata: Vec<usize> = (0..drawn).collect();
                    strata.shuffle(&mut rng);
                    strata
                        .into_iter()
                        .map(|s| (s as f64 + rng.random::<f64>()) / drawn as f64)
                        .collect()
                }
            };
            fractions.into_iter().map(|f| draw(u, f, options.spread)).collect()
        })
        .collect();
    let mut starts = if options.guess { vec![problem.guesses()] } else { Vec::new() };
    starts.extend((0..drawn).map(|j| columns.iter().map(|c| c[j]).collect()));
    starts
}

/// The value of an unknown at `fraction` ∈ [0, 1] of its range: the quantile of its
/// initialization where it has one (moved into its bounds), else uniform on its scale within
/// its bounds, or spread around its guess.
fn draw(u: &Unknown, fraction: f64, spread: f64) -> f64 {
    let clamp =
        |v: f64| v.clamp(u.min.unwrap_or(f64::NEG_INFINITY), u.max.unwrap_or(f64::INFINITY));
    if let Some(init) = &u.initialization {
        let v = clamp(init.quantile(fraction));
        // A draw a log scale cannot hold (a normal one on the value, below 0 with no lower
        // bound) falls back to the default.
        if v.is_finite() && (!u.log || v > 0.0) {
            return v;
        }
    }
    let (lo, hi) = u.coordinate_bounds();
    if lo.is_finite() && hi.is_finite() {
        return u.value(lo + fraction * (hi - lo));
    }
    let t = 2.0 * fraction - 1.0;
    let value = if u.log {
        u.guess * (1.0 + spread).powf(t)
    } else if u.guess == 0.0 {
        spread * t
    } else {
        u.guess * (1.0 + spread * t)
    };
    clamp(value)
}

/// `method`'s fit of `problem` from `start`, where a panic (a defect in sysid) becomes the
/// estimate [`Estimate::panicked`] with the panic's message instead of unwinding further: for
/// the callers that run many fits (multistart, a study's trials), so that one defect does
/// not lose the others' results.
pub fn guarded<S, M>(method: &M, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError>
where
    S: System,
    M: Method<S> + ?Sized,
{
    let began = std::time::Instant::now();
    sysid_core::caught(|| method.fit_once_from(problem, start)).unwrap_or_else(|message| {
        Ok(Estimate::panicked(problem, method.name(), start, message, began.elapsed()))
    })
}

/// One start's fit: the fit, how often its start was redrawn, its wall time in milliseconds
/// (redraws included) and the start it began from (values).
struct Run {
    fit: Estimate,
    redrawn: usize,
    ms: f64,
    from: Vec<f64>,
}

/// Fits `problem` with `method` from the starts of `options`, on rayon.
pub fn multistart<S, M>(
    method: &M,
    problem: &Problem<S>,
    options: &MultistartOptions,
) -> Result<Multistart, FitError>
where
    S: System + Sync,
    M: Method<S> + Sync + ?Sized,
{
    multistart_observed(method, problem, options, &|_| {})
}

/// A start's fit that has just ended, as [`multistart_observed`] tells it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartDone {
    /// The start's index (0 is the guess where [`MultistartOptions::guess`]).
    pub start: usize,
    /// How many starts have ended, this one included.
    pub done: usize,
    /// How many starts there are (those the budget leaves out included).
    pub total: usize,
    /// Its final objective (the negative log-likelihood plus the priors' term, or ε/2 without
    /// a likelihood), as the waterfall gives it.
    pub objective: Option<f64>,
    /// Whether its certificate holds.
    pub converged: bool,
}

/// [`multistart`], telling `observer` of each start as its fit ends (from the thread that
/// fitted it, in the order they end).
pub fn multistart_observed<S, M>(
    method: &M,
    problem: &Problem<S>,
    options: &MultistartOptions,
    observer: &(dyn Fn(StartDone) + Sync),
) -> Result<Multistart, FitError>
where
    S: System + Sync,
    M: Method<S> + Sync + ?Sized,
{
    options.validate()?;
    let done = AtomicUsize::new(0);
    let started = std::time::Instant::now();
    let starts = starts(problem, options);
    // A queue in start order, served by one task per thread: once the budget is spent no
    // task takes another start, so the starts fitted are the first ones, whatever the timing.
    let next = AtomicUsize::new(0);
    // A fit that panics (a defect) is reported as that start's outcome; the others stand.
    let fit_from = |from: &[f64]| guarded(method, problem, from);
    let fit_start = |j: usize| -> Result<Run, FitError> {
        let began = std::time::Instant::now();
        let mut from = starts[j].clone();
        let mut fit = fit_from(&from)?;
        let mut redrawn = 0;
        // The guess (start 0) is the user's: it is kept whatever happens there.
        if j > 0 || !options.guess {
            let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
            rng.set_stream(j as u64);
            while redrawn < MAX_REDRAWS
                && matches!(fit.termination, Termination::StartFailed(_))
                && !sysid_core::observer::stop_requested()
            {
                from = problem
                    .unknowns()
                    .list()
                    .iter()
                    .map(|u| draw(u, rng.random::<f64>(), options.spread))
                    .collect();
                fit = fit_from(&from)?;
                redrawn += 1;
            }
        }
        Ok(Run { fit, redrawn, ms: began.elapsed().as_secs_f64() * 1e3, from })
    };
    // The caller's stop flag (sysid_core::observer::stop_when), handed to each start's fit:
    // once set, the fits running stop at their next iteration and no start is begun.
    let stop = sysid_core::observer::current_stop();
    let stopped = || stop.as_ref().is_some_and(|s| s.requested());
    let spent = || options.budget.is_some_and(|b| started.elapsed() >= b) || stopped();
    let mut runs: Vec<(usize, Run)> = (0..rayon::current_num_threads())
        .into_par_iter()
        .map(|_| {
            let mut mine = Vec::new();
            loop {
                if spent() && next.load(Ordering::SeqCst) > 0 {
                    break;
                }
                let j = next.fetch_add(1, Ordering::SeqCst);
                if j >= starts.len() {
                    break;
                }
                let run = sysid_core::observer::stop_within(stop.clone(), || fit_start(j))?;
                observer(StartDone {
                    start: j,
                    done: done.fetch_add(1, Ordering::SeqCst) + 1,
                    total: starts.len(),
                    objective: reported_objective(&run.fit),
                    converged: run.fit.converged(),
                });
                mine.push((j, run));
            }
            Ok(mine)
        })
        .collect::<Result<Vec<_>, FitError>>()?
        .into_iter()
        .flatten()
        .collect();
    runs.sort_by_key(|r| r.0);
    let mut runs: Vec<Run> = runs.into_iter().map(|r| r.1).collect();
    let continued = match (spent(), promising(&runs)) {
        (false, Some(j)) => {
            let began = std::time::Instant::now();
            // A continuation that cannot be run (an error) or that ends higher loses nothing:
            // the start's first end stands, and its row is as before (the time spent counts in
            // the run's only).
            fit_from(&runs[j].fit.values).ok().filter(|on| kept(&runs[j].fit, on)).map(|on| {
                let run = &mut runs[j];
                run.fit.continue_with(on);
                run.ms += began.elapsed().as_secs_f64() * 1e3;
                j
            })
        }
        _ => None,
    };
    let not_started = starts.len() - runs.len();
    let redrawn = runs.iter().map(|r| r.redrawn).sum();
    let times: Vec<f64> = runs.iter().map(|r| r.ms).collect();
    // The free unknowns where each fit began, then the noise scales, which every fit starts
    // from the problem's values.
    let mut names = problem.names();
    names.extend(problem.scales().iter().map(|&j| problem.declared()[j].name.clone()));
    let scales = problem.scale_values();
    let mut from: Vec<serde_json::Map<String, serde_json::Value>> =
        runs.iter().map(|r| by_name(names.iter().cloned(), r.from.iter().chain(&scales))).collect();
    let fits: Vec<Estimate> = runs.into_iter().map(|r| r.fit).collect();
    let mut summary = summarise(&fits, options);
    summary.redrawn = redrawn;
    summary.not_started = not_started;
    summary.stopped = stopped();
    summary.elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
    summary.converged_per_minute = summary.converged as f64 / (summary.elapsed_ms / 6e4);
    for row in &mut summary.waterfall {
        row.elapsed_ms = times[row.start];
        row.start_values = std::mem::take(&mut from[row.start]);
        row.continued = continued == Some(row.start);
    }
    let best = fits.into_iter().nth(summary.best_start).expect("the best start's fit");
    Ok(Multistart { best, starts: summary })
}

/// The start fitted on once more, with its method's budget again, after every start has run:
/// the one that ran out of iterations lowest, where that is below every converged start (by
/// more than [`resolution`]), or where none converged. Its crawl was going where no other
/// start went, and one more start's budget there is worth more than another random start
/// (Okuonghae: start 48 of 100 ended at the limit at 373.561151 and certifies 373.547669 when
/// fitted on, 2.37 below the least converged start).
fn promising(runs: &[Run]) -> Option<usize> {
    let at_limit = runs
        .iter()
        .enumerate()
        .filter(|(_, r)| matches!(r.fit.termination, Termination::MaxIterations { .. }))
        .filter(|(_, r)| r.fit.objective().is_finite())
        .min_by(|a, b| a.1.fit.objective().total_cmp(&b.1.fit.objective()))?;
    let below = |r: &Run| {
        at_limit.1.fit.objective() < r.fit.objective() - resolution(&at_limit.1.fit, &r.fit)
    };
    runs.iter().filter(|r| r.fit.converged()).all(below).then_some(at_limit.0)
}

/// Whether the continuation `on` of `first` is kept: where it ended no higher, or certified
/// within [`resolution`] above (it begins at the start's point, but its noise scales begin
/// again at the problem's values). A NaN objective (a fit that panicked) is never kept.
fn kept(first: &Estimate, on: &Estimate) -> bool {
    on.objective() <= first.objective()
        || (on.converged() && on.objective() <= first.objective() + resolution(first, on))
}

/// [`Estimate::objective`] as the waterfall and [`StartDone`] report it: None where it is NaN (a fit
/// that never evaluated a cost).
fn reported_objective(f: &Estimate) -> Option<f64> {
    Some(f.objective()).filter(|v| !v.is_nan())
}

/// [`SAME_MINIMUM_RTOL`] of ε, in the objective's units: ½·rtol·ε (for known σ exactly the
/// relative rule on ε).
fn resolution(a: &Estimate, b: &Estimate) -> f64 {
    0.5 * SAME_MINIMUM_RTOL * a.cost.abs().max(b.cost.abs())
}

/// Whether two converged fits are at one minimum: objectives within [`resolution`], or
/// both exact fits (ε = 0 to rounding, where the relative difference of the costs is noise).
fn same_minimum(a: &Estimate, b: &Estimate) -> bool {
    (a.certificate.exact_fit && b.certificate.exact_fit)
        || (a.objective() - b.objective()).abs() <= resolution(a, b)
}

fn summarise(fits: &[Estimate], options: &MultistartOptions) -> Starts {
    let least = |converged: bool| {
        fits.iter()
            .enumerate()
            .filter(|(_, f)| !converged || f.converged())
            .filter(|(_, f)| !f.objective().is_nan())
            .min_by(|a, b| a.1.objective().total_cmp(&b.1.objective()))
            .map(|(i, _)| i)
    };
    let lower = |a: usize, b: usize| {
        fits[a].objective() < fits[b].objective() - resolution(&fits[a], &fits[b])
    };
    let best_start = match (least(true), least(false)) {
        (Some(c), Some(any)) if lower(any, c) => any,
        (Some(c), _) => c,
        (None, any) => any.unwrap_or(0),
    };
    let mut order: Vec<usize> = (0..fits.len()).filter(|&i| fits[i].converged()).collect();
    order.sort_by(|&a, &b| fits[a].objective().total_cmp(&fits[b].objective()).then(a.cmp(&b)));
    // A fit joins a minimum when it matches that minimum's least fit (the first in the
    // objective's order), which the minimum reports whole: its start, estimates, ε and NLL
    // belong to one fit.
    let mut minima: Vec<(usize, Minimum)> = Vec::new();
    for i in order {
        let fit = &fits[i];
        match minima.last_mut() {
            Some((least, m)) if same_minimum(fit, &fits[*least]) => m.count += 1,
            _ => minima.push((
                i,
                Minimum { cost: fit.cost, nll: fit.nll, count: 1, start: i, estimates: named(fit) },
            )),
        }
    }
    let minima = minima.into_iter().map(|(_, m)| m).collect();
    let best = &fits[best_start];
    let reached_best = if best.converged() {
        let threshold = REACHED.max(resolution(best, best));
        fits.iter()
            .filter(|f| {
                f.converged()
                    && (same_minimum(f, best) || f.objective() - best.objective() <= threshold)
            })
            .count()
    } else {
        0
    };
    let mut waterfall: Vec<Outcome> = fits
        .iter()
        .enumerate()
        .map(|(start, f)| Outcome {
            start,
            objective: reported_objective(f),
            cost: Some(f.cost).filter(|c| c.is_finite()),
            converged: f.converged(),
            termination_code: f.termination.code(),
            iterations: f.iterations,
            elapsed_ms: 0.0,
            start_values: serde_json::Map::new(),
            estimates: named(f),
            continued: false,
        })
        .collect();
    waterfall.sort_by(|a, b| {
        let key = |o: &Outcome| o.objective.unwrap_or(f64::INFINITY);
        key(a).total_cmp(&key(b)).then(a.start.cmp(&b.start))
    });
    Starts {
        count: fits.len(),
        not_started: 0,
        stopped: false,
        seed: options.seed,
        spread: options.spread,
        sampling: options.sampling,
        guess: options.guess,
        best_start,
        converged: fits.iter().filter(|f| f.converged()).count(),
        reached_best,
        redrawn: 0,
        minima,
        elapsed_ms: 0.0,
        converged_per_minute: 0.0,
        waterfall,
    }
}

/// The fit's estimates by name, the noise scales set in closed form last (as in its JSON).
fn named(fit: &Estimate) -> serde_json::Map<String, serde_json::Value> {
    by_name(
        fit.all_names().into_iter(),
        fit.values.iter().chain(fit.scales.iter().map(|s| &s.value)),
    )
}

/// Values paired with their names, as a JSON object.
fn by_name<'a>(
    names: impl Iterator<Item = String>,
    values: impl Iterator<Item = &'a f64>,
) -> serde_json::Map<String, serde_json::Value> {
    names.zip(values.map(|&v| serde_json::json!(v))).collect()
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use sysid_core::{Certificate, Failure, Rule};

    use super::*;

    /// A fit ending at `cost`, certified or not.
    fn fit(cost: f64, converged: bool) -> Estimate {
        Estimate {
            method: "m".into(),
            names: vec!["a".into()],
            values: vec![cost],
            std_errors: None,
            intervals: None,
            covariance: None,
            cost,
            dof: None,
            iterations: 1,
            best_iteration: 1,
            termination: if converged {
                Termination::Converged(Rule::Step)
            } else {
                Termination::MaxIterations { fell: None, moving: vec![], unresolved_gradient: None }
            },
            certificate: Certificate {
                optimality: if converged { 0.0 } else { 0.5 },
                error: 0.0,
                cost_error: 0.0,
                error_measured: false,
                gtol: 1e-6,
                exact_fit: false,
                active: vec![None],
                flat: vec![false],
                null_space: None,
                scales: None,
                unchecked: None,
                unresolved: false,
            },
            history: Vec::new(),
            elapsed: Duration::ZERO,
            counts: Default::default(),
            nll: None,
            prior: None,
            experiments: Vec::new(),
            scales: Vec::new(),
            noise_model: false,
            retry: None,
        }
    }

    /// A fit of a problem with estimated noise scales: ε about the number of data, ranked by
    /// its negative log-likelihood.
    fn fit_nll(cost: f64, nll: f64, converged: bool) -> Estimate {
        Estimate { nll: Some(nll), ..fit(cost, converged) }
    }

    #[test]
    fn fits_with_estimated_noise_are_ranked_by_their_likelihood() {
        // Boehm's problem with σ estimated from 20 starts: every certified fit ends at ε ≈ 48
        // (σ in closed form), at NLL 138.22 or 150.0; an unconverged one ends at ε = 47.9 but
        // NLL 147.87, worse. Ranked by ε, it was reported as the best, and the two minima
        // were one.
        let fits =
            [fit_nll(47.9, 147.87, false), fit_nll(48.0, 138.22, true), fit_nll(48.0, 150.0, true)];
        let s = summarise(&fits, &MultistartOptions::default());
        assert_eq!((s.best_start, s.reached_best, s.minima.len()), (1, 1, 2));
        assert_eq!(s.minima[0].nll, Some(138.22));
        // Lower only by noise (within ½·1e-6·ε of the objective): still the certified one.
        let fits = [fit_nll(48.0, 138.22 - 1e-5, false), fit_nll(48.0, 138.22, true)];
        assert_eq!(best(&fits), 1);
        let fits = [fit_nll(48.0, 138.22 - 1e-4, false), fit_nll(48.0, 138.22, true)];
        assert_eq!(best(&fits), 0);
    }

    /// A minimum reports one fit whole: the one that reached it lowest, a later start here.
    /// (It paired the earliest start and its estimates with the least fit's NLL.)
    #[test]
    fn a_minimum_is_the_fit_that_reached_it_lowest() {
        let fits = [
            Estimate { values: vec![1.0], ..fit_nll(48.0, 138.22 + 1e-6, true) },
            Estimate { values: vec![2.0], ..fit_nll(48.0, 138.22, true) },
        ];
        let s = summarise(&fits, &MultistartOptions::default());
        let m = &s.minima[..];
        assert_eq!((m.len(), m[0].count, m[0].start, m[0].nll), (1, 2, 1, Some(138.22)));
        assert_eq!(m[0].estimates["a"], serde_json::json!(2.0));
        assert_eq!(s.best_start, m[0].start);
    }

    /// Runs ending at these fits, for [`promising`].
    fn runs(fits: Vec<Estimate>) -> Vec<Run> {
        fits.into_iter().map(|fit| Run { fit, redrawn: 0, ms: 0.0, from: vec![] }).collect()
    }

    #[test]
    fn the_start_fitted_on_is_the_lowest_at_the_limit_below_every_converged_one() {
        let promising = |fits: Vec<Estimate>| promising(&runs(fits));
        // Below the converged start: the lowest of those at the limit.
        assert_eq!(promising(vec![fit(48.0, false), fit(50.0, true)]), Some(0));
        assert_eq!(promising(vec![fit(48.0, false), fit(47.0, false), fit(50.0, true)]), Some(1));
        // Above a converged start, or below it only within ½·1e-6·ε: none.
        assert_eq!(promising(vec![fit(50.0, false), fit(48.0, true)]), None);
        assert_eq!(promising(vec![fit(48.0, false), fit(50.0, true), fit(47.0, true)]), None);
        assert_eq!(promising(vec![fit(50.0 * (1.0 - 1e-7), false), fit(50.0, true)]), None);
        // None converged: the least of all. None at the limit, or only at NaN: none.
        assert_eq!(promising(vec![fit(48.0, false), fit(47.0, false)]), Some(1));
        assert_eq!(promising(vec![fit(48.0, true)]), None);
        assert_eq!(promising(vec![fit(f64::NAN, false), fit(50.0, true)]), None);
    }

    #[test]
    fn a_continuation_is_kept_where_it_ends_no_higher_and_then_counts_both_fits() {
        // Kept no higher, or certified within ½·1e-6·ε above; never higher, never NaN.
        assert!(kept(&fit(48.0, false), &fit(47.0, true)));
        assert!(kept(&fit(48.0, false), &fit(48.0, false)));
        assert!(kept(&fit(48.0, false), &fit(48.0 * (1.0 + 1e-7), true)));
        assert!(!kept(&fit(48.0, false), &fit(48.0 * (1.0 + 1e-7), false)));
        assert!(!kept(&fit(48.0, false), &fit(49.0, true)));
        assert!(!kept(&fit(48.0, false), &fit(f64::NAN, false)));
        // One fit of 1 000 iterations then 40, with its best iterate at the continuation's
        // 40th: iteration 1 040 of 1 041 rows, the continuation's first row in place of the
        // first fit's last (the same point).
        let rows = |n: usize, cost: f64| -> Vec<sysid_core::Iteration> {
            (0..=n)
                .map(|iteration| sysid_core::Iteration {
                    iteration,
                    cost: cost - iteration as f64 * 1e-3,
                    gradient_norm: 1.0,
                    step_norm: None,
                    condition: None,
                    optimality: None,
                    values: vec![],
                    diagnostics: Default::default(),
                })
                .collect()
        };
        let first = Estimate {
            iterations: 1000,
            best_iteration: 1000,
            history: rows(1000, 49.0),
            elapsed: Duration::from_millis(300),
            counts: sysid_ode::Counts { steps: 9000, integrations: 1500, ..Default::default() },
            ..fit(48.0, false)
        };
        let on = Estimate {
            iterations: 40,
            best_iteration: 40,
            history: rows(40, 48.0),
            elapsed: Duration::from_millis(20),
            counts: sysid_ode::Counts { steps: 400, integrations: 60, ..Default::default() },
            ..fit(47.96, true)
        };
        let mut fit = first;
        fit.continue_with(on);
        assert_eq!((fit.iterations, fit.best_iteration, fit.history.len()), (1040, 1040, 1041));
        assert!(fit.history.iter().enumerate().all(|(i, row)| row.iteration == i));
        assert_eq!((fit.history[999].cost, fit.history[1000].cost), (49.0 - 0.999, 48.0));
        assert_eq!(fit.elapsed, Duration::from_millis(320));
        assert_eq!((fit.counts.steps, fit.counts.integrations), (9400, 1560));
        assert!(fit.converged());
    }

    /// A continuation's termination names its iteration on the whole fit's count: Crauste's
    /// start 2 (goodman, `--starts 5 --max-iterations 3`) said "failed stepping from
    /// iteration 1" after 4 iterations, its continuation's own count.
    #[test]
    fn a_continuations_termination_counts_the_whole_fits_iterations() {
        let failure = Failure::NonFinite { what: "ε is not finite".into(), at: vec![1.0] };
        let on = Estimate {
            termination: Termination::Failed { iteration: 1, failure },
            ..fit(47.0, false)
        };
        let mut fit = Estimate { iterations: 3, best_iteration: 3, ..fit(48.0, false) };
        fit.continue_with(on);
        assert_eq!(fit.iterations, 4);
        assert!(matches!(fit.termination, Termination::Failed { iteration: 4, .. }));
        assert!(fit.termination.to_string().starts_with("failed stepping from iteration 4:"));
    }

    fn best(fits: &[Estimate]) -> usize {
        summarise(fits, &MultistartOptions::default()).best_start
    }

    #[test]
    fn a_certified_point_is_not_the_best_when_a_lower_one_was_found() {
        // A certified corner at 7846 and a fit that ran out of iterations at 48: the lower.
        assert_eq!(best(&[fit(7846.0, true), fit(48.0, false), fit(7846.0, true)]), 1);
        // Lower only by noise (within 1e-6 relative): the certified one.
        assert_eq!(best(&[fit(48.0 * (1.0 + 1e-7), false), fit(48.0, true)]), 1);
        assert_eq!(best(&[fit(48.0 * (1.0 - 1e-7), false), fit(48.0, true)]), 1);
        // The least certified cost otherwise; the least of all when none is certified.
        assert_eq!(best(&[fit(50.0, true), fit(60.0, false), fit(48.0, true)]), 2);
        assert_eq!(best(&[fit(50.0, false), fit(f64::NAN, false), fit(49.0, false)]), 2);
        // The minima are the certified fits only, and `reached_best` is 0 when the best is
        // not certified.
        let s = summarise(&[fit(7846.0, true), fit(48.0, false)], &MultistartOptions::default());
        assert_eq!((s.minima.len(), s.reached_best, s.converged), (1, 0, 1));
    }
}
