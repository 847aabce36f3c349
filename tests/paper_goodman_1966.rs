//! Goodman 1966, Section IV, reproduced number by number, and the continuous case of
//! Section III against a closed form.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use sysid::core::{Data, Method, Problem, Rule, Termination};
use sysid::goodman::{Goodman, newton_step};
use sysid::model::table::Table;
use sysid::ode::testing::{assert_close, assert_close_abs};
use sysid::systems::falling_body::{self, FallingBody, TABLE_I, continuous_record};

/// Rounding of a 4-point problem integrated in a handful of steps: the paper's numbers are
/// exact, ours carry a few ulps of the integration.
const ROUNDING: f64 = 1e-12;

#[test]
fn table_three_and_the_normal_matrix_at_the_start() {
    let problem = falling_body::falling_body().problem(1).unwrap();
    // c* = (0, 0, 32), eq. (29).
    let lin = problem.linearize(&[0.0, 0.0, 32.0]).unwrap();
    // U* = (−1, −4, −6) from Table III and eq. (12).
    for (u, expected) in lin.gradient.iter().zip([-1.0, -4.0, -6.0]) {
        assert_close(*u, expected, ROUNDING);
    }
    // The matrix of coefficients after Table III, eq. (15).
    let expected = [[4.0, 6.0, 7.0], [6.0, 14.0, 18.0], [7.0, 18.0, 24.5]];
    for (i, row) in expected.iter().enumerate() {
        for (j, &a) in row.iter().enumerate() {
            assert_close(lin.normal[(i, j)], a, ROUNDING);
        }
    }
    // Table III: y₁* − b_m = (0, 1, −1, −1), so ε* = 3.
    let r = &lin.residuals.as_ref().unwrap().r;
    for (ri, expected) in r.iter().zip([0.0, 1.0, -1.0, -1.0]) {
        assert_close_abs(*ri, expected, ROUNDING);
    }
    assert_close(lin.cost, 3.0, ROUNDING);
    // Table III's sensitivity columns δy₁ᵢ(t_m) = (1, t, t²/2).
    let jac = &lin.residuals.as_ref().unwrap().jacobian;
    for (m, t) in TABLE_I.0.iter().enumerate() {
        for (j, expected) in [1.0, *t, t * t / 2.0].iter().enumerate() {
            assert_close_abs(jac[(m, j)], *expected, ROUNDING);
        }
    }
}

#[test]
fn one_newton_step_is_exact_and_the_next_is_negligible() {
    let problem = falling_body::falling_body().problem(1).unwrap();
    let lin = problem.linearize(&[0.0, 0.0, 32.0]).unwrap();
    let unbounded = ([f64::NEG_INFINITY; 3], [f64::INFINITY; 3]);
    let step = newton_step(&lin, (&unbounded.0, &unbounded.1), 1e12).unwrap();
    let c: Vec<f64> = [0.0, 0.0, 32.0].iter().zip(&step.delta).map(|(c, d)| c + d).collect();
    // Eq. (28): A = −.25, B = −.25, α = 32.5.
    for (ci, expected) in c.iter().zip([-0.25, -0.25, 32.5]) {
        assert_close(*ci, expected, 1e-10);
    }
    // The second iteration's step is below 1e-10: the first one was exact.
    let again = problem.linearize(&c).unwrap();
    assert!(newton_step(&again, (&unbounded.0, &unbounded.1), 1e12).unwrap().delta.norm() < 1e-10);
    assert_close(again.cost, 1.25, ROUNDING);

    let estimate = Goodman::default().fit(&problem).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    assert_eq!(estimate.iterations, 1);
    for (v, expected) in estimate.values.iter().zip([-0.25, -0.25, 32.5]) {
        assert_close(*v, expected, 1e-10);
    }
    assert_close(estimate.cost, 1.25, ROUNDING);
    assert_close(estimate.history[0].cost, 3.0, ROUNDING);
    assert_eq!(estimate.history.len(), 2);
}

#[test]
fn standard_errors_match_linear_regression() {
    // The model is linear in (y0, v0, g): Cov = s² (XᵀX)⁻¹ with X = [1, t, t²/2] and
    // s² = ε / (N − k), computed here by an independent inverse.
    let problem = falling_body::falling_body().problem(1).unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    let x = DMatrix::from_fn(4, 3, |m, j| TABLE_I.0[m].powi(j as i32) / [1.0, 1.0, 2.0][j]);
    let inverse = (x.transpose() * &x).try_inverse().unwrap();
    let s2 = 1.25 / (4.0 - 3.0);
    let se = estimate.std_errors.as_ref().unwrap();
    for j in 0..3 {
        assert_close(se[j], (s2 * inverse[(j, j)]).sqrt(), 1e-10);
    }
    let cov = estimate.covariance.as_ref().unwrap();
    assert_close(cov[(0, 2)], s2 * inverse[(0, 2)], 1e-10);
}

/// The least-squares fit of (B, A, g/2) to b(t) over [0, 3]: the polynomial part of b is
/// matched exactly and 0.5 sin 5t is projected on {1, t, t²} through closed-form moments.
fn continuous_closed_form() -> ([f64; 3], f64) {
    let (s15, c15) = (15f64.sin(), 15f64.cos());
    let moments = Vector3::new(
        (1.0 - c15) / 5.0,
        s15 / 25.0 - 3.0 * c15 / 5.0,
        -9.0 * c15 / 5.0 + 6.0 * s15 / 25.0 + 2.0 * c15 / 125.0 - 2.0 / 125.0,
    );
    let gram = Matrix3::from_fn(|i, j| 3f64.powi((i + j + 1) as i32) / (i + j + 1) as f64);
    let projection = gram.try_inverse().unwrap() * moments;
    let c = Vector3::new(-0.25, -0.25, 16.25) + 0.5 * projection;
    // ε = ∫ (0.5 sin 5t)² − 0.25 sᵀ G⁻¹ s.
    let cost = 0.25 * (1.5 - 30f64.sin() / 20.0) - 0.25 * moments.dot(&projection);
    ([c[0], c[1], 2.0 * c[2]], cost)
}

#[test]
fn continuous_record_as_a_function() {
    let case = falling_body::falling_body_continuous();
    let reference = case.reference.clone().unwrap();
    // docs/catalogue.md's reference agrees with the closed form.
    let (exact, cost) = continuous_closed_form();
    for ((_, r), e) in reference.values.iter().zip(exact) {
        assert_close(*r, e, 1e-13);
    }
    assert_close(reference.cost, cost, 1e-13);

    let estimate = Goodman::default().fit(&case.problem(1).unwrap()).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    assert_eq!(estimate.iterations, 1, "linear model: one step");
    for (v, (name, r)) in estimate.values.iter().zip(&reference.values) {
        assert_close(*v, *r, 1e-8);
        assert_eq!(estimate.value(name), Some(*v));
    }
    assert_close(estimate.cost, cost, 1e-8);
}

#[test]
fn continuous_record_sampled_every_millisecond_from_csv() {
    let dir = std::env::temp_dir().join(format!("sysid-paper-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("record.csv");
    let mut text = String::from("t,y\n");
    for i in 0..=3000 {
        let t = i as f64 * 1e-3;
        text += &format!("{t},{}\n", continuous_record(t));
    }
    std::fs::write(&path, text).unwrap();
    let table = Table::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let (times, values) = table.samples("y").unwrap();
    assert_eq!(times.len(), 3001);

    let problem = Problem::builder(FallingBody::default())
        .unknown("y", 0.0)
        .unknown("v", 0.0)
        .unknown("g", 32.0)
        .data(Data::continuous(0.0, 3.0).series("y", &times, &values))
        .build()
        .unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    let (exact, cost) = continuous_closed_form();
    // Linear interpolation between 1 ms samples misrepresents b(t) by up to
    // Δ²·max|b''|/8 ≈ 6e-6 (b'' ≤ 45), so the estimates move by a few 1e-6: the tolerance is
    // absolute, in the units of each estimate (y(0) ≈ 0.145 is small against a record that
    // reaches 145, so a relative test would measure the wrong thing).
    for (v, e) in estimate.values.iter().zip(exact) {
        assert_close_abs(*v, e, 1e-5);
    }
    assert_close(estimate.cost, cost, 1e-5);
    // A sampled record has a sample count, hence standard errors.
    assert!(estimate.std_errors.is_some());
    assert!(matches!(estimate.termination, Termination::Converged(Rule::Gradient | Rule::Step)));
}

#[test]
fn weights_follow_equation_32() {
    // Position and velocity measured with weights w_y, w_v: the estimate is the weighted
    // linear least-squares solution, computed here by an independent solve.
    let times = [0.0, 0.5, 1.0, 2.0, 2.5, 3.0];
    let ys = [0.3, 4.1, 15.2, 64.0, 100.9, 145.5];
    let vs = [0.0, 15.8, 32.9, 64.4, 81.0, 97.2];
    let (wy, wv) = (4.0, 0.25);
    let problem = Problem::builder(FallingBody::default())
        .unknown("y", 0.0)
        .unknown("v", 0.0)
        .unknown("g", 30.0)
        .data(
            Data::discrete()
                .weighted_series("y", wy, &times, &ys)
                .weighted_series("v", wv, &times, &vs),
        )
        .build()
        .unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    // Rows [1, t, t²/2] for y and [0, 1, t] for v, scaled by √w.
    let mut x = DMatrix::zeros(12, 3);
    let mut b = DVector::zeros(12);
    for (m, &t) in times.iter().enumerate() {
        let (sy, sv) = (wy.sqrt(), wv.sqrt());
        x.set_row(m, &nalgebra::RowVector3::new(sy, sy * t, sy * t * t / 2.0));
        x.set_row(6 + m, &nalgebra::RowVector3::new(0.0, sv, sv * t));
        b[m] = sy * ys[m];
        b[6 + m] = sv * vs[m];
    }
    let exact = (x.transpose() * &x).lu().solve(&(x.transpose() * &b)).unwrap();
    for (v, e) in estimate.values.iter().zip(exact.iter()) {
        assert_close(*v, *e, 1e-10);
    }
    assert_close(estimate.cost, (&x * &exact - &b).norm_squared(), 1e-10);
}
