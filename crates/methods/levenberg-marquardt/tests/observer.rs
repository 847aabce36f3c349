//! The observer of a running fit (`sysid_core::observer`): it hears of every iterate the
//! driver records, as the fit's history records it, and only while it is set.

use std::cell::RefCell;
use std::rc::Rc;

use sysid_core::Method;
use sysid_core::observer::observe;
use sysid_levenberg_marquardt::LevenbergMarquardt;

/// (iteration, objective, ε, optimality) of each iterate heard of.
type Heard = Rc<RefCell<Vec<(usize, Option<f64>, f64, Option<f64>)>>>;

#[test]
fn the_observer_hears_every_iterate_of_the_fit_and_nothing_after() {
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let heard: Heard = Rc::default();
    let into = Rc::clone(&heard);
    let method = LevenbergMarquardt::adaptive(Default::default());
    let fit = observe(
        move |p| {
            assert_eq!(p.method, "nl2sol");
            into.borrow_mut().push((p.iteration, p.objective, p.cost, p.optimality));
        },
        || method.fit(&problem).unwrap(),
    );
    assert!(fit.converged(), "{}", fit.termination);
    let log = heard.borrow().clone();
    // Every iteration from 0 to the last, in order (an iterate integrated again at finer
    // tolerances, or at the coarse stage's end, is heard of again).
    let mut iterations: Vec<usize> = log.iter().map(|h| h.0).collect();
    assert!(iterations.is_sorted(), "{iterations:?}");
    iterations.dedup();
    assert_eq!(iterations, (0..=fit.iterations).collect::<Vec<_>>());
    // The last iterate heard of is the point returned, with its ε, objective and measure as
    // the history and the estimate give them.
    let last = log.last().unwrap();
    let row = fit.history.last().unwrap();
    assert_eq!((last.2, last.3), (row.cost, row.optimality));
    assert_eq!(last.2.to_bits(), fit.cost.to_bits());
    assert_eq!(last.1, fit.nll.map(|nll| nll + fit.prior.unwrap_or(0.0)));
    assert!(last.1.is_some(), "the catalogue's noise gives a likelihood");
    // Once `observe` returns, fits are not heard of.
    LevenbergMarquardt::adaptive(Default::default()).fit(&case.problem(1).unwrap()).unwrap();
    assert_eq!(heard.borrow().len(), log.len());
}
