//! State events against closed forms: the located times, the resets, and the sensitivities'
//! jumps (with the term that moves the event with the unknowns), on every integrator.

use sysid_ode::testing::assert_close;
use sysid_ode::{Integrator, Ivp, OdeError, Scalar, Signature, System, Wrt};

/// x' = −k x; where x falls to a, x jumps up by d: a sawtooth. With N(t) the firings up to
/// t, x(t) = x0·e^{−kt}·((a + d)/a)^N, so ln x has the derivatives −t (k), 1/x0,
/// N(1/(a + d) − 1/a) (a) and N/(a + d) (d).
struct Sawtooth(Signature);

impl System for Sawtooth {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -(p[0] * y[0]);
    }
    fn n_events(&self) -> usize {
        1
    }
    fn event_condition<T: Scalar>(&self, _i: usize, _t: f64, y: &[T], p: &[T]) -> T {
        y[0] - p[1]
    }
    fn event_reset<T: Scalar>(&self, _i: usize, _t: f64, y: &[T], p: &[T], y_new: &mut [T]) {
        y_new[0] = y[0] + p[2];
    }
}

fn integrators() -> [Integrator; 5] {
    [
        Integrator::dopri5(1e-11, 1e-13),
        Integrator::dop853(1e-11, 1e-13),
        Integrator::rodas4(1e-10, 1e-12),
        Integrator::rodas5p(1e-10, 1e-12),
        Integrator::rk4(1e-3),
    ]
}

#[test]
fn a_sawtooth_fires_where_its_closed_form_does_with_exact_sensitivities() {
    let sys = Sawtooth(Signature::new(&["x"], &["k", "a", "d"]));
    let (x0, k, a, d): (f64, f64, f64, f64) = (3.0, 0.7, 1.0, 1.5);
    // Firings at ln(3)/0.7 = 1.569 and every ln(2.5)/0.7 = 1.309 after: the times below
    // lie between firings 0 and 5.
    let times = [0.5, 1.0, 2.0, 3.5, 4.0, 5.0, 7.3];
    let firings = |t: f64| {
        let (first, period) = ((x0 / a).ln() / k, ((a + d) / a).ln() / k);
        if t < first { 0.0 } else { ((t - first) / period).floor() + 1.0 }
    };
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0), Wrt::Parameter(1), Wrt::Parameter(2)];
    for integrator in integrators() {
        let sol = Ivp::new(&sys, 0.0, &[x0], &[k, a, d])
            .solve_sensitivities(&integrator, &wrt, &times)
            .unwrap();
        for (m, &t) in times.iter().enumerate() {
            let n = firings(t);
            let x = x0 * (-k * t).exp() * ((a + d) / a).powf(n);
            // RK4 at h = 1e-3: 1e-11 per step, the events located on its cubic interpolant.
            let tol = 1e-8;
            assert_close(sol.state(m)[0], x, tol);
            let s = sol.sensitivity(m);
            assert_close(s[(0, 0)], -t * x, tol);
            assert_close(s[(0, 1)], x / x0, tol);
            if n > 0.0 {
                assert_close(s[(0, 2)], n * x * (1.0 / (a + d) - 1.0 / a), tol);
                assert_close(s[(0, 3)], n * x / (a + d), tol);
            } else {
                let untouched = s[(0, 2)].abs().max(s[(0, 3)].abs()) < f64::MIN_POSITIVE;
                assert!(untouched, "{integrator:?} at {t}");
            }
        }
        // The state alone, without sensitivities, fires the same way.
        let alone = Ivp::new(&sys, 0.0, &[x0], &[k, a, d]).solve(&integrator, &times).unwrap();
        for (m, &t) in times.iter().enumerate() {
            let x = x0 * (-k * t).exp() * ((a + d) / a).powf(firings(t));
            assert_close(alone.state(m)[0], x, 1e-8);
        }
    }
}

/// x' = b; where t reaches T (a parameter), x is halved: x = bt before T and bt − bT/2 after,
/// so ∂x/∂T = −b/2 and ∂x/∂b = t − T/2 after T. The condition T − t depends on the time,
/// so the event moves with T only through the condition's own dependence on it.
struct Halved(Signature);

impl System for Halved {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, _y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = p[0];
    }
    fn n_events(&self) -> usize {
        1
    }
    fn event_condition<T: Scalar>(&self, _i: usize, t: f64, _y: &[T], p: &[T]) -> T {
        p[1] - t
    }
    fn event_reset<T: Scalar>(&self, _i: usize, _t: f64, y: &[T], _p: &[T], y_new: &mut [T]) {
        y_new[0] = y[0] * 0.5;
    }
}

#[test]
fn an_event_at_a_time_that_is_a_parameter_moves_with_it() {
    let sys = Halved(Signature::new(&["x"], &["b", "T"]));
    let (b, tau) = (2.0, 1.3);
    let times = [0.5, 2.0, 4.0];
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1)];
    for integrator in integrators() {
        let sol = Ivp::new(&sys, 0.0, &[0.0], &[b, tau])
            .solve_sensitivities(&integrator, &wrt, &times)
            .unwrap();
        assert_close(sol.state(0)[0], b * 0.5, 1e-12);
        assert_close(sol.sensitivity(0)[(0, 0)], 0.5, 1e-12);
        assert!(sol.sensitivity(0)[(0, 1)].abs() < f64::MIN_POSITIVE, "no event yet");
        for (m, &t) in times.iter().enumerate().skip(1) {
            assert_close(sol.state(m)[0], b * t - b * tau / 2.0, 1e-10);
            assert_close(sol.sensitivity(m)[(0, 0)], t - tau / 2.0, 1e-9);
            assert_close(sol.sensitivity(m)[(0, 1)], -b / 2.0, 1e-8);
        }
    }
}

/// An event two units in the last place before the end of the integration: no step fits
/// between them, so the integration ends there with the state after the event (x halved:
/// 2·4 − 2·T/2 = 4). Before, the step size collapsed there (`StepSizeTooSmall`).
#[test]
fn an_event_just_before_the_end_is_fired_and_ends_the_integration() {
    let sys = Halved(Signature::new(&["x"], &["b", "T"]));
    let tau = 4.0f64.next_down().next_down();
    for integrator in integrators() {
        let sol = Ivp::new(&sys, 0.0, &[0.0], &[2.0, tau]).solve(&integrator, &[4.0]).unwrap();
        assert_close(sol.state(0)[0], 4.0, 1e-10);
    }
}

#[test]
fn a_condition_already_met_at_the_start_does_not_fire() {
    // x0 = 0.5 < a = 1: the trigger is true from the start, and x only falls.
    let sys = Sawtooth(Signature::new(&["x"], &["k", "a", "d"]));
    let sol = Ivp::new(&sys, 0.0, &[0.5], &[0.7, 1.0, 1.5])
        .solve(&Integrator::dopri5(1e-11, 1e-13), &[3.0])
        .unwrap();
    assert_close(sol.state(0)[0], 0.5 * (-2.1f64).exp(), 1e-9);
}

#[test]
fn integrating_back_through_state_events_is_refused() {
    let sys = Sawtooth(Signature::new(&["x"], &["k", "a", "d"]));
    let err = Ivp::new(&sys, 2.0, &[3.0], &[0.7, 1.0, 1.5])
        .solve(&Integrator::dopri5(1e-11, 1e-13), &[0.0])
        .unwrap_err();
    assert!(matches!(err, OdeError::InvalidSetup(_)), "{err:?}");
    assert!(err.to_string().contains("forward in time only"), "{err}");
}

/// x' = −k x and z' = −m z; where x falls to a, z is halved. The reset leaves the
/// condition's state alone, so the event fires once, at τ = ln(x0/a)/k: z(t) = z0·e^{−mt}/2
/// after it. Before, the step landed on τ with the condition a hair above 0 (τ is located on
/// the trial step's interpolant, the retaken step's end differs by its error), so the event
/// fired again as soon as x fell on: z quartered, on DOPRI5 always and on Rosenbrock for
/// some parameter values.
struct Halving(Signature);

impl System for Halving {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -(p[0] * y[0]);
        dy[1] = -(p[2] * y[1]);
    }
    fn n_events(&self) -> usize {
        1
    }
    fn event_condition<T: Scalar>(&self, _i: usize, _t: f64, y: &[T], p: &[T]) -> T {
        y[0] - p[1]
    }
    fn event_reset<T: Scalar>(&self, _i: usize, _t: f64, y: &[T], _p: &[T], y_new: &mut [T]) {
        y_new[1] = y[1] * 0.5;
    }
}

#[test]
fn a_reset_that_leaves_its_condition_alone_fires_once() {
    let sys = Halving(Signature::new(&["x", "z"], &["k", "a", "m"]));
    let times = [1.0, 2.0, 3.0, 6.0];
    // τ = ln(3/0.2)/0.8 ≈ 3.39, at several rates and thresholds around it.
    for (k, a) in [(0.8, 0.2), (0.7, 0.2), (0.8, 0.25), (1.1, 0.3), (0.5, 0.1)] {
        let p = [k, a, 0.3];
        let tau = (3.0f64 / a).ln() / k;
        let wrt = [Wrt::Parameter(0)];
        for integrator in integrators() {
            let ivp = Ivp::new(&sys, 0.0, &[3.0, 1.0], &p);
            let plain = ivp.solve(&integrator, &times).unwrap();
            let with = ivp.solve_sensitivities(&integrator, &wrt, &times).unwrap();
            for (m, &t) in times.iter().enumerate() {
                let z = (-0.3 * t).exp() * if t > tau { 0.5 } else { 1.0 };
                let tol = if integrator.fixed_step.is_some() { 1e-8 } else { 1e-9 };
                assert_close(plain.state(m)[1], z, tol);
                assert_close(with.state(m)[1], z, tol);
            }
        }
    }
}
