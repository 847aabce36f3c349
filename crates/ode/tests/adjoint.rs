//! Adjoint gradients G_j = Σ_m c_mᵀ S_j(t_m) against closed forms and against the forward
//! sensitivities' own sum: every column kind (initial values, parameters, given S(t0)), every
//! way a Jacobian is had (dual numbers, hand-written), explicit and implicit schemes, a stiff
//! system, and a switch that moves with a parameter.

use crate::common;

use common::Oscillator;
use sysid_ode::testing::{Decay, assert_close};
use sysid_ode::{Integrator, Ivp, OdeError, Scalar, Side, Signature, System, Wrt};
use sysid_systems::{LotkaVolterra, Robertson};

/// Σ_m c_mᵀ S_j(t_m) from the forward sensitivities.
fn forward_sum<S: System>(
    ivp: &Ivp<'_, S>,
    integrator: &Integrator,
    wrt: &[Wrt],
    s0: Option<&[f64]>,
    (times, seeds): (&[f64], &[f64]),
) -> Vec<f64> {
    let n = ivp.y0.len();
    let sol = match s0 {
        Some(s0) => ivp.solve_sensitivities_from(integrator, wrt, s0, times).unwrap(),
        None => ivp.solve_sensitivities(integrator, wrt, times).unwrap(),
    };
    (0..wrt.len())
        .map(|j| {
            (0..times.len())
                .map(|m| (0..n).map(|i| seeds[m * n + i] * sol.sensitivity(m)[(i, j)]).sum::<f64>())
                .sum()
        })
        .collect()
}

/// The adjoint's G along the forward solution at the same integrator.
fn adjoint_sum<S: System>(
    ivp: &Ivp<'_, S>,
    integrator: &Integrator,
    wrt: &[Wrt],
    s0: Option<&[f64]>,
    (times, seeds): (&[f64], &[f64]),
) -> Vec<f64> {
    let (_, forward) = ivp.solve_dense(integrator, times).unwrap();
    ivp.adjoint(integrator, wrt, s0, (&forward, times, seeds)).unwrap().0
}

/// Seeds that differ by state and time, some negative, one time without any.
fn seeds(n: usize, times: usize) -> Vec<f64> {
    (0..n * times)
        .map(|i| if i / n == 1 { 0.0 } else { ((i * 7 + 3) % 11) as f64 / 5.0 - 1.0 })
        .collect()
}

#[track_caller]
fn agree(actual: &[f64], expected: &[f64], tol: f64) {
    let size = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (a, e) in actual.iter().zip(expected) {
        assert!(
            (a - e).abs() <= tol * size,
            "adjoint {actual:?} against {expected:?}: {a:e} and {e:e} differ by more than {tol:e} of {size:e}"
        );
    }
}

/// x' = −k x: G = Σ c_m ∂x(t_m)/∂(x0, k) in closed form, with a sample at t0 itself and two at
/// one time.
#[test]
fn decay_gradient_matches_the_closed_form() {
    let sys = Decay::new();
    let times = [1.0, 2.0, 4.0, 4.0, 8.0];
    let c = [0.7, 1.0, 0.5, -2.0, 3.0];
    let ivp = Ivp::new(&sys, 1.0, &[2.0], &[0.3]);
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0)];
    for integrator in [
        Integrator::dopri5(1e-12, 1e-14),
        Integrator::dop853(1e-12, 1e-14),
        Integrator::rodas5p(1e-11, 1e-14),
        Integrator::bdf(1e-11, 1e-14),
    ] {
        let g = adjoint_sum(&ivp, &integrator, &wrt, None, (&times, &c));
        let (mut dk, mut dx0) = (0.0, 0.0);
        for (&t, &c) in times.iter().zip(&c) {
            let (_, e, k) = Decay::exact(2.0, 0.3, t - 1.0);
            (dk, dx0) = (dk + c * k, dx0 + c * e);
        }
        assert_close(g[0], dk, 1e-8);
        assert_close(g[1], dx0, 1e-8);
    }
}

/// Lotka–Volterra (dual-number Jacobians), all six columns, DOPRI5 and Rodas5P: the adjoint
/// and the forward sums agree to 1e-7 of the largest (both at rtol 1e-11).
#[test]
fn lotka_volterra_adjoint_agrees_with_forward_sensitivities() {
    let sys = LotkaVolterra::default();
    let p = [1.1, 0.4, 0.4, 0.1];
    let ivp = Ivp::new(&sys, 0.0, &[10.0, 10.0], &p);
    let wrt = [
        Wrt::InitialValue(0),
        Wrt::Parameter(0),
        Wrt::Parameter(1),
        Wrt::InitialValue(1),
        Wrt::Parameter(2),
        Wrt::Parameter(3),
    ];
    let times: Vec<f64> = (0..=15).map(|i| 1.0 + 0.9 * i as f64).collect();
    let c = seeds(2, times.len());
    for integrator in [
        Integrator::dopri5(1e-11, 1e-12),
        Integrator::dop853(1e-11, 1e-12),
        Integrator::rodas5p(1e-11, 1e-12),
        Integrator::bdf(1e-11, 1e-12),
    ] {
        let fwd = forward_sum(&ivp, &integrator, &wrt, None, (&times, &c));
        let adj = adjoint_sum(&ivp, &integrator, &wrt, None, (&times, &c));
        agree(&adj, &fwd, 1e-7);
    }
}

/// Given initial sensitivities S(t0) (an integration continued from another) and a subset of
/// the parameters, in another order.
#[test]
fn given_initial_sensitivities_enter_through_the_adjoint_at_t0() {
    let sys = LotkaVolterra::default();
    let ivp = Ivp::new(&sys, 0.5, &[8.0, 12.0], &[1.1, 0.4, 0.4, 0.1]);
    let wrt = [Wrt::Parameter(3), Wrt::Parameter(1)];
    let s0 = [0.3, -1.0, 2.0, 0.5];
    let times = [0.5, 1.5, 3.0, 6.0];
    let c = seeds(2, times.len());
    let integrator = Integrator::dopri5(1e-11, 1e-12);
    let fwd = forward_sum(&ivp, &integrator, &wrt, Some(&s0), (&times, &c));
    let adj = adjoint_sum(&ivp, &integrator, &wrt, Some(&s0), (&times, &c));
    agree(&adj, &fwd, 1e-7);
}

/// The oscillator's hand-written Jacobians give what its dual numbers give.
#[test]
fn hand_written_jacobians_give_the_same_adjoint() {
    let wrt = [Wrt::InitialValue(0), Wrt::InitialValue(1), Wrt::Parameter(0)];
    let times = [0.5, 2.0, 7.0];
    let c = seeds(2, times.len());
    let integrator = Integrator::rodas5p(1e-11, 1e-13);
    let run = |analytic| {
        let sys = Oscillator::new(analytic);
        let ivp = Ivp::new(&sys, 0.0, &[1.0, 0.3], &[1.7]);
        (
            adjoint_sum(&ivp, &integrator, &wrt, None, (&times, &c)),
            forward_sum(&ivp, &integrator, &wrt, None, (&times, &c)),
        )
    };
    let ((analytic, fwd), (dual, _)) = (run(true), run(false));
    agree(&analytic, &fwd, 1e-7);
    agree(&analytic, &dual, 1e-9);
}

/// Robertson's kinetics (stiff: rates over nine decades) with Rodas5P over five decades of
/// time: the adjoint's implicit steps solve with E = I/(γh) + J_yᵀ.
#[test]
fn stiff_robertson_adjoint_agrees_with_forward_sensitivities() {
    let sys = Robertson::default();
    let ivp = Ivp::new(&sys, 0.0, &[1.0, 0.0, 0.0], &[0.04, 3e7, 1e4]);
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::Parameter(2), Wrt::InitialValue(0)];
    let times: Vec<f64> = (0..12).map(|m| 10f64.powf(-2.0 + 6.0 * m as f64 / 11.0)).collect();
    // Weighted as a fit would weigh y2, which is 1e-5 the size of the others.
    let c: Vec<f64> =
        seeds(3, times.len()).chunks(3).flat_map(|s| [s[0], 1e4 * s[1], s[2]]).collect();
    for integrator in [Integrator::rodas5p(1e-10, 1e-14), Integrator::bdf(1e-10, 1e-14)] {
        let fwd = forward_sum(&ivp, &integrator, &wrt, None, (&times, &c));
        let (_, forward) = ivp.solve_dense(&integrator, &times).unwrap();
        let (adj, counts) = ivp.adjoint(&integrator, &wrt, None, (&forward, &times, &c)).unwrap();
        for (j, (a, f)) in adj.iter().zip(&fwd).enumerate() {
            assert_close(*a, *f, 1e-6 * if j == 1 { 1e3 } else { 1.0 });
        }
        assert!(counts.jacobians > 0, "the backward steps are implicit: {counts:?}");
    }
}

/// y′ = −k (y − a cos t): with k = 10⁴ the solution follows a cos t on the slow scale while
/// the Jacobian −k keeps every explicit step below 3.3/k.
struct Relaxing(Signature);
impl System for Relaxing {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * (y[0] - p[1] * T::from(t.cos()));
    }
}

/// The backward integration restarts at every sample, in parts, each from Hairer's first
/// step, and the automatic choice carries its scheme from part to part: on a model stiff
/// throughout, with 40 samples, the adjoint's gradient agrees with the forward
/// sensitivities' and the automatic choice takes no more steps than it did when every part
/// started with DOPRI5 (measured: 7 902 backward steps against 8 608, Rodas5P alone 5 219;
/// the parts' first steps are short enough that it goes back to DOPRI5 in most of them).
/// `a_continued_part_starts_where_the_last_one_ended` (src/driver.rs) holds the carry itself.
#[test]
fn a_stiff_adjoint_in_forty_parts_under_the_automatic_choice() {
    let sys = Relaxing(Signature::new(&["y"], &["k", "a"]));
    let ivp = Ivp::new(&sys, 0.0, &[2.0], &[1e4, 2.0]);
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::InitialValue(0)];
    let times: Vec<f64> = (1..=40).map(|m| 0.1 * m as f64).collect();
    let c = seeds(1, times.len());
    let (rtol, atol) = (1e-10, 1e-12);
    let integrator = Integrator::auto(rtol, atol);
    let (_, forward) = ivp.solve_dense(&integrator, &times).unwrap();
    let (adj, counts) = ivp.adjoint(&integrator, &wrt, None, (&forward, &times, &c)).unwrap();
    assert!(counts.steps + counts.rejected_steps <= 8_000, "{counts:?}");
    assert!(counts.jacobians > 0, "{counts:?}");
    let fwd = forward_sum(&ivp, &Integrator::rodas5p(rtol, atol), &wrt, None, (&times, &c));
    agree(&adj, &fwd, 1e-6);
}

/// x' = −k x + a before τ and −k x after: a switch at τ = p[2] that moves with it.
struct Dosed(Signature);
impl System for Dosed {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let dose = if t < p[2].re() { p[1] } else { T::from(0.0) };
        dy[0] = -p[0] * y[0] + dose;
    }
    fn switches(&self, p: &[f64]) -> Vec<f64> {
        vec![p[2]]
    }
    fn moving_switches(&self, p: &[f64]) -> Vec<(f64, usize, f64)> {
        vec![(p[2], 2, 1.0)]
    }
}

/// The switch's time τ is a column: the adjoint's λ(τ)ᵀ(g₋ − g₊) term gives ∂G/∂τ as the
/// forward sensitivities' jump does, and both equal the closed form a e^{−k(t−τ)} per sample
/// after τ (samples on both sides and one at τ itself, which sees the state before the jump).
#[test]
fn a_moving_switch_enters_the_adjoint() {
    let sys = Dosed(Signature::new(&["x"], &["k", "a", "tau"]));
    let p = [0.5, 2.0, 1.5];
    let ivp = Ivp::new(&sys, 0.0, &[1.0], &p);
    let wrt = [Wrt::Parameter(2), Wrt::Parameter(0), Wrt::Parameter(1)];
    let times = [0.5, 1.5, 2.0, 4.0];
    let c = [1.0, -0.5, 2.0, 1.5];
    let integrator = Integrator::dopri5(1e-11, 1e-13);
    let fwd = forward_sum(&ivp, &integrator, &wrt, None, (&times, &c));
    let adj = adjoint_sum(&ivp, &integrator, &wrt, None, (&times, &c));
    agree(&adj, &fwd, 1e-8);
    let dtau: f64 = times
        .iter()
        .zip(&c)
        .filter(|(t, _)| **t > p[2])
        .map(|(t, c)| c * p[1] * (-p[0] * (t - p[2])).exp())
        .sum();
    assert_close(adj[0], dtau, 1e-8);
}

/// What the adjoint cannot take is an error, not a panic or a wrong number.
#[test]
fn the_adjoint_refuses_what_it_cannot_do() {
    let sys = Decay::new();
    let ivp = Ivp::new(&sys, 1.0, &[2.0], &[0.3]);
    let integrator = Integrator::dopri5(1e-8, 1e-10);
    let wrt = [Wrt::Parameter(0)];
    assert!(matches!(ivp.solve_dense(&integrator, &[0.5, 2.0]), Err(OdeError::InvalidSetup(_))));
    let (_, forward) = ivp.solve_dense(&integrator, &[2.0, 3.0]).unwrap();
    let times = [2.0, 3.0];
    let wrong_length = ivp.adjoint(&integrator, &wrt, None, (&forward, &times, &[1.0]));
    assert!(matches!(wrong_length, Err(OdeError::InvalidSetup(_))));
    let nan = ivp.adjoint(&integrator, &wrt, None, (&forward, &times, &[1.0, f64::NAN]));
    assert!(matches!(nan, Err(OdeError::NonFinite { t: 3.0, .. })));
    let zero = ivp.adjoint(&integrator, &wrt, None, (&forward, &times, &[0.0, 0.0])).unwrap();
    assert_eq!(zero.0, vec![0.0]);
}

/// A parameter whose term is large where its quadrature starts at 0 (x0 = 1e12, so ∂g/∂k =
/// −1e12): Hairer's first-step estimate from ‖f‖ would put the first backward step below the
/// resolution of t (it did on Rahman's problem, in absolute time). The backward integration
/// runs in time local to each sample, where such a first step only costs a few more, and
/// meets the closed form.
#[test]
fn a_large_quadrature_derivative_does_not_stall_the_first_step() {
    let sys = Decay::new();
    let ivp = Ivp::new(&sys, 0.0, &[1e12], &[1e-3]);
    let times = [10.0, 20.0];
    let c = [1.0, 1.0];
    let integrator = Integrator::rodas5p(1e-8, 1e-12);
    let g = adjoint_sum(&ivp, &integrator, &[Wrt::Parameter(0)], None, (&times, &c));
    let expected: f64 = times.iter().map(|&t| Decay::exact(1e12, 1e-3, t).2).sum();
    assert_close(g[0], expected, 1e-6);
}

/// A fast state tied to a slow one, y₁' = −k(y₁ − y₂) + b, y₂' = −a y₂, with k = 1e12.
struct Tied(Signature);
impl System for Tied {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * (y[0] - y[1]) + p[2];
        dy[1] = -p[1] * y[1];
    }
}

/// Samples far from t = 0 on a system with a mode of rate 1e12 (Lang's problem, reduced). Each
/// jump of λ₁ at a sample sets the mode off backward, and its quadratures need steps near
/// 1e-13 to resolve it; at t = 1e5 no step in absolute time can be shorter than 16 ulps of t,
/// 2.3e-10 (the backward integration failed there before it ran in time local to each
/// sample). Forward, the fast state rides on the slow one from t0 on. The gradient agrees with
/// the forward sensitivities' to 1e-7 of the largest (measured 3.3e-9; 4e-6 when each part
/// started with the last step of the part before, which crossed the jump's fast modes).
#[test]
fn a_fast_mode_set_off_at_a_late_sample_is_resolved() {
    let sys = Tied(Signature::new(&["fast", "slow"], &["k", "a", "b"]));
    let p = [1e12, 1e-5, 3.0];
    let ivp = Ivp::new(&sys, 0.0, &[1.0, 1.0], &p);
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::Parameter(2), Wrt::InitialValue(1)];
    let times = [5e4, 1e5, 1e5 + 10.0];
    let c = [1.0, 0.0, 2.0, 0.5, -1.0, 0.0];
    let integrator = Integrator::rodas5p(1e-8, 1e-12);
    let fwd = forward_sum(&ivp, &integrator, &wrt, None, (&times, &c));
    let adj = adjoint_sum(&ivp, &integrator, &wrt, None, (&times, &c));
    agree(&adj, &fwd, 1e-7);
}

/// Two coupled states with a state event: where y0 falls to a·(1 + t/20) (a condition that
/// moves in time too), y0 gains d·y1 and y1 is scaled by r. Every derivative of the reset
/// and the condition is non-trivial: in y (both states), in t and in the parameters.
struct Kicked(Signature);
impl System for Kicked {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -p[0] * y[0] + p[1] * y[1];
        dy[1] = p[0] * y[0] - p[2] * y[1] * y[1];
    }
    fn n_events(&self) -> usize {
        1
    }
    fn event_condition<T: Scalar>(&self, _i: usize, t: f64, y: &[T], p: &[T]) -> T {
        y[0] - p[3] * (1.0 + t / 20.0)
    }
    fn event_reset<T: Scalar>(&self, _i: usize, _t: f64, y: &[T], p: &[T], y_new: &mut [T]) {
        y_new[0] = y[0] + p[4] * y[1];
        y_new[1] = y[1] * p[5];
    }
}

/// Back through state events: the adjoint's jump (λ⁻ = Mᵀλ⁺, μ += Nᵀλ⁺) gives the forward
/// sensitivities' sum, whose own jumps tests/events.rs checks against closed forms, for
/// every kind of column, explicit and implicit, with the events firing several times
/// between the samples.
#[test]
fn state_events_enter_the_adjoint() {
    let sys = Kicked(Signature::new(&["y0", "y1"], &["k", "c", "m", "a", "d", "r"]));
    let p = [0.8, 0.1, 0.3, 0.6, 2.0, 0.7];
    let ivp = Ivp::new(&sys, 0.0, &[2.0, 0.5], &p);
    let wrt: Vec<Wrt> =
        (0..6).map(Wrt::Parameter).chain([Wrt::InitialValue(0), Wrt::InitialValue(1)]).collect();
    let times = [0.7, 2.3, 4.1, 6.6, 9.2];
    let c = seeds(2, times.len());
    for integrator in [Integrator::dopri5(1e-11, 1e-13), Integrator::rodas5p(1e-10, 1e-13)] {
        let (trajectory, forward) = ivp.solve_dense(&integrator, &times).unwrap();
        let with = ivp.solve_sensitivities(&integrator, &wrt, &times).unwrap();
        for m in 0..times.len() {
            for i in 0..2 {
                assert_close(trajectory.state(m)[i], with.state(m)[i], 1e-8);
            }
        }
        let events: Vec<f64> = forward.event_times().collect();
        assert!(events.len() >= 3, "the events fire {} times", events.len());
        // The backward steps read y just below an event and just above it: the solution's
        // two one-sided limits there are the state on the condition's root and its reset.
        for &tau in &events {
            let (mut before, mut after, mut hint) = ([0.0; 2], [0.0; 2], 0);
            assert!(forward.eval_side(tau, Side::Before, &mut hint, &mut before));
            assert!(forward.eval_side(tau, Side::After, &mut hint, &mut after));
            assert_close(before[0], p[3] * (1.0 + tau / 20.0), 1e-9);
            assert_close(after[0], before[0] + p[4] * before[1], 1e-12);
            assert_close(after[1], before[1] * p[5], 1e-12);
        }
        let fwd = forward_sum(&ivp, &integrator, &wrt, None, (&times, &c));
        let adj = ivp.adjoint(&integrator, &wrt, None, (&forward, &times, &c)).unwrap().0;
        agree(&adj, &fwd, 1e-7);
        // The jump is felt: without it the reset's parameters d and r would have no gradient.
        assert!(fwd[4].abs() > 1e-3 && fwd[5].abs() > 1e-3, "{fwd:?}");
    }
}
