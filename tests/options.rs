//! Every method's options are set one field at a time with `with_*` setters: the driver's
//! through [`Driven`], each method's own through its options type. Each setter sets its field
//! and nothing else.

use sysid::gauss_newton::JacobianSource;
use sysid::levenberg_marquardt::Hessian;
use sysid::prelude::*;
use sysid::quasilinearization::Start;
use sysid::registry::Settings;

/// The driver's options with every field away from its default.
fn driver() -> sysid::core::DriverOptions {
    sysid::core::DriverOptions {
        max_iterations: 7,
        step_tolerance: 1e-3,
        gradient_tolerance: 1e-4,
        gtol: Some(1e-5),
        max_condition: 1e6,
        max_integrations: Some(99),
        max_seconds: Some(60.0),
        coarse_first: false,
    }
}

/// `options` with every driver field set by its setter.
fn driven<O: Driven>(options: O) -> O {
    options
        .with_max_iterations(7)
        .with_step_tolerance(1e-3)
        .with_gradient_tolerance(1e-4)
        .with_gtol(1e-5)
        .with_max_condition(1e6)
        .with_max_integrations(99)
        .with_max_seconds(60.0)
        .with_coarse_first(false)
}

#[test]
fn the_driver_setters_set_the_drivers_fields_on_every_method() {
    assert_eq!(driven(sysid::core::DriverOptions::default()), driver());
    assert_eq!(driven(GoodmanOptions::default()).driver, driver());
    assert_eq!(driven(GaussNewtonOptions::default()).driver, driver());
    assert_eq!(driven(LevenbergMarquardtOptions::default()).driver, driver());
    assert_eq!(driven(MultipleShootingOptions::default()).driver, driver());
    assert_eq!(driven(QuasilinearizationOptions::default()).driver, driver());
    assert_eq!(driven(Settings::default()).driver, driver());
    let replaced = GoodmanOptions::default().with_driver(driver());
    assert_eq!(replaced.driver, driver());
}

#[test]
fn each_methods_own_setters_set_its_fields() {
    let g = GoodmanOptions::default()
        .with_step_halving(true)
        .with_cost_tolerance(1e-9)
        .with_max_halvings(3);
    assert_eq!(
        g,
        GoodmanOptions {
            step_halving: true,
            cost_tolerance: 1e-9,
            max_halvings: 3,
            ..Default::default()
        }
    );
    let n = GaussNewtonOptions::default()
        .with_tolerance(1e-6)
        .with_line_search(true)
        .with_armijo(0.3)
        .with_jacobian(JacobianSource::FiniteDifferences);
    assert_eq!(
        n,
        GaussNewtonOptions {
            tolerance: 1e-6,
            line_search: true,
            armijo: 0.3,
            jacobian: JacobianSource::FiniteDifferences,
            ..Default::default()
        }
    );
    let l = LevenbergMarquardtOptions::default()
        .with_factor(1.0)
        .with_max_rejections(4)
        .with_hessian(Hessian::Adaptive)
        .with_geodesic(true);
    assert_eq!(
        l,
        LevenbergMarquardtOptions {
            factor: 1.0,
            max_rejections: 4,
            hessian: Hessian::Adaptive,
            geodesic: true,
            ..Default::default()
        }
    );
    let m = MultipleShootingOptions::default().with_intervals(6);
    assert_eq!(m, MultipleShootingOptions { intervals: Some(6), ..Default::default() });
    let q = QuasilinearizationOptions::default().with_start(Start::Data);
    assert!(matches!(q.start, Start::Data));
}
