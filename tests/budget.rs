//! No data and no start makes a fit run past its budget of model integrations, whatever
//! the method: property-tested over data of any magnitude (up to where a weighted square
//! still fits in an f64) and starts of either sign and any scale.

use proptest::prelude::*;
use sysid::core::{Data, DriverOptions, Problem, Unknown};
use sysid::ode::Integrator;
use sysid::registry::{Boxed, Registry, Settings};
use sysid::systems::stress::Tracking;

/// The hard budget of these tests: small, so that a runaway shows at once.
const BUDGET: u64 = 40;

fn methods() -> Vec<Boxed<Tracking>> {
    let driver = DriverOptions { max_integrations: Some(BUDGET), ..DriverOptions::default() };
    let settings = Settings { driver, ..Settings::default() };
    Registry::<Tracking>::standard().build_all(&settings).into_iter().map(|(_, m)| m).collect()
}

/// A value m·10^e with e spread over the usable range.
fn magnitude() -> impl Strategy<Value = f64> {
    (-1.0f64..1.0, -300i32..150).prop_map(|(m, e)| m * 10f64.powi(e))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn no_fit_runs_past_its_budget(
        values in prop::collection::vec(magnitude(), 6),
        y0 in magnitude(),
        k in (-3.0f64..3.0, -1.0f64..1.0).prop_map(|(e, s)| s.signum() * 10f64.powf(e)),
    ) {
        let times = [0.0, 0.5, 1.0, 2.0, 3.0, 5.0];
        // A step budget of 10⁴ per integration keeps the failing trial points (a rate of 1e5
        // is stiff for DOPRI5) cheap; the budget under test counts integrations.
        let problem = Problem::builder(Tracking::default())
            .unknown("y", y0)
            .unknown_with(Unknown::new("k", k))
            .data(Data::discrete().series("y", &times, &values))
            .integrator(Integrator::default().with_max_steps(10_000))
            .build()
            .unwrap();
        for method in methods() {
            let e = method.fit(&problem).unwrap();
            // Past the budget: the last difference-quotient Jacobian of `-fd` (k + 1 = 3
            // integrations, admitted while one was left: up to 2 over), and the certificate's
            // own integrations (the reported point's linearization where the method made none,
            // and one at finer tolerances for the measure's integration error).
            prop_assert!(
                e.counts.integrations <= BUDGET + 4,
                "{}: {} integrations ({})", method.name(), e.counts.integrations, e.termination
            );
            let text = serde_json::to_string(&e.record("tracking")).unwrap();
            let json: serde_json::Value = serde_json::from_str(&text).unwrap();
            prop_assert_eq!(json["converged"].as_bool(), Some(e.converged()));
        }
    }
}
