//! Bounds through the change of variables: the same answer as Goodman's projected method
//! when the bound is inactive, and iterates that respect an active bound.

use sysid_core::{Data, Method, Problem, Unknown};
use sysid_gauss_newton::GaussNewton;
use sysid_goodman::Goodman;
use sysid_ode::Integrator;
use sysid_ode::testing::{Decay, assert_close};

fn problem(k: Unknown) -> Problem<Decay> {
    let times: [f64; 6] = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0];
    // 2 e^{-0.8 t} with a fixed perturbation, so that the residual is not zero.
    let values: Vec<f64> = times
        .iter()
        .enumerate()
        .map(|(m, t)| 2.0 * (-0.8 * t).exp() + 0.01 * (m as f64).cos())
        .collect();
    Problem::builder(Decay::new())
        .unknown("x", 1.5)
        .unknown_with(k)
        .data(Data::discrete().series("x", &times, &values))
        .integrator(Integrator::dopri5(1e-10, 1e-12))
        .build()
        .unwrap()
}

#[test]
fn inactive_bounds_do_not_change_the_answer() {
    for k in [
        Unknown::new("k", 0.5).min(0.1),
        Unknown::new("k", 0.5).min(0.1).max(2.0),
        Unknown::new("k", 0.5).max(5.0),
    ] {
        let p = problem(k);
        let goodman = Goodman::default().fit(&p).unwrap();
        for gn in [GaussNewton::plain(), GaussNewton::line_search()] {
            let e = gn.fit(&p).unwrap();
            assert!(e.converged(), "{}", e.termination);
            assert_close(e.cost, goodman.cost, 1e-9);
            for (a, b) in e.values.iter().zip(&goodman.values) {
                assert_close(*a, *b, 1e-6);
            }
            // Standard errors in the problem's coordinates, as without bounds.
            let (se, sg) = (e.std_errors.unwrap(), goodman.std_errors.clone().unwrap());
            assert_close(se[1], sg[1], 1e-4);
        }
    }
}

#[test]
fn an_optimum_on_a_bound_is_reached_and_reported() {
    // The best k is about 0.8; with k ≥ 1 the bounded optimum has k on its bound. The change
    // of variables approaches it; the adapter holds k there once the projected Gauss–Newton
    // model holds it on the bound, and every method agrees on the bounded optimum.
    let problem = problem(Unknown::new("k", 1.5).min(1.0));
    let goodman = Goodman::default().fit(&problem).unwrap();
    assert!(goodman.converged(), "{}", goodman.termination);
    for gn in [GaussNewton::plain(), GaussNewton::line_search(), GaussNewton::finite_differences()]
    {
        let e = gn.fit(&problem).unwrap();
        assert!(e.converged(), "{}: {}", e.method, e.termination);
        assert!(e.history.iter().all(|h| h.values[1] >= 1.0), "never below the bound");
        assert_eq!(e.active_bounds(), vec![("k", sysid_core::Bound::Lower)]);
        assert_eq!(e.value("k").unwrap().to_bits(), 1.0f64.to_bits(), "{:?}", e.values);
        assert_close(e.cost, goodman.cost, 1e-8);
        assert_close(e.value("x").unwrap(), goodman.value("x").unwrap(), 1e-7);
        assert!(e.history[0].cost.is_finite(), "the start's cost is recorded");
    }
}
