//! Levenberg–Marquardt, the Fletcher–Xu hybrid and NL2SOL's adaptive model against an
//! independent reference: Goodman's
//! method with step halving on the same data from the same start, on every catalogue system,
//! and the paper's example.
//! (Its certificate on bounds, outliers, tiny rates and blow-ups is checked with every other
//! method's in the workspace's tests/certificate.rs.)

use sysid_core::Method;
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_levenberg_marquardt::LevenbergMarquardt;
use sysid_ode::System;
use sysid_ode::testing::assert_close;
use sysid_systems::{Case, Visit};

struct BothMethods;

impl Visit for BothMethods {
    type Output = (f64, f64, f64, f64, bool);
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        let problem = case.problem(1).unwrap();
        let lm = LevenbergMarquardt::default().fit(&problem).unwrap();
        assert!(lm.converged(), "{}: {}", case.name, lm.termination);
        let hybrid = LevenbergMarquardt::hybrid(Default::default()).fit(&problem).unwrap();
        assert!(hybrid.converged(), "{}: {}", case.name, hybrid.termination);
        assert_eq!(hybrid.method, "hybrid-newton");
        let adaptive = LevenbergMarquardt::adaptive(Default::default()).fit(&problem).unwrap();
        assert!(adaptive.converged(), "{}: {}", case.name, adaptive.termination);
        assert_eq!(adaptive.method, "nl2sol");
        let reference =
            Goodman::new(GoodmanOptions::default().with_step_halving(true)).fit(&problem).unwrap();
        assert!(reference.converged(), "{}: {}", case.name, reference.termination);
        (lm.cost, hybrid.cost, adaptive.cost, reference.cost, lm.active_bounds().is_empty())
    }
}

#[test]
fn every_catalogue_minimum_is_goodmans() {
    for name in sysid_systems::NAMES {
        let (lm, hybrid, adaptive, goodman, _) = sysid_systems::visit(name, BothMethods).unwrap();
        // All stop where the certificate holds (optimality ≤ 1e-6): the costs of one minimum
        // then agree to far below 1e-8 (van-der-pol-three-point's ε ≈ 1e-25 is an exact fit).
        for cost in [lm, hybrid, adaptive] {
            if goodman > 1e-20 {
                assert_close(cost, goodman, 1e-8);
            } else {
                assert!(cost <= 1e-20, "{name}: ε = {cost:e} at an exact fit");
            }
        }
    }
}

#[test]
fn the_compartment_chain_holds_its_rate_on_the_bound() {
    let (_, _, _, _, free) = sysid_systems::visit("compartment-chain", BothMethods).unwrap();
    assert!(!free, "d1's lower bound is active at the minimum");
}

#[test]
fn goodmans_falling_body_table_one() {
    let case = sysid_systems::falling_body::falling_body();
    let estimate = LevenbergMarquardt::default().fit(&case.problem(1).unwrap()).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    // Goodman 1966, §IV: y(0) = v(0) = −0.25, g = 32.5, ε = 1.25.
    assert_close(estimate.value("y").unwrap(), -0.25, 1e-9);
    assert_close(estimate.value("v").unwrap(), -0.25, 1e-9);
    assert_close(estimate.value("g").unwrap(), 32.5, 1e-10);
    assert_close(estimate.cost, 1.25, 1e-10);
}

struct Screening;

impl Visit for Screening {
    /// The screened fits' integrations less the unscreened fits', over the two methods.
    type Output = i64;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        use sysid_levenberg_marquardt::LevenbergMarquardtOptions;
        let problem = case.problem(1).unwrap();
        let mut extra = 0;
        for adaptive in [false, true] {
            let fit = |screen: bool| {
                let options = LevenbergMarquardtOptions::default().with_screen(screen);
                let method = match adaptive {
                    true => LevenbergMarquardt::adaptive(options),
                    false => LevenbergMarquardt::new(options),
                };
                method.fit(&problem).unwrap()
            };
            let (on, off) = (fit(true), fit(false));
            // The same points visited: the same iterations, and the same history of ε to
            // the integration's accuracy.
            assert_eq!(on.iterations, off.iterations, "{}", case.name);
            assert_eq!(on.converged(), off.converged(), "{}", case.name);
            for (a, b) in on.history.iter().zip(&off.history) {
                assert_close(a.cost, b.cost, 1e-12);
            }
            extra += on.counts.integrations as i64 - off.counts.integrations as i64;
        }
        extra
    }
}

struct Correcting;

impl Visit for Correcting {
    type Output = ();
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
        use sysid_levenberg_marquardt::{Hessian, LevenbergMarquardtOptions};
        let problem = case.problem(1).unwrap();
        let on = LevenbergMarquardt::adaptive(LevenbergMarquardtOptions::default());
        let off = LevenbergMarquardt::new(
            LevenbergMarquardtOptions::default()
                .with_hessian(Hessian::Adaptive)
                .with_correct(false),
        );
        let (on, off) = (on.fit(&problem).unwrap(), off.fit(&problem).unwrap());
        assert_eq!(on.method, "nl2sol", "{}", case.name);
        assert_eq!(on.iterations, off.iterations, "{}", case.name);
        assert_eq!(on.counts.integrations, off.counts.integrations, "{}", case.name);
        for (a, b) in on.history.iter().zip(&off.history) {
            assert_eq!(a.cost.to_bits(), b.cost.to_bits(), "{}", case.name);
        }
    }
}

/// The crawl's corrector ([`sysid_levenberg_marquardt::CRAWL_FALL`]) acts only where a fit
/// has crept for [`sysid_levenberg_marquardt::CRAWL_WINDOW`] iterations: on every catalogue
/// system nl2sol converges before that, and its fit is the same to the bit with the
/// corrector on and off (its effect on the PEtab problems' crawls is in docs/methods.md).
#[test]
fn the_crawls_corrector_leaves_a_fit_that_does_not_crawl_alone() {
    for name in sysid_systems::NAMES {
        sysid_systems::visit(name, Correcting).unwrap();
    }
}

#[test]
fn screening_trials_changes_the_cost_of_a_fit_not_its_path() {
    let mut screened = 0;
    for name in sysid_systems::NAMES {
        let extra = sysid_systems::visit(name, Screening).unwrap();
        // Screening adds plain integrations (the sensitivities' it saves are counted as one
        // integration each as well).
        assert!(extra >= 0, "{name}: {extra}");
        screened += extra;
    }
    // Some fit was screened (lotka-volterra's rejects most of its first trials).
    assert!(screened > 0);
}
