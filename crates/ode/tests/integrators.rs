//! Integrators against closed forms: accuracy, dense output, direction, order of
//! convergence, discontinuities, and the errors that replace panics.

use crate::common;

use common::Oscillator;
use sysid_ode::testing::Decay;
use sysid_ode::testing::{assert_close, assert_close_abs};
use sysid_ode::{
    Inputs, Integrator, Ivp, OdeError, Scalar, Side, Signal, Signature, System, integrate,
};
use sysid_systems::FallingBody;

/// Tight tolerances for closed-form checks; the claim is 1e-9 relative.
fn tight() -> Integrator {
    Integrator::dopri5(1e-12, 1e-14)
}

#[test]
fn exponential_decay_matches_closed_form() {
    let sys = Decay::new();
    let times: Vec<f64> = (0..=20).map(|i| 0.5 * i as f64).collect();
    let sol = Ivp::new(&sys, 0.0, &[3.0], &[0.7]).solve(&tight(), &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        assert_close(sol.state(m)[0], Decay::exact(3.0, 0.7, t).0, 1e-9);
    }
}

#[test]
fn harmonic_oscillator_matches_closed_form() {
    let sys = Oscillator::new(false);
    let times: Vec<f64> = (1..=40).map(|i| 0.25 * i as f64).collect();
    let sol = Ivp::new(&sys, 0.0, &[1.0, 0.5], &[2.0]).solve(&tight(), &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        let (x, v, _, _) = Oscillator::exact(1.0, 0.5, 2.0, t);
        // Relative to the amplitude: x and v pass through zero.
        assert_close_abs(sol.state(m)[0], x, 1e-9 * 1.03);
        assert_close_abs(sol.state(m)[1], v, 1e-9 * 2.07);
    }
}

#[test]
fn falling_body_is_exact() {
    // A quadratic: DOPRI5 integrates it without truncation error.
    let sys = FallingBody::default();
    let times = [0.0, 1.0, 2.0, 3.0, 10.0];
    let sol = Ivp::new(&sys, 0.0, &[1.0, -2.0], &[32.0]).solve(&tight(), &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        assert_close_abs(sol.state(m)[0], 1.0 - 2.0 * t + 16.0 * t * t, 1e-12 * 1600.0);
        assert_close_abs(sol.state(m)[1], -2.0 + 32.0 * t, 1e-12 * 320.0);
    }
}

/// The oscillator at 2 000 output times, far more than the integrator's steps, so that the
/// values come from its dense output: the steps taken and the largest error against the
/// closed form.
fn dense_output_against_closed_form(integrator: &Integrator) -> (u64, f64) {
    let sys = Oscillator::new(false);
    let times: Vec<f64> = (0..2000).map(|i| 0.005 * i as f64 + 0.0013).collect();
    let sol = Ivp::new(&sys, 0.0, &[1.0, 0.0], &[1.0]).solve(integrator, &times).unwrap();
    let mut worst: f64 = 0.0;
    for (m, &t) in times.iter().enumerate() {
        let (x, v, _, _) = Oscillator::exact(1.0, 0.0, 1.0, t);
        worst = worst.max((sol.state(m)[0] - x).abs()).max((sol.state(m)[1] - v).abs());
    }
    (sol.counts().steps, worst)
}

#[test]
fn dense_output_between_steps_matches_closed_form() {
    let (steps, worst) = dense_output_against_closed_form(&Integrator::dopri5(1e-10, 1e-12));
    assert!(steps < 400, "{steps} steps");
    // The order-4 interpolant keeps the error at the level of the tolerance.
    assert!(worst < 1e-9, "worst dense-output error {worst:e}");
}

#[test]
fn backward_and_two_sided_integration() {
    let sys = Decay::new();
    // Initial value given at t0 = 2, data on both sides.
    let times = [-1.0, 0.0, 1.5, 2.0, 2.0, 3.0, 6.0];
    let sol = Ivp::new(&sys, 2.0, &[1.5], &[0.4]).solve(&tight(), &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        assert_close(sol.state(m)[0], Decay::exact(1.5, 0.4, t - 2.0).0, 1e-9);
    }
    let back = Ivp::new(&sys, 2.0, &[1.5], &[0.4]).solve(&tight(), &[0.0]).unwrap();
    assert_close(back.state(0)[0], 1.5 * (0.8f64).exp(), 1e-9);
}

/// Observed order p from errors at steps h and h/2: p = log2(e(h) / e(h/2)).
fn observed_orders(integrator: impl Fn(f64) -> Integrator, steps: &[f64]) -> Vec<f64> {
    let sys = Oscillator::new(false);
    let errors: Vec<f64> = steps
        .iter()
        .map(|&h| {
            let sol =
                Ivp::new(&sys, 0.0, &[1.0, 0.0], &[1.0]).solve(&integrator(h), &[10.0]).unwrap();
            let (x, v, _, _) = Oscillator::exact(1.0, 0.0, 1.0, 10.0);
            ((sol.state(0)[0] - x).powi(2) + (sol.state(0)[1] - v).powi(2)).sqrt()
        })
        .collect();
    errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect()
}

#[test]
fn rk4_converges_with_order_four() {
    let orders = observed_orders(Integrator::rk4, &[0.2, 0.1, 0.05, 0.025]);
    for p in orders {
        assert!((p - 4.0).abs() < 0.1, "observed order {p}");
    }
}

#[test]
fn dopri5_converges_with_order_five() {
    let orders =
        observed_orders(|h| Integrator::default().with_fixed_step(h), &[0.4, 0.2, 0.1, 0.05]);
    for p in orders {
        assert!((p - 5.0).abs() < 0.15, "observed order {p}");
    }
}

#[test]
fn dop853_converges_with_order_eight() {
    let orders =
        observed_orders(|h| Integrator::dop853(1e-8, 1e-10).with_fixed_step(h), &[1.0, 0.5, 0.25]);
    for p in orders {
        assert!((p - 8.0).abs() < 0.2, "observed order {p}");
    }
}

/// DOP853 against the closed forms at tight tolerances: at the steps' ends, between them
/// (2 000 output times from its dense output of order 7), and the parameter's sensitivity.
#[test]
fn dop853_matches_closed_forms_at_and_between_its_steps() {
    let tight = Integrator::dop853(1e-12, 1e-14);
    let sys = Decay::new();
    let times: Vec<f64> = (0..=20).map(|i| 0.5 * i as f64).collect();
    let sol = Ivp::new(&sys, 0.0, &[3.0], &[0.7]).solve(&tight, &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        assert_close(sol.state(m)[0], Decay::exact(3.0, 0.7, t).0, 1e-9);
    }
    let (steps, worst) = dense_output_against_closed_form(&Integrator::dop853(1e-10, 1e-12));
    assert!(steps < 100, "{steps} steps");
    assert!(worst < 1e-9, "worst dense-output error {worst:e}");
    let sys = Oscillator::new(false);
    let times: Vec<f64> = (1..=20).map(|i| 0.5 * i as f64).collect();
    let sol = Ivp::new(&sys, 0.0, &[1.0, 0.3], &[1.7])
        .solve_sensitivities(&tight, &[sysid_ode::Wrt::Parameter(0)], &times)
        .unwrap();
    for (m, &t) in times.iter().enumerate() {
        let (x, v, dx, dv) = Oscillator::exact(1.0, 0.3, 1.7, t);
        assert_close_abs(sol.state(m)[0], x, 1e-9);
        assert_close_abs(sol.state(m)[1], v, 2e-9);
        assert_close_abs(sol.sensitivity(m)[(0, 0)], dx, 1e-9 * (1.0 + t));
        assert_close_abs(sol.sensitivity(m)[(1, 0)], dv, 1e-9 * (1.0 + 2.0 * t));
    }
}

/// What DOP853 is for: at rtol 1e-12 it reaches DOPRI5's accuracy or better with fewer
/// evaluations of f, on a problem that is not stiff (the oscillator over 20 periods).
#[test]
fn dop853_needs_fewer_evaluations_than_dopri5_at_tight_tolerances() {
    let sys = Oscillator::new(false);
    let t_end = 40.0 * std::f64::consts::PI;
    let run = |integrator: Integrator| {
        let sol = Ivp::new(&sys, 0.0, &[1.0, 0.0], &[1.0]).solve(&integrator, &[t_end]).unwrap();
        let (x, v, _, _) = Oscillator::exact(1.0, 0.0, 1.0, t_end);
        let error = (sol.state(0)[0] - x).abs().max((sol.state(0)[1] - v).abs());
        (sol.counts().rhs_evaluations, error)
    };
    let (dopri5, dopri5_error) = run(Integrator::dopri5(1e-12, 1e-14));
    let (dop853, dop853_error) = run(Integrator::dop853(1e-12, 1e-14));
    assert!(dop853_error <= dopri5_error.max(1e-10), "{dop853_error:e} against {dopri5_error:e}");
    assert!(2 * dop853 < dopri5, "{dop853} evaluations against DOPRI5's {dopri5}");
}

/// x' = u(t) with a piecewise-constant input (a doublet).
struct Integrator1 {
    sig: Signature,
    inputs: Inputs,
}
impl System for Integrator1 {
    fn signature(&self) -> &Signature {
        &self.sig
    }
    fn rhs<T: Scalar>(&self, _t: f64, _y: &[T], _p: &[T], u: &[f64], dy: &mut [T]) {
        dy[0] = T::from(u[0]);
    }
    fn input_values(&self, t: f64, side: Side, u: &mut [f64]) {
        self.inputs.eval(t, side, u);
    }
    fn discontinuities(&self) -> &[f64] {
        self.inputs.jumps()
    }
}

#[test]
fn steps_stop_on_input_discontinuities() {
    let doublet = Signal::steps(0.0, &[(1.0, 1.0), (2.0, -1.0), (3.0, 0.0)]).unwrap();
    let sys = Integrator1 {
        sig: Signature::new(&["x"], &[]).with_inputs(&["u"]),
        inputs: Inputs::new(vec![doublet]),
    };
    let exact = |t: f64| (t - 1.0).clamp(0.0, 1.0) - (t - 2.0).clamp(0.0, 1.0);
    let times = [0.5, 1.0, 1.7, 2.0, 2.5, 3.0, 5.0];
    let integrators = [
        Integrator::dopri5(1e-8, 1e-10),
        Integrator::rk4(0.3),
        Integrator::rodas4(1e-8, 1e-10),
        Integrator::rodas5p(1e-8, 1e-10),
    ];
    // Exact up to rounding: every step lies inside a piece where u is constant. Rodas5P's
    // coefficients reach 165, and its rounding 2.1e-14 (measured); the others' stays
    // below 1e-14.
    for (integrator, rounding) in integrators.into_iter().zip([1e-14, 1e-14, 1e-14, 5e-14]) {
        let sol = Ivp::new(&sys, 0.0, &[0.0], &[]).solve(&integrator, &times).unwrap();
        for (m, &t) in times.iter().enumerate() {
            assert_close_abs(sol.state(m)[0], exact(t), rounding);
        }
        // Backward across the same jumps from t0 = 5.
        let back = Ivp::new(&sys, 5.0, &[0.0], &[]).solve(&integrator, &[0.0, 1.5, 2.5]).unwrap();
        assert_close_abs(back.state(0)[0], 0.0, rounding);
        // x(t) = x(5) − ∫_t^5 u = exact(t) − exact(5).
        assert_close_abs(back.state(1)[0], exact(1.5), rounding);
        assert_close_abs(back.state(2)[0], exact(2.5), rounding);
    }
}

/// x' = 1 before t = 1 and −1000 from it on, a switch written in the right-hand side (as a
/// model file's `if(lt(t, 1), 1, -1000)`) and declared as a stop.
struct Switched(Signature);
impl System for Switched {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, t: f64, _y: &[T], _p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = T::from(if t < 1.0 { 1.0 } else { -1000.0 });
    }
    fn switches(&self, _p: &[f64]) -> Vec<f64> {
        vec![1.0]
    }
}

/// An integration that ends (or starts) on a switch takes the right-hand side there from
/// inside its span, as at a switch between: x(1) = 1 from 0, and x(0) = 0 back from
/// x(1) = 1, exactly up to rounding. Before, the last stage evaluated the other branch and
/// the steps shrank to nothing at t = 1.
#[test]
fn an_integration_may_end_or_start_on_a_switch() {
    let sys = Switched(Signature::new(&["x"], &[]));
    let integrators = [
        Integrator::dopri5(1e-8, 1e-10),
        Integrator::rk4(0.3),
        Integrator::rodas4(1e-8, 1e-10),
        Integrator::rodas5p(1e-8, 1e-10),
    ];
    for integrator in integrators {
        let forward = Ivp::new(&sys, 0.0, &[0.0], &[]).solve(&integrator, &[0.5, 1.0]).unwrap();
        assert_close_abs(forward.state(1)[0], 1.0, 1e-13);
        let back = Ivp::new(&sys, 1.0, &[1.0], &[]).solve(&integrator, &[0.0]).unwrap();
        assert_close_abs(back.state(0)[0], 0.0, 1e-13);
        assert!(forward.counts().steps < 20 && back.counts().steps < 20, "{integrator:?}");
    }
}

/// y' = y²: y = 1/(1 − t) blows up at t = 1.
struct BlowUp(Signature);
impl System for BlowUp {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], _p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = y[0] * y[0];
    }
}

/// y' = −√y: y = (1 − t/2)² reaches 0 at t = 2, beyond which √y is NaN.
struct SqrtDecay(Signature);
impl System for SqrtDecay {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], _p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -y[0].sqrt();
    }
}

#[test]
fn finite_time_blow_up_is_reported_as_a_blow_up_at_the_singularity() {
    // y' = y², y(0) = 1: y = 1/(1 − t) grows without bound as t → 1. The step size collapses
    // there; the error says why, with the component and how far it grew.
    let sys = BlowUp(Signature::new(&["y"], &[]));
    let err = Ivp::new(&sys, 0.0, &[1.0], &[]).solve(&tight(), &[2.0]).unwrap_err();
    match &err {
        OdeError::BlowUp { t, what, value, start, steps } => {
            assert!((t - 1.0).abs() < 1e-6, "t = {t}");
            assert!(*steps > 0, "{steps} steps");
            assert_eq!(what, "state y");
            assert!(*value > sysid_ode::BLOW_UP_GROWTH, "{value}");
            assert_eq!(start.to_bits(), 1.0f64.to_bits());
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(err.to_string().starts_with("the solution blows up: state y reaches"), "{err}");
    // A step budget that runs out long before the singularity is not a blow-up.
    let err =
        Ivp::new(&sys, 0.0, &[1.0], &[]).solve(&tight().with_max_steps(5), &[0.9]).unwrap_err();
    assert!(matches!(err, OdeError::TooManySteps { .. }), "{err:?}");
}

#[test]
fn non_finite_values_are_reported_with_the_time() {
    let sys = SqrtDecay(Signature::new(&["y"], &[]));
    let err = Ivp::new(&sys, 0.0, &[1.0], &[]).solve(&tight(), &[3.0]).unwrap_err();
    match &err {
        OdeError::NonFinite { t, what } => {
            assert!((t - 2.0).abs() < 1e-3, "t = {t}");
            assert_eq!(what, "state y");
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(err.to_string().starts_with("state y became non-finite at t = 2.0"), "{err}");
    // With a fixed step the NaN is accepted into the state and reported the same way.
    let err = Ivp::new(&sys, 0.0, &[1.0], &[]).solve(&Integrator::rk4(0.3), &[3.0]).unwrap_err();
    assert!(matches!(err, OdeError::NonFinite { .. }), "{err:?}");
}

#[test]
fn step_budget_and_bad_requests_are_errors() {
    let sys = Oscillator::new(false);
    let ivp = Ivp::new(&sys, 0.0, &[1.0, 0.0], &[1.0]);
    let err = ivp.solve(&tight().with_max_steps(10), &[100.0]).unwrap_err();
    assert!(matches!(err, OdeError::TooManySteps { steps: 10, .. }), "{err:?}");
    let err = ivp.solve(&tight(), &[0.0, 2.0, 1.0]).unwrap_err();
    assert_eq!(err, OdeError::TimesOutOfOrder { index: 2, previous: 2.0, time: 1.0 });
    let err = ivp.solve(&tight(), &[f64::NAN]).unwrap_err();
    assert!(matches!(err, OdeError::InvalidInput { .. }), "{err:?}");
    let err = Ivp::new(&sys, 0.0, &[1.0], &[1.0]).solve(&tight(), &[1.0]).unwrap_err();
    assert!(matches!(err, OdeError::Dimension { expected: 2, actual: 1, .. }), "{err:?}");
    let err =
        Ivp::new(&sys, 0.0, &[1.0, 0.0], &[f64::INFINITY]).solve(&tight(), &[1.0]).unwrap_err();
    assert_eq!(err.to_string(), "invalid input: parameter w is inf");
    let err = ivp.solve(&Integrator { rtol: -1.0, ..tight() }, &[1.0]).unwrap_err();
    assert!(err.to_string().contains("rtol must be positive"), "{err}");
}

#[test]
fn raw_integrate_reports_work_and_final_state() {
    let sys = Decay::new();
    let mut rhs = sysid_ode::ModelRhs::new(&sys, &[1.0]);
    let mut steps = 0;
    let (counts, end) =
        integrate(&tight(), &mut rhs, (0.0, &[1.0]), 1.0, &[], |_| steps += 1).unwrap();
    assert_close(end[0], (-1.0f64).exp(), 1e-10);
    assert_eq!(counts.steps, steps);
    assert_eq!(counts.integrations, 1);
    // Six new stages per step (FSAL), the first evaluation, and two for the starting step.
    assert_eq!(counts.rhs_evaluations, 6 * (counts.steps + counts.rejected_steps) + 2);
}

#[test]
fn tiny_time_scales_are_not_mistaken_for_underflow() {
    // Steps of about 1e-15 near t = 0: only a step that no longer changes t is too small.
    let sys = Decay::new();
    let times = [1e-13, 3e-13, 5e-13];
    let sol = Ivp::new(&sys, 0.0, &[1.0], &[1e13]).solve(&tight(), &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        assert_close(sol.state(m)[0], Decay::exact(1.0, 1e13, t).0, 1e-9);
    }
}

#[test]
fn every_output_time_is_filled_even_when_t_plus_h_rounds_past_it() {
    // The configuration that exposed it: 4-point Gauss–Legendre nodes on 256 panels of [0, 3]
    // around t0 = 1, where the backward pass ends on the first node and t + h misses it by
    // one ulp. Each row must hold the solution, including the last of each direction.
    let sys = FallingBody::default();
    let h = 3.0 / 256.0;
    let nodes = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    let times: Vec<f64> =
        (0..256).flat_map(|i| nodes.map(|x| h * (i as f64 + 0.5) + 0.5 * h * x)).collect();
    let sol =
        Ivp::new(&sys, 1.0, &[0.3, -0.5], &[31.0]).solve(&Integrator::default(), &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        let exact = 0.3 - 0.5 * (t - 1.0) + 15.5 * (t - 1.0) * (t - 1.0);
        assert_close_abs(sol.state(m)[0], exact, 1e-12);
    }
}

#[test]
fn dense_solution_on_both_sides_evaluates_and_maps_exactly() {
    // Stored steps of a two-sided integration against the closed form, by plain and hinted
    // lookups, and a linear map of the stored solution against the map of the values.
    let sys = Oscillator::new(false);
    let (solution, _) = Ivp::new(&sys, 1.0, &[1.0, 0.5], &[2.0])
        .dense(&Integrator::dopri5(1e-10, 1e-12), &[], (-2.0, 4.0))
        .unwrap();
    assert_eq!(solution.span(), Some((-2.0, 4.0)));
    let mut hint = 0;
    let mut out = [0.0; 2];
    let mut mapped_out = [0.0];
    let mapped = solution.map(1, |x, o| o[0] = 3.0 * x[0] - x[1]);
    for i in 0..=600 {
        let t = -2.0 + 0.01 * i as f64;
        let (x, v, _, _) = Oscillator::exact(1.0, 0.5, 2.0, t - 1.0);
        assert!(solution.eval_hinted(t, &mut hint, &mut out));
        assert_close_abs(out[0], x, 1e-8);
        assert_close_abs(out[1], v, 2e-8);
        assert!(solution.eval(t, &mut out));
        assert_close_abs(out[0], x, 1e-8);
        assert!(mapped.eval(t, &mut mapped_out));
        assert_close_abs(mapped_out[0], 3.0 * out[0] - out[1], 1e-13);
    }
    assert!(!solution.eval(4.5, &mut out));
}

/// A → B → C with rates k1, k2, from (1, 0, 0).
struct Consecutive(Signature);

impl System for Consecutive {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * y[0];
        dy[1] = p[0] * y[0] - p[1] * y[1];
        dy[2] = p[1] * y[1];
    }
}

/// A purely relative tolerance (atol = 0) integrates states that start at 0 and
/// sensitivities that stay 0 (∂A/∂k2): a component with no scale and no error counts as
/// none, where 0/0 used to make the first state non-finite.
#[test]
fn a_purely_relative_tolerance_integrates_zero_components() {
    let sys = Consecutive(Signature::new(&["A", "B", "C"], &["k1", "k2"]));
    let (k1, k2) = (0.8, 0.3);
    let times: Vec<f64> = (1..=10).map(f64::from).collect();
    let wrt = [sysid_ode::Wrt::Parameter(0), sysid_ode::Wrt::Parameter(1)];
    for integrator in [Integrator::dopri5(1e-10, 0.0), Integrator::rodas5p(1e-10, 0.0)] {
        let sol = Ivp::new(&sys, 0.0, &[1.0, 0.0, 0.0], &[k1, k2])
            .solve_sensitivities(&integrator, &wrt, &times)
            .unwrap_or_else(|e| panic!("{:?}: {e}", integrator.scheme));
        for (m, &t) in times.iter().enumerate() {
            let b = k1 / (k2 - k1) * ((-k1 * t).exp() - (-k2 * t).exp());
            assert_close(sol.state(m)[1], b, 1e-8);
            assert_eq!(sol.sensitivity(m)[(0, 1)].to_bits(), 0f64.to_bits(), "∂A/∂k2 stays 0");
        }
    }
}

/// An rtol below 1e-14 asks for more than double precision holds: refused, by name.
#[test]
fn an_rtol_below_double_precision_is_refused() {
    let e = Integrator::dopri5(1e-300, 1e-12).validate().unwrap_err();
    assert_eq!(e.name, "rtol");
    assert!(e.problem.contains("at least 1e-14"), "{e}");
    assert!(Integrator::dopri5(1e-14, 1e-16).validate().is_ok());
    let e = Integrator::dopri5(1e-8, -1.0).validate().unwrap_err();
    assert_eq!(e.name, "atol");
}

/// A stiff linear system x' = A x that solves its own implicit steps and counts its own
/// calls, charging made-up costs ([`Rhs::costs`](sysid_ode::Rhs::costs)).
struct Charged {
    a: [[f64; 2]; 2],
    inverse: [[f64; 2]; 2],
    calls: (u64, u64, u64),
}

impl Charged {
    const COSTS: sysid_ode::Costs = sysid_ode::Costs { eval: 7, factor: 1000, solve: 30 };
}

impl sysid_ode::Rhs for Charged {
    fn dim(&self) -> usize {
        2
    }
    fn eval(&mut self, _t: f64, _side: Side, x: &[f64], dx: &mut [f64]) {
        self.calls.0 += 1;
        for (i, d) in dx.iter_mut().enumerate() {
            *d = self.a[i][0] * x[0] + self.a[i][1] * x[1];
        }
    }
    fn autonomous(&self) -> bool {
        true
    }
    fn factor(
        &mut self,
        _t: f64,
        _side: Side,
        _x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), sysid_ode::FactorError> {
        self.calls.1 += 1;
        let a = &self.a;
        let e = [[inv_gamma_h - a[0][0], -a[0][1]], [-a[1][0], inv_gamma_h - a[1][1]]];
        let det = e[0][0] * e[1][1] - e[0][1] * e[1][0];
        self.inverse = [[e[1][1] / det, -e[0][1] / det], [-e[1][0] / det, e[0][0] / det]];
        Ok(())
    }
    fn solve(&mut self, r: &mut [f64]) {
        self.calls.2 += 1;
        let m = &self.inverse;
        let (r0, r1) = (r[0], r[1]);
        r[0] = m[0][0] * r0 + m[0][1] * r1;
        r[1] = m[1][0] * r0 + m[1][1] * r1;
    }
    fn costs(&self) -> sysid_ode::Costs {
        Self::COSTS
    }
}

/// `Counts::operations` charges every evaluation, factorisation and solve what the right-hand
/// side says one costs, once each: against the right-hand side's own count of its calls, by
/// every scheme (the explicit ones never factorise; `auto` switches to Rodas5P on this stiff
/// system and factorises once more where it does; BDF factorises only now and then).
#[test]
fn operations_charge_every_call_its_cost() {
    use sysid_ode::Scheme;
    for scheme in
        [Scheme::Dopri5, Scheme::Dop853, Scheme::Rodas4, Scheme::Rodas5p, Scheme::Auto, Scheme::Bdf]
    {
        let mut rhs =
            Charged { a: [[-1.0, 0.5], [0.0, -2000.0]], inverse: [[0.0; 2]; 2], calls: (0, 0, 0) };
        let cfg = Integrator { scheme, ..Integrator::dopri5(1e-8, 1e-10) };
        let (counts, _) = integrate(&cfg, &mut rhs, (0.0, &[1.0, 1.0]), 5.0, &[], |_| {}).unwrap();
        let (evals, factors, solves) = rhs.calls;
        assert_eq!(counts.rhs_evaluations, evals, "{scheme:?}");
        assert_eq!(counts.jacobians, factors, "{scheme:?}");
        let c = Charged::COSTS;
        assert_eq!(
            counts.operations,
            c.eval * evals + c.factor * factors + c.solve * solves,
            "{scheme:?}: {evals} evaluations, {factors} factorisations, {solves} solves"
        );
        let implicit = !matches!(scheme, Scheme::Dopri5 | Scheme::Dop853);
        assert_eq!(factors > 0 && solves > 0, implicit, "{scheme:?}");
    }
}

/// A state that starts far below atol is still controlled where its size is given
/// ([`Ivp::sized`]): x′ = x from ±1e-14 under atol 1e-10 grows to ±1 at t = ln 1e14, where
/// it matches the closed form to 1e-4, by DOPRI5 and by Rodas5P: its floor is a thousandth
/// of its initial size at rtol 1e-8 (3e-5 measured). Without its size, atol is the state's
/// floor: the first steps hold it to nothing and it ends at 0.13 (87 % off). At a tenth of
/// rtol the floor is a tenth as large, and the error within 1e-5.
#[test]
fn a_state_that_starts_below_atol_is_held_to_its_own_size() {
    let sys = Decay::new();
    let t = 1e14f64.ln();
    let off = |scheme: Integrator, x0: f64, sized: bool| {
        let (y0, p) = ([x0], [-1.0]);
        let ivp = Ivp::new(&sys, 0.0, &y0, &p);
        let sizes = [x0];
        let ivp = if sized { ivp.sized(&sizes) } else { ivp };
        let sol = ivp.solve(&scheme, &[t]).unwrap();
        let exact = Decay::exact(x0, -1.0, t).0;
        ((sol.state(0)[0] - exact) / exact).abs()
    };
    let error = |scheme: Integrator, x0: f64| off(scheme, x0, true);
    let at_atol = off(Integrator::dopri5(1e-8, 1e-10), 1e-14, false);
    assert!(at_atol > 0.5, "held to atol: {at_atol:e}");
    type Scheme = fn(f64, f64) -> Integrator;
    for (name, scheme) in
        [("dopri5", Integrator::dopri5 as Scheme), ("rodas5p", Integrator::rodas5p)]
    {
        for x0 in [1e-14, -1e-14] {
            let (coarse, fine) = (error(scheme(1e-8, 1e-10), x0), error(scheme(1e-9, 1e-11), x0));
            assert!(coarse < 1e-4 && fine < 1e-5, "{name} from {x0}: {coarse:e}, {fine:e}");
        }
    }
}
