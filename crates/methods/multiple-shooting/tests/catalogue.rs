//! Multiple shooting against an independent reference: Goodman's method with step halving on
//! the same data, started from the truth, on every catalogue system (so that the reference
//! sits at the true minimum even where single shooting from the catalogue's start does not
//! reach it), and the paper's example. (Its certificate on bounds, outliers, tiny rates and
//! blow-ups is checked with every other method's in the workspace's tests/certificate.rs.)

use sysid_core::Method;
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_multiple_shooting::{DEFECT, MultipleShooting, MultipleShootingOptions};
use sysid_ode::System;
use sysid_ode::testing::assert_close;
use sysid_systems::{Case, Visit};

struct BothMethods;

impl Visit for BothMethods {
    type Output = (f64, f64, bool);
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        let problem = case.problem(1).unwrap();
        let ms = MultipleShooting::default().fit(&problem).unwrap();
        assert!(ms.converged(), "{}: {}", case.name, ms.termination);
        let truth = case.expected_values().unwrap_or_else(|| problem.guesses());
        let reference = Goodman::new(GoodmanOptions::default().with_step_halving(true))
            .fit_from(&problem, &truth)
            .unwrap();
        assert!(reference.converged(), "{}: {}", case.name, reference.termination);
        let defect = ms.history.last().and_then(|row| row.diagnostic(DEFECT)).unwrap();
        assert!(defect.is_finite(), "{}: the history carries the defect", case.name);
        (ms.cost, reference.cost, ms.active_bounds().is_empty())
    }
}

#[test]
fn every_catalogue_minimum_is_goodmans_from_the_truth() {
    for name in sysid_systems::NAMES {
        let (ms, goodman, _) = sysid_systems::visit(name, BothMethods).unwrap();
        // Both stop where the certificate holds (optimality ≤ 1e-6): the costs of one minimum
        // then agree to far below 1e-8 (van-der-pol-three-point's ε ≈ 1e-25 is an exact fit).
        if goodman > 1e-20 {
            assert_close(ms, goodman, 1e-8);
        } else {
            assert!(ms <= 1e-20, "{name}: ε = {ms:e} at an exact fit");
        }
    }
}

#[test]
fn lotka_volterra_from_the_catalogue_start_reaches_the_true_minimum() {
    // From (1.2, 0.8, 2.5, 0.8) Goodman and Gauss–Newton diverge and the line searches stop
    // at ε ≈ 56 116; the true minimum of this data (seed 1) is ε = 199.0124698 (Goodman from
    // the truth gives the same, in the test above).
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let ms = MultipleShooting::default().fit(&problem).unwrap();
    assert!(ms.converged(), "{}", ms.termination);
    // The value is given to 10 significant digits.
    assert_close(ms.cost, 199.012_469_8, 1e-8);
    // The first iterate starts from the data: its nodes do not match yet.
    assert!(
        ms.history[0].diagnostic(DEFECT).unwrap() > 1.0,
        "{:?}",
        ms.history[0].diagnostic(DEFECT)
    );
    assert!(ms.history.last().unwrap().diagnostic(DEFECT).unwrap() < 1e-6);
}

#[test]
fn the_compartment_chain_holds_its_rate_on_the_bound() {
    let (_, _, free) = sysid_systems::visit("compartment-chain", BothMethods).unwrap();
    assert!(!free, "d1's lower bound is active at the minimum");
}

#[test]
fn one_interval_is_single_shooting() {
    let case = sysid_systems::van_der_pol::van_der_pol();
    let problem = case.problem(1).unwrap();
    let one = MultipleShootingOptions { intervals: Some(1), ..Default::default() };
    let ms = MultipleShooting::new(one).fit(&problem).unwrap();
    let goodman = Goodman::default().fit(&problem).unwrap();
    assert!(ms.converged() && goodman.converged());
    assert_close(ms.cost, goodman.cost, 1e-10);
    assert!(ms.history.iter().all(|row| row.diagnostic(DEFECT) == Some(0.0)));
    let zero = MultipleShootingOptions { intervals: Some(0), ..Default::default() };
    assert!(MultipleShooting::new(zero).fit(&problem).is_err());
}

#[test]
fn goodmans_falling_body_table_one() {
    let case = sysid_systems::falling_body::falling_body();
    let estimate = MultipleShooting::default().fit(&case.problem(1).unwrap()).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    // Goodman 1966, §IV: y(0) = v(0) = −0.25, g = 32.5, ε = 1.25.
    assert_close(estimate.value("y").unwrap(), -0.25, 1e-9);
    assert_close(estimate.value("v").unwrap(), -0.25, 1e-9);
    assert_close(estimate.value("g").unwrap(), 32.5, 1e-10);
    assert_close(estimate.cost, 1.25, 1e-10);
}
