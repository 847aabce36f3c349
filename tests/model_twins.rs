//! Model files give the results of the dual-number path: every method of the registry fits
//! the catalogue's model-file twins (`tests/twins/`) twice, once with the symbolic Jacobians
//! (compiled, as sysid runs model files) and once differentiated by dual numbers, and the
//! two fits agree in their outcome, iterations, cost and estimates. (The derivatives
//! themselves are compared point by point in `crates/model/tests/symbolic.rs`.)
//!
//! The tolerance is 1e-12 relative, except where a fit does not reproduce itself that
//! closely under rounding: the estimates of quasilinearization, whose linear two-point
//! problems amplify rounding (on Robertson, the compiled Rust system and the model file,
//! both differentiated by dual numbers, give estimates 5e-10 and 9e-10 apart; the symbolic
//! path lands 3e-10 and 7e-10 from the dual one), and fits that stop without converging,
//! whose path after many iterations far from the minimum amplifies it likewise (LV's
//! quasilinearization: 3e-11). There it is 1e-9.
//!
//! `gauss-newton-fd` differences f, which amplifies f's rounding by the inverse of its step:
//! the symbolic path reads f from the compiled program that also computes the Jacobian's
//! entries, the dual path from the interpreter, and the two differ in the last bits. Its
//! path may then take one iteration more or less; its converged point is held to
//! [`DIFFERENCED`].

use crate::twins;

use sysid::core::{Estimate, Termination};
use sysid::model::ModelSystem;
use sysid::registry::{Registry, Settings};

/// The relative agreement of fitted quantities.
const RTOL: f64 = 1e-12;
/// Where rounding is amplified (see the module's documentation).
const AMPLIFIED: f64 = 1e-9;
/// A differenced Jacobian's fit (see the module's documentation).
const DIFFERENCED: f64 = 1e-7;

fn within(a: f64, b: f64, rtol: f64) -> bool {
    a.to_bits() == b.to_bits() || (a - b).abs() <= rtol * a.abs().max(b.abs())
}

#[test]
fn every_method_fits_the_twins_as_the_dual_path_does() {
    let registry = Registry::<ModelSystem>::standard();
    let mut tight = 0;
    for (name, _) in twins::TWINS {
        let symbolic = twins::file_problem(name, 1, false);
        let dual = twins::file_problem(name, 1, true);
        let rhs = symbolic.system().symbolic_rhs().expect("symbolic derivatives");
        assert_eq!(rhs.is_compiled(), cfg!(feature = "jit"), "compiled by the jit feature");
        // Without the trust regions' coarse stage: at rtol 1e-6 the two paths' rounding
        // steers their trials apart a little, and the fits then end within gtol of each other,
        // not within 1e-12 (van der Pol's nl2sol: v 4.6e-12 apart). The paths' arithmetic is
        // what this compares.
        let mut settings = Settings::default();
        settings.driver.coarse_first = false;
        for (method_name, method) in registry.build_all(&settings) {
            let what = format!("{name}, {method_name}");
            let (a, b) = match (method.fit(&symbolic), method.fit(&dual)) {
                (Ok(a), Ok(b)) => (a, b),
                (Err(a), Err(b)) => {
                    assert_eq!(a.to_string(), b.to_string(), "{what}");
                    continue;
                }
                (a, b) => panic!("{what}: {:?} vs {:?}", a.map(|e| e.cost), b.map(|e| e.cost)),
            };
            let kind = |e: &Estimate| std::mem::discriminant(&e.termination);
            assert_eq!(kind(&a), kind(&b), "{what}: {:?} vs {:?}", a.termination, b.termination);
            let differenced = method_name == "gauss-newton-fd";
            if differenced {
                assert!(a.iterations.abs_diff(b.iterations) <= 1, "{what}");
            } else {
                assert_eq!(a.iterations, b.iterations, "{what}");
            }
            let converged = matches!(a.termination, Termination::Converged(_));
            let (cost, estimates) = match (converged, method_name.starts_with("quasilinearization"))
            {
                _ if differenced => (DIFFERENCED, DIFFERENCED),
                (true, false) => (RTOL, RTOL),
                (true, true) => (RTOL, AMPLIFIED),
                (false, _) => (AMPLIFIED, AMPLIFIED),
            };
            assert!(within(a.cost, b.cost, cost), "{what}: ε {} vs {}", a.cost, b.cost);
            for ((n, x), y) in a.names.iter().zip(&a.values).zip(&b.values) {
                assert!(within(*x, *y, estimates), "{what}: {n} {x} vs {y}");
            }
            tight += usize::from(estimates == RTOL);
        }
    }
    // 5 twins × 12 methods: 60 fits; all but quasilinearization's ten, gauss-newton-fd's five
    // and those that stop without converging (LV's goodman and gauss-newton, at their first
    // step) are held to 1e-12.
    assert!(tight >= 33, "{tight} fits held to 1e-12");
}
