//! Forward sensitivities against closed forms and finite differences; Jacobians by dual
//! numbers against finite differences (property tests); quadratures against closed forms.

use crate::common;

use common::Oscillator;
use nalgebra::DMatrix;
use proptest::prelude::*;
use sysid_ode::testing::Decay;
use sysid_ode::testing::{assert_close, assert_close_abs};
use sysid_ode::{
    Integrator, Interpolation, Ivp, Observable, ObservableGradient, Record, RecordedOutput, Signal,
    System, Wrt,
};
use sysid_systems::{LotkaVolterra, VanDerPol};

fn tight() -> Integrator {
    Integrator::dopri5(1e-12, 1e-14)
}

#[test]
fn decay_sensitivities_match_closed_form_on_both_sides() {
    let sys = Decay::new();
    let times = [-2.0, 0.0, 1.0, 3.0, 8.0];
    let wrt = [Wrt::InitialValue(0), Wrt::Parameter(0)];
    let sol =
        Ivp::new(&sys, 1.0, &[2.0], &[0.3]).solve_sensitivities(&tight(), &wrt, &times).unwrap();
    for (m, &t) in times.iter().enumerate() {
        let (x, dx0, dk) = Decay::exact(2.0, 0.3, t - 1.0);
        assert_close(sol.state(m)[0], x, 1e-9);
        assert_close(sol.sensitivity(m)[(0, 0)], dx0, 1e-9);
        // ∂x/∂k vanishes at t0 (m = 2): compare with the envelope 2 e^{-k τ}.
        assert_close_abs(sol.sensitivity(m)[(0, 1)], dk, 1e-9 * x.abs().max(1.0));
    }
}

#[test]
fn oscillator_parameter_sensitivity_matches_closed_form() {
    let sys = Oscillator::new(false);
    let times: Vec<f64> = (1..=20).map(|i| 0.5 * i as f64).collect();
    let sol = Ivp::new(&sys, 0.0, &[1.0, 0.3], &[1.7])
        .solve_sensitivities(&tight(), &[Wrt::Parameter(0)], &times)
        .unwrap();
    for (m, &t) in times.iter().enumerate() {
        let (_, _, dx, dv) = Oscillator::exact(1.0, 0.3, 1.7, t);
        // ∂x/∂ω grows like t: compare with the size of its envelope.
        assert_close_abs(sol.sensitivity(m)[(0, 0)], dx, 1e-9 * (1.0 + t));
        assert_close_abs(sol.sensitivity(m)[(1, 0)], dv, 1e-9 * (1.0 + 2.0 * t));
    }
}

#[test]
fn hand_written_jacobians_give_the_same_sensitivities() {
    let wrt = [Wrt::InitialValue(0), Wrt::InitialValue(1), Wrt::Parameter(0)];
    let times = [0.5, 2.0, 7.0];
    let run = |analytic| {
        let sys = Oscillator::new(analytic);
        Ivp::new(&sys, 0.0, &[1.0, 0.3], &[1.7])
            .solve_sensitivities(&tight(), &wrt, &times)
            .unwrap()
    };
    let (dual, hand) = (run(false), run(true));
    for m in 0..times.len() {
        for (a, b) in dual.sensitivity_slice(m).iter().zip(hand.sensitivity_slice(m)) {
            assert_close_abs(*a, *b, 1e-12);
        }
    }
}

/// Central differences (y(z + δ) − y(z − δ)) / 2δ of the state at `times`, per column.
fn central_differences<S: System>(
    sys: &S,
    integrator: &Integrator,
    (y0, p): (&[f64], &[f64]),
    wrt: &[Wrt],
    times: &[f64],
    delta: f64,
) -> Vec<Vec<[f64; 2]>> {
    wrt.iter()
        .map(|w| {
            let solve = |s: f64| {
                let (mut y, mut q) = (y0.to_vec(), p.to_vec());
                match *w {
                    Wrt::InitialValue(i) => y[i] += s,
                    Wrt::Parameter(k) => q[k] += s,
                }
                Ivp::new(sys, 0.0, &y, &q).solve(integrator, times).unwrap()
            };
            let (plus, minus) = (solve(delta), solve(-delta));
            (0..times.len())
                .map(|m| [0, 1].map(|i| (plus.state(m)[i] - minus.state(m)[i]) / (2.0 * delta)))
                .collect()
        })
        .collect()
}

/// With a fixed step the computed sensitivities are the exact derivatives of the computed
/// solution (the RK scheme commutes with linearisation), so central differences of the
/// solution agree with them to the difference error O(δ²) plus rounding O(ε/δ).
#[test]
fn van_der_pol_sensitivities_match_central_differences() {
    let sys = VanDerPol::default();
    let integrator = Integrator::default().with_fixed_step(0.01);
    let times = [0.7, 3.0, 9.5, 20.0];
    let (y0, p) = ([2.0, 0.0], [1.0]);
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0), Wrt::InitialValue(1)];
    let sol = Ivp::new(&sys, 0.0, &y0, &p).solve_sensitivities(&integrator, &wrt, &times).unwrap();
    let fd = central_differences(&sys, &integrator, (&y0, &p), &wrt, &times, 1e-6);
    for (j, column) in fd.iter().enumerate() {
        for (m, at) in column.iter().enumerate() {
            for (i, &fd) in at.iter().enumerate() {
                let s = sol.sensitivity(m)[(i, j)];
                assert_close_abs(s, fd, 1e-7 * (1.0 + s.abs()));
            }
        }
    }
}

/// With error control the sensitivities are those of the variational equations, accurate to
/// the tolerance: compare with central differences of tightly integrated solutions.
#[test]
fn adaptive_sensitivities_match_central_differences() {
    let sys = LotkaVolterra::with_total();
    let (y0, p) = ([1.0, 1.0], [1.5, 1.0, 3.0, 1.0]);
    let times = [1.0, 4.0, 10.0];
    let wrt: Vec<Wrt> = (0..4).map(Wrt::Parameter).chain([Wrt::InitialValue(1)]).collect();
    let sol = Ivp::new(&sys, 0.0, &y0, &p).solve_sensitivities(&tight(), &wrt, &times).unwrap();
    let reference = Integrator::dopri5(1e-13, 1e-15);
    let fd = central_differences(&sys, &reference, (&y0, &p), &wrt, &times, 1e-5);
    for (j, column) in fd.iter().enumerate() {
        for (m, at) in column.iter().enumerate() {
            for (i, &fd) in at.iter().enumerate() {
                let s = sol.sensitivity(m)[(i, j)];
                // Difference error ~δ² |y‴| and integration noise ~1e-13/δ.
                assert_close_abs(s, fd, 1e-6 * (1.0 + s.abs()));
            }
        }
    }
}

#[test]
fn output_gradients_follow_the_chain_rule() {
    let sys = LotkaVolterra::with_total();
    let (y0, p) = ([1.0, 1.0], [1.5, 1.0, 3.0, 1.0]);
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(2), Wrt::InitialValue(0)];
    let sol = Ivp::new(&sys, 0.0, &y0, &p).solve_sensitivities(&tight(), &wrt, &[2.5]).unwrap();
    let mut og = ObservableGradient::new(&sys, &p, &wrt);
    let mut grad = [0.0; 3];
    let total =
        og.eval(2.5, sol.state(0), sol.sensitivity_slice(0), Observable::Output(0), &mut grad);
    assert_close(total, sol.state(0)[0] + sol.state(0)[1], 1e-15);
    let s = sol.sensitivity(0);
    for j in 0..3 {
        assert_close_abs(grad[j], s[(0, j)] + s[(1, j)], 1e-15);
    }
    let x = og.eval(2.5, sol.state(0), sol.sensitivity_slice(0), Observable::State(1), &mut grad);
    // A measured state is read off, not computed: exact.
    assert_close_abs(x, sol.state(0)[1], 0.0);
    assert_close_abs(grad[2], s[(1, 2)], 0.0);
}

/// Central differences of the right-hand side, for the property tests.
fn fd_jacobians<S: System>(sys: &S, y: &[f64], p: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, np) = (y.len(), p.len());
    let f = |y: &[f64], p: &[f64]| {
        let mut dy = vec![0.0; n];
        sys.rhs(0.0, y, p, &[], &mut dy);
        dy
    };
    let mut jy = DMatrix::zeros(n, n);
    let mut jp = DMatrix::zeros(n, np);
    for j in 0..n + np {
        let h = 1e-6;
        let (mut yp, mut ym, mut pp, mut pm) = (y.to_vec(), y.to_vec(), p.to_vec(), p.to_vec());
        if j < n {
            yp[j] += h;
            ym[j] -= h;
        } else {
            pp[j - n] += h;
            pm[j - n] -= h;
        }
        let (a, b) = (f(&yp, &pp), f(&ym, &pm));
        for i in 0..n {
            let d = (a[i] - b[i]) / (2.0 * h);
            if j < n { jy[(i, j)] = d } else { jp[(i, j - n)] = d }
        }
    }
    (jy, jp)
}

/// Dual-number Jacobians against central differences: O(h²)·|g‴| + O(ε/h), about 1e-9.
fn check_jacobians<S: System>(sys: &S, y: &[f64], p: &[f64]) -> Result<(), TestCaseError> {
    let (fjy, fjp) = fd_jacobians(sys, y, p);
    let mut jy = DMatrix::zeros(y.len(), y.len());
    let mut jp = DMatrix::zeros(y.len(), p.len());
    sys.jacobians(0.0, y, p, &[], &mut jy, &mut jp);
    for (e, f) in jy.iter().chain(jp.iter()).zip(fjy.iter().chain(fjp.iter())) {
        prop_assert!((e - f).abs() <= 1e-7 * (1.0 + e.abs()), "{} vs {}", e, f);
    }
    Ok(())
}

proptest! {
    #[test]
    fn dual_jacobians_match_finite_differences(
        x in -3.0..3.0f64, y in 0.1..3.0f64, a in 0.1..3.0f64, b in 0.1..3.0f64,
        g in 0.1..3.0f64, d in 0.1..3.0f64, mu in 0.0..5.0f64,
    ) {
        check_jacobians(&LotkaVolterra::with_total(), &[x.abs(), y], &[a, b, g, d])?;
        check_jacobians(&VanDerPol::default(), &[x, y], &[mu])?;
    }
}

/// x = e^{−kt} measured against b(t): ε, U, A over [0, T] in closed form for b ≡ 0.
#[test]
fn least_squares_integrals_match_closed_form() {
    let sys = Decay::new();
    let (k, t_end) = (0.8, 2.5);
    let outputs = [RecordedOutput {
        observable: Observable::State(0),
        weight: 2.0,
        record: Record::function(|_| 0.0),
    }];
    let q = Ivp::new(&sys, 0.0, &[1.0], &[k])
        .least_squares_integrals(
            &tight(),
            &[Wrt::Parameter(0), Wrt::InitialValue(0)],
            &outputs,
            (0.0, t_end),
            1e-12,
        )
        .unwrap();
    let e = (-2.0 * k * t_end).exp();
    // ∫ tⁿ e^{−2kt} dt on [0, T] for n = 0, 1, 2.
    let i0 = (1.0 - e) / (2.0 * k);
    let i1 = 1.0 / (4.0 * k * k) - e * (t_end / (2.0 * k) + 1.0 / (4.0 * k * k));
    let i2 = 2.0 / (8.0 * k.powi(3))
        - e * (t_end * t_end / (2.0 * k) + t_end / (2.0 * k * k) + 2.0 / (8.0 * k.powi(3)));
    assert_close(q.cost, 2.0 * i0, 1e-11);
    // x = e^{−kt}: ∂x/∂k = −t x, ∂x/∂x0 = x.
    assert_close(q.gradient[0], -2.0 * i1, 1e-11);
    assert_close(q.gradient[1], 2.0 * i0, 1e-11);
    assert_close(q.normal[(0, 0)], 2.0 * i2, 1e-11);
    assert_close(q.normal[(0, 1)], -2.0 * i1, 1e-11);
    assert_close_abs(q.normal[(0, 1)], q.normal[(1, 0)], 0.0);
    assert_close(q.normal[(1, 1)], 2.0 * i0, 1e-11);
}

#[test]
fn sampled_record_is_integrated_exactly_between_samples() {
    // A record that is linear between its samples is represented exactly by the samples, so
    // the sampled and the functional record give the same integrals; t0 inside the record.
    let sys = Oscillator::new(false);
    let b = |t: f64| 0.3 - 0.2 * t + if t > 1.0 { 0.5 * (t - 1.0) } else { 0.0 };
    let sample_times = vec![-1.0, 0.25, 1.0, 2.0, 4.0];
    let samples = Signal::new(
        sample_times.clone(),
        sample_times.iter().map(|&t| b(t)).collect(),
        Interpolation::Linear,
    )
    .unwrap();
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(1)];
    let run = |record: Record| {
        let outputs = [RecordedOutput { observable: Observable::State(0), weight: 1.0, record }];
        Ivp::new(&sys, 0.5, &[1.0, 0.0], &[1.3])
            .least_squares_integrals(&tight(), &wrt, &outputs, (-1.0, 4.0), 1e-12)
            .unwrap()
    };
    let (sampled, function) = (run(Record::Samples(samples)), run(Record::function(b)));
    assert_close(sampled.cost, function.cost, 1e-11);
    for (a, f) in sampled
        .normal
        .iter()
        .chain(sampled.gradient.iter())
        .zip(function.normal.iter().chain(function.gradient.iter()))
    {
        assert_close_abs(*a, *f, 1e-11 * (1.0 + f.abs()));
    }
}

/// x' = A x with the 9 entries of A as parameters: 12 sensitivity columns, more than one
/// chunk of dual numbers.
struct Linear3(sysid_ode::Signature);
impl System for Linear3 {
    fn signature(&self) -> &sysid_ode::Signature {
        &self.0
    }
    fn rhs<T: sysid_ode::Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        for i in 0..3 {
            dy[i] = p[3 * i] * y[0] + p[3 * i + 1] * y[1] + p[3 * i + 2] * y[2];
        }
    }
}

#[test]
fn many_columns_in_chunks_match_one_column_at_a_time() {
    let names = ["a0", "a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8"];
    let sys = Linear3(sysid_ode::Signature::new(&["x", "y", "z"], &names));
    let p = [-0.5, 0.2, 0.1, -0.3, -0.4, 0.25, 0.15, -0.2, -0.6];
    let y0 = [1.0, -0.5, 2.0];
    let wrt: Vec<Wrt> = (0..9).map(Wrt::Parameter).chain((0..3).map(Wrt::InitialValue)).collect();
    // A fixed step gives every run the same steps, so the columns must agree to rounding.
    let integrator = Integrator::default().with_fixed_step(0.05);
    let times = [0.5, 2.0, 3.0];
    let ivp = Ivp::new(&sys, 0.0, &y0, &p);
    let all = ivp.solve_sensitivities(&integrator, &wrt, &times).unwrap();
    for (j, w) in wrt.iter().enumerate() {
        let one = ivp.solve_sensitivities(&integrator, &[*w], &times).unwrap();
        for m in 0..times.len() {
            for i in 0..3 {
                assert_close_abs(all.sensitivity(m)[(i, j)], one.sensitivity(m)[(i, 0)], 1e-14);
            }
        }
    }
}

/// Inputs of the wrong size are errors, as the crate's docs promise (found by a probe of the
/// library, where they panicked): weights not one per column, an s0 not one per state and
/// column; and a first step that is not positive is an invalid setting.
#[test]
fn inputs_of_the_wrong_size_are_errors() {
    let sys = Decay::new();
    let wrt = [Wrt::InitialValue(0), Wrt::Parameter(0)];
    let ivp = Ivp::new(&sys, 0.0, &[2.0], &[0.3]);
    let weighted = Ivp::new(&sys, 0.0, &[2.0], &[0.3]).weighted(&[]);
    let e = weighted.solve_sensitivities(&tight(), &wrt, &[1.0]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "dimension mismatch: the sensitivity columns' weights has length 0, expected 2"
    );
    let e = ivp.solve_sensitivities_from(&tight(), &wrt, &[1.0], &[1.0]).unwrap_err();
    assert_eq!(e.to_string(), "dimension mismatch: s0 has length 1, expected 2");
    let from = ivp.solve_sensitivities_from(&tight(), &wrt, &[1.0, 0.0], &[1.0]).unwrap();
    let (x, dx0, dk) = Decay::exact(2.0, 0.3, 1.0);
    assert_close(from.state(0)[0], x, 1e-9);
    assert_close(from.sensitivity(0)[(0, 0)], dx0, 1e-9);
    assert_close(from.sensitivity(0)[(0, 1)], dk, 1e-9);
    let first = Integrator { initial_step: Some(-1.0), ..tight() };
    assert!(first.validate().unwrap_err().to_string().contains("initial_step"));
    let sized = Ivp::new(&sys, 0.0, &[2.0], &[0.3]).sized(&[2.0, 1.0]);
    let e = sized.solve(&tight(), &[1.0]).unwrap_err();
    assert_eq!(e.to_string(), "dimension mismatch: state sizes has length 2, expected 1");
}

/// A state that starts far below atol, its size given ([`Ivp::sized`]), holds its
/// sensitivities to its own floor too: for
/// x′ = −k x from 1e-14 at k = −1 under atol 1e-10, the columns x0·∂x/∂x0 and k·∂x/∂k (a fit
/// in ln x0 and ln k) match the closed form at t = ln 1e14, where x = 1, to 1e-4: the state's
/// floor is a thousandth of its initial size at rtol 1e-8 (with atol as the floor all three
/// were 79 % off).
#[test]
fn sensitivities_of_a_state_below_atol_are_held_to_its_floor() {
    let sys = Decay::new();
    let (x0, k, t) = (1e-14, -1.0, 1e14f64.ln());
    let wrt = [Wrt::InitialValue(0), Wrt::Parameter(0)];
    let weights = [x0, k];
    let sizes = [x0];
    let sol = Ivp::new(&sys, 0.0, &[x0], &[k])
        .sized(&sizes)
        .weighted(&weights)
        .solve_sensitivities(&Integrator::dopri5(1e-8, 1e-10), &wrt, &[t])
        .unwrap();
    let (x, dx0, dk) = Decay::exact(x0, k, t);
    assert_close(sol.state(0)[0], x, 1e-4);
    assert_close(sol.sensitivity(0)[(0, 0)], dx0, 1e-4);
    assert_close(sol.sensitivity(0)[(0, 1)], dk, 1e-4);
}
