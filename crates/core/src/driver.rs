//! The iteration driver every method uses, in the spirit of argmin's executor: the problem,
//! the method's step, the state of the run and the record of it are kept apart. A method
//! supplies only its [`Step`] (Goodman's Newton step, the quasilinearization step, the
//! argmin adapter); the driver owns the loop, the history, the iteration and integration
//! budgets, the step test, the best iterate, the certificate at the returned point and the
//! assembly of the [`Estimate`].
//!
//! At each iterate, in order: record it; stop if ε = 0 exactly ([`Rule::ExactFit`]) or if
//! the first-order optimality there is below the gradient tolerance ([`Rule::Gradient`],
//! where the method computed the model's sensitivities at the iterate), or if ε fell by less
//! than 1e-6 of itself over the last 100 iterations ([`Rule::Progress`]: a crawl, whose
//! termination names the unknowns still moving), or if the measure is within gtol and ε fell
//! by less than 1e-8 of itself over the last 10 ([`Rule::Settled`]: a minimum to the promised
//! accuracy that further steps no longer lower; it stops the run where the certificate
//! holds, and elsewhere only once the extra steps after an earlier rule are used up); ask the
//! method for a
//! proposal (a failure, such as a singular matrix, ends the run); stop on the method's own
//! rule or when the proposed step is below the step tolerance ([`Rule::Step`]); stop at the
//! iteration budget; let the method move (a failure ends the run; halving or a line search
//! may stop it with [`Rule::NoDescent`]).
//!
//! A run that stops on a rule returns the iterate the rule judged; any other ending (a
//! failure, a budget) returns the best iterate so far, with its history. Either way the
//! certificate is computed at the returned point and decides `converged`: a rule without the
//! certificate is [`Termination::Stalled`].
//!
//! Noise scales (σ = s·f of a series, s an unknown used for nothing else) are not moved by
//! the method: the driver holds them while the method fits the rest, then sets each to its
//! closed form given the rest, ŝ² = mean over its samples of ((T(h) − T(b))/f)² (clamped to
//! its bounds), and lets the method fit again from where it stopped (hierarchical
//! optimisation, Loos et al., Bioinformatics 2018). The rounds end when a round's fit is
//! certified and the scales move by less than 1e-3·gtol relative; the scales' part of the
//! certificate is that relative move. A round at held scales also ends, uncertified, where
//! moving the scales that would shrink gains far more than its last iterations did
//! ([`HAND_OVER`]): the next round goes on from there.
use std::time::Instant;

use sysid_ode::System;

use crate::assemble::{Ending, Record, is_better, returns_best};
use crate::certificate::{onto_bounds, optimality};
use crate::error::FitError;
use crate::estimate::{Estimate, Iteration};
use crate::evaluations::{COARSE_RTOL, Evaluations, coarser};
use crate::method::start_coordinates;
use crate::options::DriverOptions;
use crate::problem::Problem;
use crate::step::{Advance, Iterate, Step};
use crate::termination::{
    Failure, PROGRESS, PROGRESS_WINDOW, Rule, SETTLE, SETTLE_WINDOW, Termination,
};

/// Runs `step` from `start` (values of the free unknowns) on `problem` and returns the
/// estimate of method `method`. `Err` only for misuse: invalid options or start.
pub fn drive<S: System>(
    problem: &Problem<S>,
    method: &str,
    options: &DriverOptions,
    step: &mut impl Step<S>,
    start: &[f64],
) -> Result<Estimate, FitError> {
    options.validate()?;
    if problem.scales().is_empty() {
        return drive_once(problem, method, options, step, start, (false, true, 0), false)
            .map(|(e, ..)| e);
    }
    let gtol = options.gtol_for(problem.integrator().rtol);
    let mut sigma = problem.scale_values();
    let mut z = start.to_vec();
    let mut rounds: Vec<Estimate> = Vec::new();
    // The hard budget of the whole fit, which its rounds share.
    let budget = options.integration_budget(problem.unknowns().len(), problem.experiments().len());
    // The fit's first scales, which every round's history is measured on.
    let first = Profile::new(problem, true);
    let started = Instant::now();
    loop {
        let used: usize = rounds.iter().map(|e| e.iterations).sum();
        let spent: u64 = rounds.iter().map(|e| e.counts.integrations).sum();
        let round_options = DriverOptions {
            max_iterations: options.max_iterations.saturating_sub(used),
            max_integrations: Some(budget.saturating_sub(spent).max(1)),
            max_seconds: options
                .max_seconds
                .map(|s| (s - started.elapsed().as_secs_f64()).max(0.0)),
            ..*options
        };
        // The first round holds the scales where they start; the rounds after it, where the
        // method profiles, are one run at the closed form of every iterate.
        let profiles = step.profiles() && !rounds.is_empty();
        // Only the first round integrates coarsely first: the later ones start near a minimum.
        let (mut estimate, ended, profiled, handed_over) = drive_once(
            &problem.with_scales(&sigma),
            method,
            &round_options,
            step,
            &z,
            (profiles, rounds.is_empty(), used),
            !profiles && rounds.len() + 1 < MAX_ROUNDS,
        )?;
        on_first_scales(&first, &sigma, &mut estimate);
        // A round that ran out of integrations names the fit's budget, not what was left of it.
        if let Termination::IntegrationBudget { integrations } = &mut estimate.termination {
            *integrations = budget;
        }
        if let Some(moved) = profiled {
            // Hierarchical optimisation: one run, at the closed form of the point it returns.
            let held = problem.with_scales(&ended);
            rounds.push(estimate);
            return Ok(crate::assemble::with_scales(problem, &held, rounds, moved, false));
        }
        let held = problem.with_scales(&sigma);
        let next = held.optimal_scales(&estimate.values);
        let moved = next.as_ref().map_or(f64::INFINITY, |next| {
            next.iter().zip(&sigma).map(|(a, b)| (a / b).ln().abs()).fold(0.0, f64::max)
        });
        // Where the returned point cannot be evaluated again at the held scales (`next` is
        // None), there is no closed form to move to: the rounds end there, the scales
        // unsettled (`moved` ∞), rather than at a panic.
        let out_of_iterations = estimate.iterations >= round_options.max_iterations;
        let last = estimate.start_failed()
            || next.is_none()
            || !(estimate.converged() || handed_over)
            || moved <= 1e-3 * gtol
            || out_of_iterations
            || matches!(
                estimate.termination,
                Termination::TimeLimit { .. }
                    | Termination::Interrupted
                    | Termination::IntegrationBudget { .. }
            )
            // The budget has no room for another round's first evaluation.
            || spent + estimate.counts.integrations + problem.experiments().len() as u64 > budget
            || rounds.len() + 1 >= MAX_ROUNDS;
        rounds.push(estimate);
        if last {
            let e = crate::assemble::with_scales(problem, &held, rounds, moved, out_of_iterations);
            return Ok(e);
        }
        sigma = next.expect("a round whose scales cannot be formed is the last");
        z = rounds.last().expect("a round").values.clone();
    }
}

/// A round's history measured as the first round's: a round run at the scales `sigma`
/// records ε at them (or, profiling, ε + 2 Σ_g n_g ln(ŝ_g/σ_g)); adding 2 Σ_g n_g
/// ln(σ_g/s_g) ([`Profile::shift`] from `first`, the fit's first scales s) makes every row
/// ε + 2 Σ_g n_g ln(σ̂_g/s_g) at the scales σ̂ it was evaluated at: twice the NLL up to one
/// constant for the whole fit, so that the rows of different rounds compare (the first row
/// with the last, say).
fn on_first_scales(first: &Profile, sigma: &[f64], estimate: &mut Estimate) {
    let shift = first.shift(sigma);
    if shift != 0.0 {
        for row in &mut estimate.history {
            row.cost += shift;
        }
    }
}

/// `f` with the integrations [paced](Evaluations::pace) at the work of `current`'s
/// linearization, where the method `retreats` from failed trials ([`Step::retreats`]) and
/// `current` has one.
fn paced<S: System, T>(
    ev: &mut Evaluations<'_, S>,
    retreats: bool,
    current: &Iterate,
    f: impl FnOnce(&Evaluations<'_, S>) -> T,
) -> T {
    let work = current.linearization.as_ref().filter(|_| retreats).map(|l| l.counts);
    ev.pace(work.as_ref());
    let out = f(ev);
    ev.pace(None);
    out
}

/// The most rounds of fits between closed-form updates of the noise scales.
const MAX_ROUNDS: usize = 50;

/// A round at held noise scales ends, uncertified, once moving the scales whose closed
/// form is below their held value would lower ε by more than this many times what the
/// round's last [`SETTLE_WINDOW`] iterations did (and than ε's integration error, rtol·ε):
/// the round then crawls where the scales have more to give (the data fitted far more
/// closely than the held σ say: Giordano's residuals of 1e-5 at σ = 1 took 1 000
/// iterations of a first round that lowered the NLL by 5e-7 while its σ, estimated, stood
/// still). Scales that would grow do not count for it, and hold the round where they would
/// gain more than a tenth of that: far from the data their closed form flattens the
/// landscape, which is why the first round holds them (methods.md, hierarchical
/// optimisation; Alkan from nominal, where some series were fitted far too closely and
/// others far too loosely, ended in a local minimum 12.5 higher when they did not hold it).
/// The last round allowed ([`MAX_ROUNDS`]) never hands over: it ends the fit, whose
/// termination would then name a rule that did not fire.
const HAND_OVER: f64 = 10.0;

/// One run of `step` at the problem's noise scales, or, where the method
/// [profiles](Step::profiles), with the scales set to their closed form at every iterate;
/// integrated [coarsely first](Step::coarse_first) where the method asks and `coarse`;
/// its iterations are told to the [observer](crate::observer) from `counted` on.
/// Returns the estimate, the scales of the point it returns, when it profiled, the
/// scales' part of the certificate there (the largest relative change, |ln(σ̂/σ)|, that
/// their closed form from the point's own linearization would make), and whether it
/// [handed over](HAND_OVER) to the scales' closed form (only where `hands_over`: a round at
/// held scales).
#[allow(clippy::type_complexity)]
fn drive_once<S: System>(
    problem: &Problem<S>,
    method: &str,
    options: &DriverOptions,
    step: &mut impl Step<S>,
    start: &[f64],
    (profiles, coarse, counted): (bool, bool, usize),
    hands_over: bool,
) -> Result<(Estimate, Vec<f64>, Option<f64>, bool), FitError> {
    let started = Instant::now();
    let z0 = start_coordinates(problem, start)?;
    let mut ev = Evaluations::new(
        problem,
        options.integration_budget(problem.unknowns().len(), problem.experiments().len()),
    );
    // Coarse first: `ev` integrates at the coarse tolerances until the stage ends
    // (`end_coarse`), then at the problem's own.
    let mut coarse = coarse && options.coarse_first && step.coarse_first() && {
        match coarser(problem.integrator()).map(|c| problem.clone().with_integrator(c)) {
            Some(Ok(p)) => {
                ev.refine(p);
                true
            }
            _ => false,
        }
    };
    let retreats = step.retreats();
    let gtol = options.gtol_for(problem.integrator().rtol);
    let record = Record { method, options, gtol, started };
    let profile = Profile::new(problem, profiles);
    if profile.on() {
        ev.profile_scales();
    }
    let mut first = step.start(&ev, z0.clone());
    if coarse && first.is_err() {
        // Where the coarse integration fails at the start, the problem's own may not.
        coarse = false;
        ev.refine(problem.clone());
        first = step.start(&ev, z0.clone());
    }
    let mut current = match first {
        Ok(start) => profile.apply(&mut ev, start),
        Err(failure) => {
            let moved = profile.on().then_some(f64::INFINITY);
            let failed = record.start_failed(&ev, z0, failure);
            return Ok((failed, problem.scale_values(), moved, false));
        }
    };
    // The scales of the current iterate and of the best so far.
    let mut scales = ev.problem().scale_values();
    let mut best_scales = scales.clone();
    let step_tolerance = problem.resolvable_step(options.step_tolerance);
    let mut history: Vec<Iteration> = Vec::new();
    let mut best: Option<(usize, Iterate)> = None;
    let (mut iteration, mut step_norm, mut pending) = (0, None, None);
    // Steps taken past a stopping rule that fired where the certificate fails, and the
    // certificate of the iterate the last rule stopped at.
    let (mut extra, mut verdict) = (0, None);
    // The first iteration at which the settled rule may be judged (again).
    let mut settle_from = SETTLE_WINDOW;
    // Whether the undetermined unknowns near a bound were moved onto it (once a run).
    let mut onto_bound = false;
    let mut precision = Precision::default();
    // Whether the round ended to let the scales move (`hands_over`).
    let mut handed_over = false;
    // The first row of the history that the crawl and settled rules look back to: the
    // coarse stage's costs do not compare with the problem's own to their accuracy.
    let mut window_from = 0;
    // The coarse stage closes in on a minimum once the measure is within the gtol its
    // tolerances support.
    let coarse_gtol = DriverOptions { gtol: None, ..*options }.gtol_for(COARSE_RTOL).max(gtol);
    // Ends the coarse stage: `current` evaluated again at the problem's own tolerances (at
    // the run's scales), from which the run goes on afresh (its history row, recorded at the
    // coarse tolerances, is recorded again); where it cannot be integrated
    // there (a blow-up near the end that the coarse integration did not see), the run
    // begins again from its start; `Some` failure where that fails too. (`final`: the run
    // ends there, and only the point and the best are of use.) The stage is over where it
    // succeeds.
    macro_rules! end_coarse {
        (final) => {{
            ev.refine(problem.with_scales(&ev.problem().scale_values()));
            let again = match step.restart(&ev, &current) {
                Err(failure) if !matches!(failure, Failure::Budget { .. }) => {
                    step.start(&ev, z0.clone())
                }
                again => again,
            };
            match again {
                Ok(again) => {
                    current = profile.apply(&mut ev, again);
                    scales = ev.problem().scale_values();
                    best = None;
                    coarse = false;
                    None
                }
                Err(failure) => Some(failure),
            }
        }};
        () => {{
            history.pop();
            // (Where it fails, `coarse` stays: the run ends, and its point is judged at the
            // problem's tolerances below.)
            let failed = end_coarse!(final);
            window_from = history.len();
            settle_from = iteration + SETTLE_WINDOW;
            failed
        }};
    }
    // Goes on from `current` at the finer integration `finer`: the method restarts there, and
    // the iterate's history row is recorded again; `Some` failure where the restart fails.
    macro_rules! go_finer {
        ($finer:expr) => {{
            ev.refine($finer);
            match step.restart(&ev, &current) {
                Ok(again) => {
                    current = profile.apply(&mut ev, again);
                    scales = ev.problem().scale_values();
                    history.pop();
                    None
                }
                Err(failure) => Some(failure),
            }
        }};
    }
    let ending = 'run: loop {
        let mut measure =
            current.linearization.as_ref().map(|l| optimality(ev.problem(), l, gtol).value);
        // Closing in and no longer gaining: is the measure accurate enough to be tested?
        if let Some(m) = measure
            && !coarse
            && precision.due(m, gtol, ev.problem().integrator().rtol)
            && let Some(finer) = precision.check(&ev, &current.z, m, gtol)
        {
            ev.refine(finer);
            current = match step.restart(&ev, &current) {
                Ok(again) => profile.apply(&mut ev, again),
                Err(failure) => break Ending::Failed { iteration, failure },
            };
            scales = ev.problem().scale_values();
            measure =
                current.linearization.as_ref().map(|l| optimality(ev.problem(), l, gtol).value);
        }
        precision.previous = measure;
        history.push(Iteration {
            iteration,
            cost: current.cost,
            gradient_norm: current.gradient_norm.unwrap_or(f64::NAN),
            step_norm,
            condition: None,
            optimality: measure,
            values: problem.unknowns().values(&current.z),
            diagnostics: current.diagnostics.clone(),
        });
        // ε at the iterate (under hierarchical optimisation the iterate's cost is the
        // profile's, which compares between iterates; ε is what an exact fit and the crawl's
        // scale are judged by).
        let epsilon = current.epsilon();
        if crate::observer::listening() {
            let p = ev.problem();
            let objective = current
                .linearization
                .as_ref()
                .and_then(|l| Some(p.nll(l)? + p.prior_nll(l).unwrap_or(0.0)));
            crate::observer::report(&crate::observer::IterateReport {
                method,
                iteration: counted + iteration,
                objective,
                cost: epsilon,
                optimality: measure,
                coarse,
            });
        }
        if epsilon == 0.0 {
            break Ending::Rule(Rule::ExactFit);
        }
        let gradient = measure.is_some_and(|m| m <= options.gradient_tolerance.min(gtol));
        // Whether ε fell by less than `share` of itself over the last `window` iterations
        // (of the stage the run is in).
        let fell_less = |window: usize, share: f64| {
            history.len() > window_from + window && {
                let then = history[history.len() - 1 - window].cost;
                then.is_finite()
                    && current.cost.is_finite()
                    && then - current.cost <= share * epsilon.abs()
            }
        };
        // A crawl: ε fell by less than PROGRESS of itself over the last PROGRESS_WINDOW
        // iterations.
        let crawled = fell_less(PROGRESS_WINDOW, PROGRESS);
        // Settled: the measure is within gtol and ε fell by less than SETTLE of itself over
        // the last SETTLE_WINDOW iterations (the run no longer gains; judged like any rule,
        // but where the certificate fails it does not count against the extra steps).
        let settled = iteration >= settle_from
            && measure.is_some_and(|m| m <= gtol)
            && fell_less(SETTLE_WINDOW, SETTLE);
        // The coarse stage's own settled rule, at the accuracy its tolerances support: the
        // measure within their gtol and ε falling by less than COARSE_SETTLE of itself over
        // the last SETTLE_WINDOW iterations. (The measure alone is small on a plateau at a
        // start, where the trust region has yet to find the descent.)
        let coarse_settled = coarse
            && measure.is_some_and(|m| m <= coarse_gtol)
            && fell_less(SETTLE_WINDOW, COARSE_SETTLE);
        // (The gradient and settled rules judge at the problem's own accuracy: the coarse
        // stage has its own settled rule. On a plateau at a start the measure is 0.)
        let mut fired = pending
            .take()
            .or((gradient && !coarse).then_some(Rule::Gradient))
            .or(crawled.then_some(Rule::Progress))
            .or((settled && !coarse).then_some(Rule::Settled));
        // At held scales: where one move of the tightening scales to their closed form
        // gains more than HAND_OVER times what the last SETTLE_WINDOW iterations did, and
        // than the loosening ones would, the round ends here and the scales move (the next
        // round goes on from this point).
        // (In the coarse stage too, whose gains and falls compare at its own tolerances: the
        // point is then evaluated again at the problem's.)
        if fired.is_none()
            && hands_over
            && history.len() > window_from + SETTLE_WINDOW
            && let Some(lin) = &current.linearization
        {
            let then = history[history.len() - 1 - SETTLE_WINDOW].cost;
            let (tightening, loosening) = ev.problem().split_gain(lin);
            let fall = (then - current.cost).max(0.0);
            // (A gain within ε's integration error is none: the round stalled, it did not
            // crawl past a gain.)
            let resolution = ev.problem().integrator().rtol * epsilon.abs();
            if then.is_finite() && tightening > HAND_OVER * fall.max(loosening).max(resolution) {
                if coarse && let Some(failure) = end_coarse!(final) {
                    break Ending::Failed { iteration, failure };
                }
                handed_over = true;
                break Ending::Rule(Rule::Progress);
            }
        }
        let mut proposal = None;
        if fired.is_none() && !coarse_settled {
            let p = match paced(&mut ev, retreats, &current, |ev| step.propose(ev, &current)) {
                Ok(p) => p,
                Err(failure) if coarse && !matches!(failure, Failure::Budget { .. }) => {
                    match end_coarse!() {
                        None => continue 'run,
                        Some(failure) => break Ending::Failed { iteration, failure },
                    }
                }
                Err(failure) => break Ending::Failed { iteration, failure },
            };
            if let Some(row) = history.last_mut() {
                row.condition = p.condition;
                if let Some(g) = p.gradient_norm {
                    row.gradient_norm = g;
                }
            }
            let small =
                distance(&p.z, &current.z) <= step_tolerance * (norm(&current.z) + step_tolerance);
            fired = p.stop.or(small.then_some(Rule::Step));
            proposal = Some(p);
        }
        if coarse && (fired.is_some() || coarse_settled) {
            // The coarse stage is over: the rules judge at the problem's own tolerances.
            match end_coarse!() {
                None => continue 'run,
                Some(failure) => break Ending::Failed { iteration, failure },
            }
        }
        if let Some(rule) = fired {
            // A stopping rule: the certificate judges the point. Where it fails because the
            // integration is not accurate enough to tell, the run goes on at a finer one.
            let judged = record.judge(&ev, &current);
            // An undetermined unknown within a hair of its bound: onto it, once, where the
            // cost does not rise beyond what the move's size allows.
            if !judged.1.holds()
                && !onto_bound
                && !judged.1.unresolved
                && let Some(lin) = &current.linearization
                && let Some(z) = onto_bounds(ev.problem(), lin, gtol)
            {
                onto_bound = true;
                let moved = step
                    .restart(&ev, &Iterate::new(z, f64::NAN))
                    .map(|moved| profile.apply(&mut ev, moved));
                match moved {
                    Ok(moved) if moved.cost - current.cost <= 2.0 * gtol * epsilon.abs() => {
                        step_norm = Some(distance(&moved.z, &current.z));
                        let previous = std::mem::replace(&mut current, moved);
                        let previous_scales =
                            std::mem::replace(&mut scales, ev.problem().scale_values());
                        if is_better(&previous, best.as_ref().map(|b| &b.1)) {
                            best = Some((iteration, previous));
                            best_scales = previous_scales;
                        }
                        iteration += 1;
                        continue 'run;
                    }
                    // Where the move is felt after all, the method goes on from where it
                    // was, its state evaluated there again (at its own scales).
                    _ => {
                        if profile.on() {
                            ev.set_scales(&scales);
                        }
                        match step.restart(&ev, &current) {
                            Ok(again) => current = profile.apply(&mut ev, again),
                            Err(failure) => break Ending::Failed { iteration, failure },
                        }
                    }
                }
            }
            // Where the point passes the first-order test but the integration at a tenth of
            // the tolerances fails there, going on at it would fail at once: the point is
            // reported, its check unmade. Where it fails the test as well, the extra steps
            // go on as for any failing point.
            if judged.1.holds() || extra >= EXTRA_STEPS || judged.1.unconfirmed() {
                verdict = Some(judged);
                break Ending::Rule(rule);
            }
            if ((judged.1.unchecked.is_none() && judged.1.error > ACCURATE * gtol)
                || unresolved(&judged.1, gtol, epsilon))
                && let Some(finer) = ev.finer()
            {
                match go_finer!(finer) {
                    None => continue 'run,
                    Some(failure) => break Ending::Failed { iteration, failure },
                }
            }
            if rule == Rule::Settled {
                settle_from = iteration + SETTLE_WINDOW;
            } else {
                extra += 1;
            }
        }
        // The budgets and the caller's stop end the run where it is (the coarse stage ended
        // first, at the problem's tolerances).
        let limit = options.max_seconds.filter(|&s| started.elapsed().as_secs_f64() >= s);
        let ended = if iteration >= options.max_iterations {
            Some(Ending::MaxIterations)
        } else if let Some(limit) = limit {
            Some(Ending::TimeLimit(limit))
        } else {
            crate::observer::stop_requested().then_some(Ending::Interrupted)
        };
        if let Some(ending) = ended {
            if coarse && let Some(failure) = end_coarse!(final) {
                break Ending::Failed { iteration, failure };
            }
            break ending;
        }
        let proposal = match proposal {
            Some(p) => p,
            None => match paced(&mut ev, retreats, &current, |ev| step.propose(ev, &current)) {
                Ok(p) => p,
                Err(failure) => break Ending::Failed { iteration, failure },
            },
        };
        let next =
            match paced(&mut ev, retreats, &current, |ev| step.advance(ev, &current, proposal)) {
                Ok(Advance::Moved(next)) => next,
                Ok(Advance::MovedThenStop(next, rule)) => {
                    pending = Some(rule);
                    next
                }
                Ok(Advance::Stop(_)) if coarse => match end_coarse!() {
                    None => continue 'run,
                    Some(failure) => break Ending::Failed { iteration, failure },
                },
                Err(failure) if coarse && !matches!(failure, Failure::Budget { .. }) => {
                    match end_coarse!() {
                        None => continue 'run,
                        Some(failure) => break Ending::Failed { iteration, failure },
                    }
                }
                Ok(Advance::Stop(rule)) => {
                    // The method's own stop, where its trials were judged on differences of
                    // costs the integration does not resolve: on at a finer integration.
                    let judged = record.judge(&ev, &current);
                    if !judged.1.holds()
                        && unresolved(&judged.1, gtol, epsilon)
                        && let Some(finer) = ev.finer()
                    {
                        match go_finer!(finer) {
                            None => continue 'run,
                            Some(failure) => break Ending::Failed { iteration, failure },
                        }
                    }
                    verdict = Some(judged);
                    break Ending::Rule(rule);
                }
                Err(failure) => break Ending::Failed { iteration, failure },
            };
        let next = profile.apply(&mut ev, next);
        step_norm = Some(distance(&next.z, &current.z));
        let previous = std::mem::replace(&mut current, next);
        let previous_scales = std::mem::replace(&mut scales, ev.problem().scale_values());
        if is_better(&previous, best.as_ref().map(|b| &b.1)) {
            best = Some((iteration, previous));
            best_scales = previous_scales;
        }
        iteration += 1;
    };
    // A run that ended within the coarse stage (its integration budget used up there, or a
    // failure the stage could not hand over) reports its point at the problem's own
    // tolerances, as every other run does: the coarse figures (rtol 1e-6) are not the
    // problem's, and their error, measured at a tenth of the coarse tolerances, did not
    // cover the difference (Boehm stopped by `--max-integrations 1`: an NLL 8.0e-6 from the
    // problem's, its error given as 6.9e-6). The point is integrated again outside the
    // budget, as the certificate's own integrations are.
    if coarse {
        ev.refine(problem.with_scales(&ev.problem().scale_values()));
        current.linearization = None;
        if let Some((_, b)) = &mut best {
            b.linearization = None;
        }
    }
    // The estimate is assembled at the scales of the point it returns, which is chosen here
    // as `finish` chooses it: a rule's iterate is judged at its own scales (those `ev` holds
    // now) before any switch to the best iterate's.
    if matches!(ending, Ending::Rule(_)) && verdict.is_none() {
        verdict = Some(record.judge(&ev, &current));
    }
    let returned = match &best {
        Some((_, b)) if returns_best(&ending, verdict.as_ref(), &current, Some(b)) => {
            scales = best_scales;
            ev.set_scales(&scales);
            b
        }
        _ => &current,
    };
    let moved = profile.on().then(|| {
        let closed = returned.linearization.as_ref().and_then(|l| ev.problem().scales_at(l));
        closed.map_or(f64::INFINITY, |c| {
            c.iter().zip(&scales).map(|(a, b)| (a / b).ln().abs()).fold(0.0, f64::max)
        })
    });
    let estimate = record.finish(&ev, (iteration, current, verdict), best, ending, history);
    Ok((estimate, scales, moved, handed_over))
}

/// Hierarchical optimisation (Loos et al., Bioinformatics 2018) for a method that
/// [profiles](Step::profiles): at every iterate the noise scales are set to their closed form
/// given the rest, ŝ_g² = mean of its rows' ((T(h) − T(b))/f)², from the iterate's own
/// residuals, and its linearization is re-weighted to them without an integration. The
/// method then minimises the profile NLL(z, ŝ(z)): each trial is judged at the current
/// iterate's scales, where ε falls only if the NLL does, and moving the scales to the trial's
/// closed form lowers the NLL further. The gradient of the profile is U at ŝ(z) (the scales'
/// own gradient vanishes there), so the certificate reads it as it is. An iterate's cost is
/// then ε + 2 Σ_g n_g ln(ŝ_g/s_g), s the scales the run started at, n_g the rows of scale g:
/// twice the NLL up to a constant, so that iterates at different scales compare.
struct Profile {
    /// The scales at the start and the rows of each; empty where the driver does not profile.
    start: Vec<(f64, f64)>,
}

impl Profile {
    fn new<S: System>(problem: &Problem<S>, profiles: bool) -> Self {
        let start = match profiles {
            true => problem
                .scale_values()
                .into_iter()
                .zip(problem.scale_samples())
                .map(|(s, n)| (s, n as f64))
                .collect(),
            false => Vec::new(),
        };
        Self { start }
    }

    /// Whether the driver profiles the scales.
    fn on(&self) -> bool {
        !self.start.is_empty()
    }

    /// `it` at the closed-form scales of its residuals (which `ev` evaluates at from now on).
    fn apply<S: System>(&self, ev: &mut Evaluations<'_, S>, it: Iterate) -> Iterate {
        if !self.on() {
            return it;
        }
        let Some(lin) = &it.linearization else { return it };
        let Some(sigma) = ev.problem().scales_at(lin) else { return it };
        if sigma == ev.problem().scale_values() {
            let shift = self.shift(&sigma);
            return Iterate { cost: it.cost + shift, ..it };
        }
        let lin = ev.problem().reweighed(lin, &sigma);
        ev.set_scales(&sigma);
        let mut out = Iterate::linearized(lin);
        out.cost += self.shift(&sigma);
        out.diagnostics = it.diagnostics;
        out
    }

    /// 2 Σ_g n_g ln(σ_g/s_g): what the scales at `sigma` add to twice the NLL beyond ε.
    fn shift(&self, sigma: &[f64]) -> f64 {
        sigma.iter().zip(&self.start).map(|(s, &(s0, n))| 2.0 * n * (s / s0).ln()).sum()
    }
}

/// The coarse stage of a [coarse-first](Step::coarse_first) run has settled where ε fell by
/// less than this share of itself over the last [`SETTLE_WINDOW`] iterations (with the
/// measure within the coarse tolerances' gtol): 100 times what they resolve.
const COARSE_SETTLE: f64 = 100.0 * COARSE_RTOL;

/// The measure's integration error counts as well below gtol under this share of it.
const ACCURATE: f64 = 0.1;

/// Whether a point that fails the certificate's first-order test (no unknown undetermined)
/// is one where the integration does not resolve the progress left: the decrease of ε that
/// the measure m says a step can still make, about m²·ε (the residual's share along the
/// columns), is less than 1/[`ACCURATE`] times the cost's integration error. A trust
/// region's trials there are judged on differences of costs that are mostly that error, and
/// the run stops short of the minimum (Borghans' oscillator at rtol 1e-8: m = 1.25e-4, NLL
/// −123.387, a certified minimum at −123.685 beyond it).
fn unresolved(c: &crate::Certificate, gtol: f64, epsilon: f64) -> bool {
    // A check that could not be integrated resolves nothing: its cost error is ∞, and a
    // finer integration fails at the same point. Where the integration does not resolve the
    // model at all ([`Certificate::unresolved`](crate::Certificate::unresolved)), a finer
    // one is the only way on.
    c.unchecked.is_none()
        && (c.unresolved
            || (!c.has_undetermined()
                && c.optimality > gtol
                && c.optimality.is_finite()
                && c.cost_error > ACCURATE * c.optimality.powi(2) * epsilon.abs()))
}

/// The measure counts as closing in below this multiple of gtol.
const CLOSING: f64 = 100.0;

/// The driver's watch on the accuracy of the optimality measure during a run: once the
/// measure is within [`CLOSING`]·gtol and no longer falls tenfold per iteration (a fit
/// converging quadratically never pauses there), it is measured again at a tenth of the
/// tolerances; when the two differ by more than [`ACCURATE`]·gtol, the run goes on at the
/// finer tolerances (from the same point), and is watched again there.
#[derive(Default)]
struct Precision {
    /// The measure at the previous iterate.
    previous: Option<f64>,
    /// The rtol whose accuracy was found sufficient.
    accurate_at: Option<f64>,
}

impl Precision {
    fn due(&self, m: f64, gtol: f64, rtol: f64) -> bool {
        m <= CLOSING * gtol
            && self.previous.is_none_or(|p| m > 0.1 * p)
            && self.accurate_at != Some(rtol)
    }

    /// Measures the error at z; returns the finer problem when it should be used.
    fn check<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        z: &[f64],
        m: f64,
        gtol: f64,
    ) -> Option<Problem<S>> {
        let rtol = ev.problem().integrator().rtol;
        if ev.counts().integrations >= ev.budget() {
            return None;
        }
        let Some(finer) = ev.finer() else {
            self.accurate_at = Some(rtol);
            return None;
        };
        let Ok(fine) = finer.linearize(z) else {
            self.accurate_at = Some(rtol);
            return None;
        };
        ev.add(fine.counts);
        let error = (m - optimality(&finer, &fine, gtol).value).abs();
        if error > ACCURATE * gtol {
            Some(finer)
        } else {
            self.accurate_at = Some(rtol);
            None
        }
    }
}

/// How many more steps a method may take after its stopping rule fired at a point that fails
/// the certificate. A step rule floored at the integrator's rtol can fire one or two Newton
/// steps early on an ill-conditioned problem (robertson's ln-rates near 17: a step of 2e-7
/// relative with a cosine still at 5e-6); a method that has truly stalled stays stalled.
const EXTRA_STEPS: usize = 3;
fn norm(z: &[f64]) -> f64 {
    z.iter().map(|v| v * v).sum::<f64>().sqrt()
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}
