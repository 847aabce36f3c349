//! A fit's progress while it runs: an observer, set on the calling thread around the fit
//! ([`observe`]), hears of every iterate the driver records.
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

type Observer = Rc<dyn Fn(&IterateReport<'_>)>;

thread_local! {
    static OBSERVER: RefCell<Option<Observer>> = const { RefCell::new(None) };
}

/// Runs `f` with `observer` hearing of every iterate that fits on this thread record, and
/// returns what `f` returns. Observers nest: an inner one replaces the outer for its span,
/// which is restored after it (also when `f` panics).
pub fn observe<R>(observer: impl Fn(&IterateReport<'_>) + 'static, f: impl FnOnce() -> R) -> R {
    /// Puts the outer observer back when dropped.
    struct Restore(Option<Observer>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let outer = self.0.take();
            OBSERVER.with(|o| *o.borrow_mut() = outer);
        }
    }
    let outer = OBSERVER.with(|o| o.borrow_mut().replace(Rc::new(observer)));
    let _restore = Restore(outer);
    f()
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
