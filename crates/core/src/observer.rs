//! A fit's progress while it runs: an observer, set on the calling thread around the fit
//! ([`observe`]), hears of every iterate the driver records; a trial observer
//! ([`observe_trials`]) of every trial step a trust-region method judges.
//!
//! A fit of a large problem runs for hours (Chen's 155 unknowns take about a minute an
//! iteration); the observer is how a program shows where it is. The driver runs on the
//! thread that called the method, so an observer set there hears the whole fit; fits run
//! on other threads (the starts of a multistart, on rayon) do not call it.
//!
//! ```
//! use std::cell::Cell;
//! use std::rc::Rc;
//! use sysid_core::observer::{IterateReport, observe};
//!
//! let seen = Rc::new(Cell::new(0));
//! let count = Rc::clone(&seen);
//! let answer = observe(move |_: &IterateReport| count.set(count.get() + 1), || 42);
//! assert_eq!((answer, seen.get()), (42, 0)); // no fit ran, so no iterate was heard of
//! ```

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::LocalKey;

/// An iterate of a running fit, as the driver records it.
#[derive(Clone, Debug, PartialEq)]
pub struct IterateReport<'a> {
    /// The method's name.
    pub method: &'a str,
    /// Updates before this iterate, counted over the noise scales' rounds (a round goes on
    /// from the iterations of the ones before it). The same iteration can be heard of twice:
    /// where the driver integrates the iterate again at finer tolerances, at the end of
    /// the coarse stage, and at the start of each round after the first.
    pub iteration: usize,
    /// The objective the fit minimises at the iterate: the negative log-likelihood plus the
    /// priors' term where the problem has a likelihood and the method computed the
    /// sensitivities there, else None.
    pub objective: Option<f64>,
    /// ε, the weighted sum of squares at the iterate's noise scales (what
    /// [`Iteration::cost`](crate::Iteration::cost) records is the profile's under
    /// hierarchical optimisation; this is ε itself).
    pub cost: f64,
    /// The certificate's first-order measure at the iterate, where the method computed the
    /// sensitivities there (converged when it is within `gtol`).
    pub optimality: Option<f64>,
    /// Whether the iterate was integrated at the coarse stage's tolerances (its objective
    /// then differs from the problem's by their error).
    pub coarse: bool,
}

/// A trial step of a trust-region method, as the method judged it: one per point it
/// integrated to decide whether to move there (an accepted trial moves the fit; the iterate
/// it moves to is the next one the driver records).
#[derive(Clone, Debug, PartialEq)]
pub struct TrialReport<'a> {
    /// The method's name.
    pub method: &'a str,
    /// The model the step was found on: "gauss-newton" (A = JᵀWJ), "augmented" (NL2SOL's
    /// A + S) or "newton" (the hybrid's differenced Hessian).
    pub model: &'a str,
    /// ε at the iterate the trial is taken from (at its noise scales).
    pub from: f64,
    /// The trust region's radius Δ the step was sought for (in the scaled norm ‖Dδ‖).
    pub radius: f64,
    /// The step's scaled length ‖Dδ‖.
    pub step: f64,
    /// The Levenberg–Marquardt parameter λ of the step (0: the model's own minimiser).
    pub lambda: f64,
    /// The decrease of ε the model predicted.
    pub predicted: f64,
    /// The decrease the method measured (NaN where the trial could not be integrated).
    pub actual: f64,
    /// actual / predicted, the ratio ρ the step is judged by.
    pub ratio: f64,
    /// Whether the fit moved to the trial.
    pub accepted: bool,
}

type Observer = Rc<dyn Fn(&IterateReport<'_>)>;
type TrialObserver = Rc<dyn Fn(&TrialReport<'_>)>;

thread_local! {
    static OBSERVER: RefCell<Option<Observer>> = const { RefCell::new(None) };
    static TRIALS: RefCell<Option<TrialObserver>> = const { RefCell::new(None) };
    static STOP: RefCell<Option<Stop>> = const { RefCell::new(None) };
}

/// The stop flags that apply to the work on a thread: the one [`stop_when`] set, and those of
/// the runs it was called from (a fit that a progress callback starts stops with the run
/// that called it). Carried to other threads with [`stop_within`].
#[derive(Clone, Debug)]
pub struct Stop(Arc<StopNode>);

#[derive(Debug)]
struct StopNode {
    flag: Arc<AtomicBool>,
    outer: Option<Stop>,
}

impl Stop {
    /// Whether any of its flags is set.
    pub fn requested(&self) -> bool {
        let mut node = Some(self);
        while let Some(Stop(n)) = node {
            if n.flag.load(Ordering::Relaxed) {
                return true;
            }
            node = n.outer.as_ref();
        }
        false
    }
}

/// Runs `f` with the fits on this thread stopping at their next iteration once `flag` (or a
/// flag of the work this runs within) is set: termination `interrupted`, each with its best
/// point so far, as any stopped fit. Set from another thread: a program's Ctrl-C, a progress
/// callback that raised. A multistart's and a profile's fits, which run on other threads,
/// are handed the same flags ([`current_stop`], [`stop_within`]), and the starts or
/// profiles not yet begun are not begun. Returns what `f` returns.
pub fn stop_when<R>(flag: Arc<AtomicBool>, f: impl FnOnce() -> R) -> R {
    let stop = Stop(Arc::new(StopNode { flag, outer: current_stop() }));
    stop_within(Some(stop), f)
}

/// Runs `f` with `stop` (from [`current_stop`] on the thread that handed out the work) as
/// this thread's stop flags, and puts the thread's own back after it (also when `f` panics).
pub fn stop_within<R>(stop: Option<Stop>, f: impl FnOnce() -> R) -> R {
    within(&STOP, stop, f)
}

/// Runs `f` with `value` in the thread-local `cell`, and puts the value it replaced back
/// after it (also when `f` panics).
fn within<T: 'static, R>(
    cell: &'static LocalKey<RefCell<Option<T>>>,
    value: Option<T>,
    f: impl FnOnce() -> R,
) -> R {
    /// Puts the outer value back when dropped.
    struct Restore<T: 'static>(&'static LocalKey<RefCell<Option<T>>>, Option<T>);
    impl<T: 'static> Drop for Restore<T> {
        fn drop(&mut self) {
            let outer = self.1.take();
            self.0.with(|c| *c.borrow_mut() = outer);
        }
    }
    let outer = cell.with(|c| std::mem::replace(&mut *c.borrow_mut(), value));
    let _restore = Restore(cell, outer);
    f()
}

/// The stop flags of the work on this thread, to hand to the threads it spreads to.
pub fn current_stop() -> Option<Stop> {
    STOP.with(|s| s.borrow().clone())
}

/// Whether the work on this thread was asked to stop ([`stop_when`]).
pub fn stop_requested() -> bool {
    STOP.with(|s| s.borrow().as_ref().is_some_and(Stop::requested))
}

/// Runs `f` with `observer` hearing of every iterate that fits on this thread record, and
/// returns what `f` returns. Observers nest: an inner one replaces the outer for its span,
/// which is restored after it (also when `f` panics).
pub fn observe<R>(observer: impl Fn(&IterateReport<'_>) + 'static, f: impl FnOnce() -> R) -> R {
    within(&OBSERVER, Some(Rc::new(observer) as Observer), f)
}

/// Whether an observer is listening on this thread (the driver forms a [`IterateReport`] only
/// then).
pub(crate) fn listening() -> bool {
    OBSERVER.with(|o| o.borrow().is_some())
}

/// Tells this thread's observer, if any, of `iterate`.
pub(crate) fn report(iterate: &IterateReport<'_>) {
    // Cloned out of the cell so that an observer may itself run a fit (and observe it).
    let observer = OBSERVER.with(|o| o.borrow().clone());
    if let Some(observer) = observer {
        observer(iterate);
    }
}

/// Runs `f` with `observer` hearing of every trial step that the trust-region methods
/// (`levenberg-marquardt`, `hybrid-newton`, `nl2sol`, `geodesic-lm`) judge in fits on this
/// thread, and returns what `f` returns. Nests as [`observe`] does.
pub fn observe_trials<R>(
    observer: impl Fn(&TrialReport<'_>) + 'static,
    f: impl FnOnce() -> R,
) -> R {
    within(&TRIALS, Some(Rc::new(observer) as TrialObserver), f)
}

/// Whether a trial observer is listening on this thread (a method forms a [`TrialReport`]
/// only then).
pub fn trials_listening() -> bool {
    TRIALS.with(|o| o.borrow().is_some())
}

/// Tells this thread's trial observer, if any, of `trial`.
pub fn report_trial(trial: &TrialReport<'_>) {
    let observer = TRIALS.with(|o| o.borrow().clone());
    if let Some(observer) = observer {
        observer(trial);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A trial reaches the innermost trial observer only, and the outer one is back after
    /// its span; outside every span no one listens.
    #[test]
    fn trials_reach_the_innermost_observer() {
        use std::cell::Cell;
        let trial = TrialReport {
            method: "nl2sol",
            model: "gauss-newton",
            from: 2.0,
            radius: 1.0,
            step: 0.5,
            lambda: 0.0,
            predicted: 1.0,
            actual: 0.5,
            ratio: 0.5,
            accepted: true,
        };
        let (outer, inner) = (Rc::new(Cell::new(0)), Rc::new(Cell::new(0)));
        assert!(!trials_listening());
        let (o, i) = (Rc::clone(&outer), Rc::clone(&inner));
        observe_trials(
            move |_| o.set(o.get() + 1),
            || {
                report_trial(&trial);
                observe_trials(
                    move |t| i.set(i.get() + usize::from(t.accepted)),
                    || report_trial(&trial),
                );
                assert!(trials_listening());
                report_trial(&trial);
            },
        );
        assert_eq!((outer.get(), inner.get()), (2, 1));
        assert!(!trials_listening());
        report_trial(&trial);
        assert_eq!(outer.get(), 2, "no one listens outside");
    }

    /// Work within work stops with either's flag; the flags travel to another thread with
    /// [`stop_within`], and each thread's own are back after the work.
    #[test]
    fn a_stop_applies_to_the_work_within_it_and_where_it_is_carried() {
        let (outer, inner) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        assert!(!stop_requested());
        stop_when(Arc::clone(&outer), || {
            stop_when(Arc::clone(&inner), || {
                assert!(!stop_requested());
                outer.store(true, Ordering::Relaxed);
                assert!(stop_requested(), "the outer run's flag stops the inner run");
                let carried = current_stop();
                let elsewhere = std::thread::spawn(move || {
                    let before = stop_requested();
                    (before, stop_within(carried, stop_requested), stop_requested())
                });
                assert_eq!(elsewhere.join().unwrap(), (false, true, false));
            });
            outer.store(false, Ordering::Relaxed);
            inner.store(true, Ordering::Relaxed);
            assert!(!stop_requested(), "the inner run's flag does not stop the outer run");
        });
        assert!(current_stop().is_none());
    }
}
