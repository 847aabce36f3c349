//! The stiff integrators (Rodas4 and Rodas5P) against independent references: Robertson's kinetics and
//! the van der Pol oscillator with μ = 1000 against Radau IIA solutions computed by scipy
//! (tests/data/stiff_reference.csv, scripts/reference/stiff.py), its sensitivities against
//! central differences, closed forms for order, dense output and direction, and the
//! automatic choice.

use crate::common;

use common::{Oscillator, robertson_rates, stiff_reference};
use sysid_ode::testing::Decay;
use sysid_ode::testing::{assert_close, assert_close_abs};
use sysid_ode::{AUTO_DOP853_RTOL, Integrator, Ivp, OdeError, SensitivityTrajectory, Wrt};
use sysid_systems::{Robertson, VanDerPol};

const ROBERTSON_Y0: [f64; 3] = [1.0, 0.0, 0.0];

/// The Rosenbrock schemes, each with its tolerances: every test below holds for both.
const ROSENBROCK: [fn(f64, f64) -> Integrator; 2] = [Integrator::rodas4, Integrator::rodas5p];

/// Asserts agreement with a reference value to c·(rtol·|y| + atol), the global error an
/// integrator at these tolerances should reach, plus twice the spread of the independent
/// reference runs (the reference's own error estimate).
#[track_caller]
pub(crate) fn assert_reference(
    actual: f64,
    (value, spread): (f64, f64),
    (rtol, atol): (f64, f64),
    c: f64,
) {
    assert_close_abs(actual, value, c * (rtol * value.abs() + atol) + 2.0 * spread * value.abs());
}

#[test]
fn robertson_matches_the_reference_at_40_and_4e5() {
    // y2 falls to 2e-8: the absolute tolerance sits six decades below it.
    let (rtol, atol) = (1e-10, 1e-14);
    let times = [40.0, 4e5];
    let schemes = ROSENBROCK.map(|scheme| scheme(rtol, atol));
    for integrator in schemes.into_iter().chain([Integrator::auto(rtol, atol)]) {
        let sol = Ivp::new(&Robertson::default(), 0.0, &ROBERTSON_Y0, &robertson_rates())
            .solve(&integrator, &times)
            .unwrap();
        for (m, &t) in times.iter().enumerate() {
            for (i, name) in ["y1", "y2", "y3"].iter().enumerate() {
                // Measured: within 2.4 (rtol·|y| + atol), y2 at t = 40 limited by atol.
                let reference = stiff_reference("robertson", t, name);
                assert_reference(sol.state(m)[i], reference, (rtol, atol), 5.0);
            }
        }
        // Mass is conserved by the equations and, being linear, by the scheme.
        let total: f64 = sol.state(1).iter().sum();
        assert_close(total, 1.0, 1e-13);
        assert!(sol.counts().steps < 10_000, "{:?}", sol.counts());
    }
}

#[test]
fn van_der_pol_with_mu_1000_over_one_period() {
    // The slow phases after the first and the second fast jump (t ≈ 807 and 1614).
    let rtol = 1e-10;
    let times = [1000.0, 2000.0];
    for scheme in ROSENBROCK {
        let sol = Ivp::new(&VanDerPol::default(), 0.0, &[2.0, 0.0], &[1000.0])
            .solve(&scheme(rtol, rtol), &times)
            .unwrap();
        for (m, &t) in times.iter().enumerate() {
            for (i, name) in ["x", "v"].iter().enumerate() {
                let reference = stiff_reference("vdp1000", t, name);
                assert_reference(sol.state(m)[i], reference, (rtol, rtol), 5.0);
            }
        }
        // An explicit integrator needs of the order of μ² steps for the same span.
        assert!(sol.counts().steps < 20_000, "{:?}", sol.counts());
    }
}

/// Central differences of log-scale perturbations: p_k ∂y/∂p_k for the rates, ∂y/∂y_i(0)
/// for the initial values, each from two tight Rodas4 integrations.
#[test]
fn robertson_sensitivities_match_central_differences() {
    for scheme in ROSENBROCK {
        robertson_sensitivities_against_differences(scheme(1e-10, 1e-16));
    }
}

pub(crate) fn robertson_sensitivities_against_differences(integrator: Integrator) {
    let sys = Robertson::default();
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::Parameter(2), Wrt::InitialValue(0)];
    let times = [0.01, 1.0, 40.0, 1e3];
    let sol = Ivp::new(&sys, 0.0, &ROBERTSON_Y0, &robertson_rates())
        .solve_sensitivities(&integrator, &wrt, &times)
        .unwrap();
    let reference = Integrator::rodas4(1e-12, 1e-18).with_max_steps(1_000_000);
    let delta = 1e-4;
    for (j, w) in wrt.iter().enumerate() {
        let solve = |s: f64| {
            let (mut y0, mut p) = (ROBERTSON_Y0, robertson_rates());
            match *w {
                Wrt::Parameter(k) => p[k] *= s.exp(),
                Wrt::InitialValue(i) => y0[i] += s,
            }
            Ivp::new(&sys, 0.0, &y0, &p).solve(&reference, &times).unwrap()
        };
        let (plus, minus) = (solve(delta), solve(-delta));
        let scale = match *w {
            Wrt::Parameter(k) => robertson_rates()[k],
            Wrt::InitialValue(_) => 1.0,
        };
        for m in 0..times.len() {
            for i in 0..3 {
                let fd = (plus.state(m)[i] - minus.state(m)[i]) / (2.0 * delta);
                let s = scale * sol.sensitivity(m)[(i, j)];
                // Difference error ~δ²·|y|, integration noise ~1e-12·|y|/δ and the
                // sensitivities' own tolerance 1e-10: measured within 4e-9 of |y|.
                let size = sol.state(m)[i].abs();
                assert_close_abs(s, fd, 2e-8 * (size + s.abs()));
            }
        }
    }
}

#[test]
fn rosenbrock_sensitivities_agree_with_dopri5_on_a_non_stiff_problem() {
    // Same variational equations, different schemes: agreement to the tolerances.
    let sys = VanDerPol::default();
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0), Wrt::InitialValue(1)];
    let times = [0.5, 3.0, 7.0, 12.0];
    let ivp = Ivp::new(&sys, 0.0, &[2.0, 0.0], &[1.0]);
    let dopri = ivp.solve_sensitivities(&Integrator::dopri5(1e-12, 1e-14), &wrt, &times).unwrap();
    for scheme in ROSENBROCK {
        let rodas = ivp.solve_sensitivities(&scheme(1e-11, 1e-13), &wrt, &times).unwrap();
        agree(&rodas, &dopri);
    }
}

fn agree(rodas: &SensitivityTrajectory, dopri: &SensitivityTrajectory) {
    for m in 0..dopri.times().len() {
        for (a, b) in rodas.state(m).iter().zip(dopri.state(m)) {
            assert_close_abs(*a, *b, 1e-8);
        }
        for (a, b) in rodas.sensitivity_slice(m).iter().zip(dopri.sensitivity_slice(m)) {
            assert_close_abs(*a, *b, 1e-8 * (1.0 + b.abs()));
        }
    }
}

#[test]
fn hand_written_jacobians_give_the_same_implicit_steps() {
    let wrt = [Wrt::InitialValue(0), Wrt::Parameter(0)];
    let times = [0.5, 2.0, 7.0];
    let run = |analytic| {
        let sys = Oscillator::new(analytic);
        Ivp::new(&sys, 0.0, &[1.0, 0.3], &[1.7])
            .solve_sensitivities(&Integrator::rodas4(1e-9, 1e-11), &wrt, &times)
            .unwrap()
    };
    let (dual, hand) = (run(false), run(true));
    for (m, &t) in times.iter().enumerate() {
        for (a, b) in dual.sensitivity_slice(m).iter().zip(hand.sensitivity_slice(m)) {
            assert_close_abs(*a, *b, 1e-13);
        }
        let (x, _, dx, _) = Oscillator::exact(1.0, 0.3, 1.7, t);
        assert_close_abs(dual.state(m)[0], x, 1e-8);
        assert_close_abs(dual.sensitivity(m)[(0, 1)], dx, 1e-8 * (1.0 + t));
    }
}

/// p = log2(e(h) / e(h/2)) for successive halvings.
fn observed_orders(errors: &[f64]) -> Vec<f64> {
    errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect()
}

#[test]
fn rodas4_converges_with_order_four() {
    // Fixed steps on the oscillator (no error control).
    let sys = Oscillator::new(false);
    let (x, v, _, _) = Oscillator::exact(1.0, 0.0, 1.0, 10.0);
    let errors: Vec<f64> = [0.2, 0.1, 0.05, 0.025]
        .iter()
        .map(|&h| {
            let integrator = Integrator::rodas4(1e-8, 1e-10).with_fixed_step(h);
            let sol = Ivp::new(&sys, 0.0, &[1.0, 0.0], &[1.0]).solve(&integrator, &[10.0]).unwrap();
            ((sol.state(0)[0] - x).powi(2) + (sol.state(0)[1] - v).powi(2)).sqrt()
        })
        .collect();
    for p in observed_orders(&errors) {
        assert!((p - 4.0).abs() < 0.15, "observed order {p} from errors {errors:?}");
    }
}

#[test]
fn rodas5p_converges_with_order_five() {
    // On a nonlinear problem: on the linear oscillator the error is that of the stability
    // function, of order 6 here. Fixed steps on van der Pol with μ = 1 to t = 4 against
    // DOPRI5 at rtol 1e-14. Measured orders 5.43, 5.21, 5.11 as h halves from 0.1 to
    // 0.0125, approaching 5 from above; a coefficient mistyped in any order condition of
    // order 5 or less leaves at most 4.
    let vdp = VanDerPol::default();
    let ivp = Ivp::new(&vdp, 0.0, &[2.0, 0.0], &[1.0]);
    let reference = ivp.solve(&Integrator::dopri5(1e-14, 1e-16), &[4.0]).unwrap();
    let errors: Vec<f64> = [0.1, 0.05, 0.025, 0.0125]
        .iter()
        .map(|&h| {
            let sol = ivp.solve(&Integrator::rodas5p(1e-8, 1e-10).with_fixed_step(h), &[4.0]);
            let (a, b) = (sol.unwrap().state(0).to_vec(), reference.state(0));
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
        })
        .collect();
    let orders = observed_orders(&errors);
    assert!(orders.iter().all(|p| (4.9..5.5).contains(p)), "orders {orders:?} from {errors:?}");
    assert!(orders[2] < 5.15, "orders {orders:?} from {errors:?}");
}

#[test]
fn dense_output_and_backward_integration() {
    let sys = Oscillator::new(false);
    let times: Vec<f64> = (0..5000).map(|i| 0.002 * i as f64 + 0.0007).collect();
    // Rodas4's dense output is of order 3, one below its steps; Rodas5P's of order 4.
    // Measured 9.8e-11 (918 steps) and 1.7e-11 (220 steps) at rtol 1e-10.
    for (scheme, bound) in ROSENBROCK.into_iter().zip([5e-10, 5e-11]) {
        let sol =
            Ivp::new(&sys, 0.0, &[1.0, 0.0], &[1.0]).solve(&scheme(1e-10, 1e-12), &times).unwrap();
        assert!((sol.counts().steps as usize) < times.len() / 2, "{:?}", sol.counts());
        let mut worst: f64 = 0.0;
        for (m, &t) in times.iter().enumerate() {
            let (x, v, _, _) = Oscillator::exact(1.0, 0.0, 1.0, t);
            worst = worst.max((sol.state(m)[0] - x).abs()).max((sol.state(m)[1] - v).abs());
        }
        assert!(worst < bound, "worst dense-output error {worst:e}");
    }

    let decay = Decay::new();
    let times = [-3.0, -1.0, 0.5, 2.0, 4.0];
    for scheme in ROSENBROCK {
        let sol = Ivp::new(&decay, 2.0, &[1.5], &[0.4])
            .solve_sensitivities(&scheme(1e-11, 1e-13), &[Wrt::Parameter(0)], &times)
            .unwrap();
        for (m, &t) in times.iter().enumerate() {
            let (x, _, dk) = Decay::exact(1.5, 0.4, t - 2.0);
            assert_close(sol.state(m)[0], x, 1e-9);
            assert_close_abs(sol.sensitivity(m)[(0, 0)], dk, 1e-9 * x.abs().max(1.0));
        }
    }
}

#[test]
fn the_automatic_choice_switches_only_on_stiff_problems() {
    let (rob, vdp, oscillator) =
        (Robertson::default(), VanDerPol::default(), Oscillator::new(false));
    let rates = robertson_rates();
    let robertson = Ivp::new(&rob, 0.0, &ROBERTSON_Y0, &rates);
    let auto = robertson.solve(&Integrator::auto(1e-8, 1e-14), &[40.0]).unwrap();
    assert!(auto.counts().jacobians > 0, "{:?}", auto.counts());
    let explicit = robertson.solve(&Integrator::dopri5(1e-8, 1e-14), &[40.0]).unwrap();
    // DOPRI5 gets there, limited by stability: tens of times more steps.
    assert!(explicit.counts().steps > 20 * auto.counts().steps, "{:?}", explicit.counts());
    for (a, b) in auto.state(0).iter().zip(explicit.state(0)) {
        assert_close_abs(*a, *b, 1e-7 * b.abs() + 1e-13);
    }
    // With a budget it cannot meet, DOPRI5 says why.
    let budget = Integrator::dopri5(1e-8, 1e-14).with_max_steps(10_000);
    match robertson.solve(&budget, &[40.0]) {
        Err(OdeError::Stiff { since, .. }) => assert!(since < 1.0, "stiff since {since}"),
        other => panic!("expected a stiffness error, got {other:?}"),
    }
    // Non-stiff problems never leave DOPRI5, at loose or tight tolerances.
    for tol in [1e-3, 1e-6, 1e-10] {
        let vdp = Ivp::new(&vdp, 0.0, &[2.0, 0.0], &[1.0]);
        let oscillator = Ivp::new(&oscillator, 0.0, &[1.0, 0.0], &[3.0]);
        for sol in [
            vdp.solve(&Integrator::auto(tol, tol), &[20.0]),
            oscillator.solve(&Integrator::auto(tol, tol), &[20.0]),
        ] {
            assert_eq!(sol.unwrap().counts().jacobians, 0, "switched at tolerance {tol}");
        }
    }
}

/// At rtol ≤ [`AUTO_DOP853_RTOL`] the automatic choice steps with DOP853 where it steps with
/// DOPRI5 above: on models that are not stiff its steps are `dop853`'s (states and
/// sensitivities to the bit, the same steps and rejections; its stiffness tests add
/// evaluations of f, not steps), at ten times that rtol `dopri5`'s; on Robertson's it still
/// switches to Rodas5P, and ends within the tolerance of DOPRI5 run at it throughout.
#[test]
fn the_automatic_choice_steps_with_dop853_at_tight_tolerances() {
    fn steps_as<S: sysid_ode::System>(ivp: &Ivp<'_, S>) {
        let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0)];
        let times = [0.5, 3.0, 20.0];
        for (rtol, explicit) in [
            (AUTO_DOP853_RTOL, Integrator::dop853 as fn(f64, f64) -> Integrator),
            (10.0 * AUTO_DOP853_RTOL, Integrator::dopri5),
        ] {
            let atol = 1e-3 * rtol;
            let auto =
                ivp.solve_sensitivities(&Integrator::auto(rtol, atol), &wrt, &times).unwrap();
            let alone = ivp.solve_sensitivities(&explicit(rtol, atol), &wrt, &times).unwrap();
            let (a, b) = (auto.counts(), alone.counts());
            assert_eq!((a.steps, a.rejected_steps, a.jacobians), (b.steps, b.rejected_steps, 0));
            for (m, t) in times.iter().enumerate() {
                assert_eq!(auto.state(m), alone.state(m), "rtol {rtol:e}, t = {t}");
                assert_eq!(auto.sensitivity_slice(m), alone.sensitivity_slice(m));
            }
        }
    }
    let (vdp, oscillator) = (VanDerPol::default(), Oscillator::new(false));
    steps_as(&Ivp::new(&vdp, 0.0, &[2.0, 0.0], &[1.0]));
    steps_as(&Ivp::new(&oscillator, 0.0, &[1.0, 0.0], &[3.0]));
    let (rob, rates) = (Robertson::default(), robertson_rates());
    let robertson = Ivp::new(&rob, 0.0, &ROBERTSON_Y0, &rates);
    let auto = robertson.solve(&Integrator::auto(AUTO_DOP853_RTOL, 1e-20), &[40.0]).unwrap();
    assert!(auto.counts().jacobians > 0, "{:?}", auto.counts());
    let explicit = robertson.solve(&Integrator::dopri5(AUTO_DOP853_RTOL, 1e-20), &[40.0]).unwrap();
    for (a, b) in auto.state(0).iter().zip(explicit.state(0)) {
        assert_close_abs(*a, *b, 1e-9 * b.abs() + 1e-19);
    }
}

/// Robertson's kinetics, declared [autonomous](sysid_ode::System::autonomous) or not: an
/// autonomous system's Rosenbrock step takes ∂f/∂t = 0 instead of differencing f in t. The
/// difference of an f that does not depend on t is exactly 0, so states and sensitivities
/// are the same to the last bit, with one evaluation of f fewer per step tried.
#[test]
fn an_autonomous_system_skips_the_time_derivative() {
    struct Declared(Robertson, bool);
    impl sysid_ode::System for Declared {
        fn signature(&self) -> &sysid_ode::Signature {
            self.0.signature()
        }
        fn rhs<T: sysid_ode::Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], dy: &mut [T]) {
            self.0.rhs(t, y, p, u, dy);
        }
        fn autonomous(&self) -> bool {
            self.1
        }
    }
    let times = [1.0, 40.0, 4e5];
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::InitialValue(0)];
    for scheme in ROSENBROCK {
        let integrator = scheme(1e-8, 1e-14);
        let [plain, declared] = [false, true].map(|autonomous| {
            Ivp::new(
                &Declared(Robertson::default(), autonomous),
                0.0,
                &ROBERTSON_Y0,
                &robertson_rates(),
            )
            .solve_sensitivities(&integrator, &wrt, &times)
            .unwrap()
        });
        for m in 0..times.len() {
            assert_eq!(plain.state(m), declared.state(m));
            assert_eq!(plain.sensitivity_slice(m), declared.sensitivity_slice(m));
        }
        let (a, b) = (plain.counts(), declared.counts());
        assert_eq!((a.steps, a.rejected_steps), (b.steps, b.rejected_steps));
        assert_eq!(
            a.rhs_evaluations - b.rhs_evaluations,
            a.steps + a.rejected_steps,
            "{a:?} {b:?}"
        );
    }
}

/// y′ = −λ(t)(y − cos t) − sin t with λ(t) = λ₀e^{−2t} + 1 (Prothero and Robinson's problem
/// with a fading rate): y = cos t from y(0) = 1 whatever λ, stiff at the start (λ₀ = 10⁴)
/// and not once λ has fallen to a few units (t ≳ 4.5).
struct Fading(sysid_ode::Signature);

impl sysid_ode::System for Fading {
    fn signature(&self) -> &sysid_ode::Signature {
        &self.0
    }
    fn rhs<T: sysid_ode::Scalar>(&self, t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let lambda = p[0] * (-2.0 * t).exp() + 1.0;
        dy[0] = -(lambda * (y[0] - t.cos())) - t.sin();
    }
}

/// The automatic choice leaves DOPRI5 while the rate is fast and comes back once it is not:
/// integrated to t = 40 it takes no Jacobian after t = 20 (the same count as integrated to
/// 20), where Rodas5P would take one at every step to the end; the solution is cos t to the
/// tolerance either way.
#[test]
fn the_automatic_choice_returns_to_dopri5_where_the_stiffness_ends() {
    let system = Fading(sysid_ode::Signature::new(&["y"], &["lambda0"]));
    let ivp = Ivp::new(&system, 0.0, &[1.0], &[1e4]);
    let times: Vec<f64> = (1..=80).map(|i| 0.5 * i as f64).collect();
    let (rtol, atol) = (1e-8, 1e-10);
    let auto = ivp.solve(&Integrator::auto(rtol, atol), &times).unwrap();
    let to_20 = ivp.solve(&Integrator::auto(rtol, atol), &times[..40]).unwrap();
    let implicit = ivp.solve(&Integrator::rodas5p(rtol, atol), &times).unwrap();
    let (a, a20, r) = (auto.counts(), to_20.counts(), implicit.counts());
    assert!(a.jacobians > 0, "it switched to Rodas5P while the rate was fast: {a:?}");
    assert_eq!(a.jacobians, a20.jacobians, "no implicit step after t = 20: {a:?}, {a20:?}");
    assert!(a.steps > a20.steps + 100, "{a:?}, {a20:?}");
    assert!(r.jacobians > r.steps / 2, "Rodas5P takes a Jacobian at every step: {r:?}");
    for (m, &t) in times.iter().enumerate() {
        assert_close_abs(auto.state(m)[0], t.cos(), 1e-6);
        assert_close_abs(implicit.state(m)[0], t.cos(), 1e-6);
    }
}

/// DOP853 on a stiff problem is limited by stability as DOPRI5 is, and says so when its
/// step budget runs out: its estimate of h·λ, on DOPRI5's scale, passes the same test.
#[test]
fn dop853_names_stiffness_when_its_budget_runs_out() {
    let (system, rates) = (Robertson::default(), robertson_rates());
    let robertson = Ivp::new(&system, 0.0, &ROBERTSON_Y0, &rates);
    let budget = Integrator::dop853(1e-8, 1e-14).with_max_steps(10_000);
    match robertson.solve(&budget, &[40.0]) {
        Err(e @ OdeError::Stiff { since, .. }) => {
            assert!(since < 1.0, "stiff since {since}");
            let message = e.to_string();
            assert!(
                message.contains("the explicit scheme's steps are limited by stability"),
                "{message}"
            );
        }
        other => panic!("expected a stiffness error, got {other:?}"),
    }
}
