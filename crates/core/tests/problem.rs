//! Setting up problems: every mistake is an error that names what is wrong.

use sysid_core::{Data, Problem, Unknown};
use sysid_ode::testing::assert_close;
use sysid_systems::FallingBody;

fn fall() -> FallingBody {
    FallingBody::default()
}

fn table() -> Data {
    Data::discrete().series("y", &[0.0, 1.0, 2.0, 3.0], &[0.0, 15.0, 65.0, 145.0])
}

fn error(
    f: impl FnOnce(sysid_core::ProblemBuilder<FallingBody>) -> sysid_core::ProblemBuilder<FallingBody>,
) -> String {
    let b = Problem::builder(fall()).data(table());
    f(b).build().unwrap_err().to_string()
}

#[test]
fn names_and_specification_errors() {
    assert_eq!(
        error(|b| b.unknown("y", 0.0).unknown("v", 0.0).unknown("h", 1.0)),
        "`h` is not a state or parameter of the system (states: y, v; parameters: g)"
    );
    assert_eq!(
        error(|b| b.unknown("y", 0.0).known("v", 0.0).unknown("v", 1.0).known("g", 32.0)),
        "`v` is given twice (as known and as unknown)"
    );
    assert_eq!(
        error(|b| b.unknown("y", 0.0).unknown("g", 32.0)),
        "state `v` is neither known nor unknown: give it a value or make it an unknown"
    );
    assert_eq!(
        error(|b| b.unknown("y", 0.0).known("v", 0.0)),
        "parameter `g` is neither known nor unknown: give it a value or make it an unknown"
    );
    assert_eq!(
        error(|b| b.known("y", 0.0).known("v", 0.0).known("g", 1.0)),
        "no unknowns: name at least one parameter or initial value to identify"
    );
    assert_eq!(
        error(|b| b.known("y", f64::NAN).known("v", 0.0).unknown("g", 1.0)),
        "invalid value for known `y`: NaN"
    );
}

#[test]
fn unknown_errors() {
    let e = |u: Unknown| error(|b| b.known("y", 0.0).known("v", 0.0).unknown_with(u));
    assert_eq!(
        e(Unknown::new("g", 1.0).log().min(-1.0)),
        "unknown `g`: a log-scale unknown needs a positive min, got -1"
    );
    assert_eq!(
        e(Unknown::new("g", -1.0).log()),
        "unknown `g`: a log-scale unknown needs a positive guess, got -1"
    );
    assert_eq!(
        e(Unknown::new("g", 1.0).min(2.0).max(1.0)),
        "unknown `g`: min 2 is not below max 1"
    );
    assert_eq!(
        e(Unknown::new("g", 5.0).max(1.0)),
        "unknown `g`: the guess 5 lies outside [-inf, 1]"
    );
    assert_eq!(
        e(Unknown::new("g", f64::INFINITY)),
        "unknown `g`: the guess inf is not a finite number"
    );
}

/// Fewer data than unknowns is a problem like any other (a likelihood the data cannot pin
/// down in every direction): it builds, with no degrees of freedom left.
#[test]
fn fewer_data_than_unknowns_is_a_problem() {
    let problem = Problem::builder(fall())
        .unknown("y", 0.0)
        .unknown("v", 0.0)
        .unknown("g", 1.0)
        .data(Data::discrete().series("y", &[0.0, 1.0], &[0.0, 1.0]))
        .build()
        .expect("builds");
    assert_eq!(problem.n_observations(), Some(2));
    assert_eq!(problem.dof(), Some(0));
}

#[test]
fn data_errors() {
    let e = |data: Data| {
        Problem::builder(fall())
            .unknown("y", 0.0)
            .unknown("v", 0.0)
            .unknown("g", 1.0)
            .data(data)
            .build()
            .unwrap_err()
    };
    assert_eq!(
        e(Data::discrete().series("z", &[0.0], &[1.0])).to_string(),
        "measured series `z` is not a state or output of the system (observable: y, v)"
    );
    // Discrete samples may repeat a time (replicates), not go back; a record's may not.
    assert_eq!(
        e(Data::discrete().series("y", &[0.0, 2.0, 1.0], &[0.0; 3])).to_string(),
        "measured series `y`: times must not decrease: 1 follows 2"
    );
    assert_eq!(
        e(Data::continuous(0.0, 2.0).series("y", &[0.0, 1.0, 1.0, 2.0], &[0.0; 4])).to_string(),
        "measured series `y`: times must increase: 1 follows 1"
    );
    assert_eq!(
        e(Data::discrete().series("y", &[0.0, 1.0, 2.0], &[0.0, f64::NAN, 1.0])).to_string(),
        "measured series `y`: value at t = 1 is NaN"
    );
    assert_eq!(
        e(Data::discrete().weighted_series("y", -1.0, &[0.0, 1.0, 2.0], &[0.0; 3])).to_string(),
        "measured series `y`: the weight must be positive and finite, got -1"
    );
    assert_eq!(
        e(Data::discrete()).to_string(),
        "no measurements: give at least one measured series or record"
    );
    assert_eq!(
        e(Data::discrete().function("y", 1.0, |t| t)).to_string(),
        "measured series `y`: a record given as a function needs continuous data"
    );
    assert_eq!(
        e(Data::continuous(1.0, 0.0).function("y", 1.0, |t| t)).to_string(),
        "invalid value for record span [1, 0]: -1"
    );
    let times = [0.0, 1.0, 2.0];
    assert_eq!(
        e(Data::discrete().series_with_weights("y", &times, &[0.0; 3], &[1.0, 2.0])).to_string(),
        "measured series `y`: 2 sample weights for 3 samples"
    );
    assert_eq!(
        e(Data::discrete().series_with_weights("y", &times, &[0.0; 3], &[1.0, 0.0, 1.0]))
            .to_string(),
        "measured series `y`: sample weight 1 must be positive and finite, got 0"
    );
    assert_eq!(
        e(Data::continuous(0.0, 2.0).series_with_weights("y", &times, &[0.0; 3], &[1.0; 3]))
            .to_string(),
        "measured series `y`: per-sample weights need discrete data"
    );
}

#[test]
fn per_sample_weights_weight_each_residual() {
    // Relative noise: w_m = 1 / (0.01 b_m)², so ε sums squared relative residuals.
    let (times, b) = ([0.5, 1.0, 2.0, 3.0], [4.0, 15.0, 65.0, 145.0]);
    let weights: Vec<f64> = b.iter().map(|v: &f64| 1.0 / (0.01 * v).powi(2)).collect();
    let problem = Problem::builder(fall())
        .known("y", 0.0)
        .known("v", 0.0)
        .unknown("g", 31.0)
        .data(Data::discrete().series_with_weights("y", &times, &b, &weights))
        .build()
        .unwrap();
    let z = problem.unknowns().coordinates(&[31.0]);
    let expected: f64 =
        times.iter().zip(b).map(|(t, b)| ((15.5 * t * t - b) / (0.01 * b)).powi(2)).sum();
    assert_close(problem.cost(&z).unwrap().0, expected, 1e-12);
    let lin = problem.linearize(&z).unwrap();
    assert_close(lin.cost, expected, 1e-12);
    // Row m of the Jacobian is √w_m ∂y(t_m)/∂g = t_m² / 2 / (0.01 b_m).
    let jac = &lin.residuals.as_ref().unwrap().jacobian;
    for (m, (t, b)) in times.iter().zip(b).enumerate() {
        assert_close(jac[(m, 0)], t * t / 2.0 / (0.01 * b), 1e-12);
    }
}

#[test]
fn coordinates_points_and_costs() {
    let problem = Problem::builder(fall())
        .t0(1.0)
        .known("y", 0.5)
        .unknown("v", 2.0)
        .unknown_with(Unknown::new("g", 30.0).log())
        .data(table())
        .build()
        .unwrap();
    let z = problem.unknowns().coordinates(&[2.0, 30.0]);
    assert_close(z[1], 30f64.ln(), 1e-15);
    let (y0, p) = problem.point(&z);
    assert_eq!(y0.len(), 2);
    assert_close(y0[0], 0.5, 0.0);
    assert_close(y0[1], 2.0, 0.0);
    assert_close(p[0], 30.0, 1e-15);
    // ε at z: y = 0.5 + 2 (t − 1) + 15 (t − 1)², from t0 = 1 on both sides.
    let cost: f64 = [0.0f64, 1.0, 2.0, 3.0]
        .iter()
        .zip([0.0, 15.0, 65.0, 145.0])
        .map(|(t, b)| (0.5 + 2.0 * (t - 1.0) + 15.0 * (t - 1.0).powi(2) - b).powi(2))
        .sum();
    let (c, _) = problem.cost(&z).unwrap();
    assert_close(c, cost, 1e-12);
    let lin = problem.linearize(&z).unwrap();
    assert_close(lin.cost, cost, 1e-12);
    // The chain rule of the log scale: ∂y/∂ln g = g ∂y/∂g = g (t − 1)² / 2.
    let jac = &lin.residuals.as_ref().unwrap().jacobian;
    assert_close(jac[(3, 1)], 30.0 * 4.0 / 2.0, 1e-12);
    assert_close(jac[(0, 1)], 30.0 / 2.0, 1e-12);
}

#[test]
fn residual_form_of_a_record_matches_its_integrals() {
    // ‖r‖², Jᵀr and JᵀJ at the Gauss–Legendre nodes against the adaptive quadratures.
    let record = |t: f64| 16.25 * t * t - 0.25 * t - 0.25 + 0.5 * (5.0 * t).sin();
    let times: Vec<f64> = (0..=60).map(|i| 0.05 * i as f64).collect();
    let values: Vec<f64> = times.iter().map(|&t| record(t)).collect();
    for data in [
        Data::continuous(0.0, 3.0).function("y", 2.0, record),
        Data::continuous(0.0, 3.0).weighted_series("y", 2.0, &times, &values),
    ] {
        let problem = Problem::builder(fall())
            .t0(1.0)
            .unknown("y", 0.3)
            .unknown("v", -0.5)
            .unknown_with(Unknown::new("g", 31.0).log())
            .data(data)
            .build()
            .unwrap();
        let z = problem.unknowns().coordinates(&[0.3, -0.5, 31.0]);
        let integral = problem.linearize(&z).unwrap();
        let nodes = problem.residuals_and_jacobian(&z).unwrap();
        assert_close(nodes.cost, integral.cost, 1e-12);
        assert_close(problem.residuals(&z).unwrap().0.norm_squared(), integral.cost, 1e-12);
        assert_close(problem.cost(&z).unwrap().0, integral.cost, 1e-12);
        for (a, b) in nodes.gradient.iter().zip(integral.gradient.iter()) {
            assert_close(*a, *b, 1e-11);
        }
        for (a, b) in nodes.normal.iter().zip(integral.normal.iter()) {
            assert_close(*a, *b, 1e-11);
        }
    }
}

#[test]
fn observed_values_and_bands_of_a_linear_model() {
    // y(t) = y0 + v0 (t − 1) + g (t − 1)²/2 with y0, v0, g unknown (g on a log scale, which
    // must not matter: the covariance is of the values): the band is t √(φ Cov φᵀ) with
    // φ = (1, t − 1, (t − 1)²/2), in closed form, and t the 97.5 % quantile of Student's t
    // for 4 data − 3 unknowns = 1 degree of freedom, the Cauchy quantile tan(0.475 π).
    let problem = Problem::builder(fall())
        .t0(1.0)
        .unknown("y", 0.0)
        .unknown("v", 0.0)
        .unknown_with(Unknown::new("g", 30.0).log())
        .data(table())
        .build()
        .unwrap();
    let values = [0.5, 2.0, 30.0];
    let cov = nalgebra::DMatrix::from_row_slice(
        3,
        3,
        &[0.04, 0.01, -0.002, 0.01, 0.09, 0.003, -0.002, 0.003, 0.25],
    );
    let times = [-1.0, 0.0, 0.5, 1.0, 2.5, 6.0];
    let quantile = sysid_core::confidence::t95(problem.dof().unwrap()).unwrap();
    let seen = problem.observed(&values, Some((&cov, quantile)), &times).unwrap();
    assert_eq!(seen.len(), 1);
    assert_eq!(seen[0].name, "y");
    let bands = seen[0].half_width.as_ref().unwrap();
    for (m, &t) in times.iter().enumerate() {
        let s = t - 1.0;
        assert_close(seen[0].values[m], 0.5 + 2.0 * s + 15.0 * s * s, 1e-9);
        let phi = nalgebra::DVector::from_vec(vec![1.0, s, s * s / 2.0]);
        let t1 = (0.475 * std::f64::consts::PI).tan();
        let half = t1 * phi.dot(&(&cov * &phi)).sqrt();
        // 1e-9: the sensitivities at rtol 1e-8 on a model whose solution is exact in
        // DOPRI5; cdflib's quantile is accurate to 4e-11.
        assert_close(bands[m], half, 1e-9);
    }
    let plain = problem.observed(&values, None, &times).unwrap();
    assert!(plain[0].half_width.is_none());
    // Values or a covariance of the wrong size are errors that say which, not panics.
    let error = problem.observed(&values[..2], None, &times).unwrap_err().to_string();
    assert!(error.contains("the values of the unknowns has length 2, expected 3"), "{error}");
    let small = cov.view((0, 0), (2, 3)).into_owned();
    let error = problem.trajectory(0, &values, Some((&small, quantile)), &times);
    let error = error.unwrap_err().to_string();
    assert!(error.contains("the covariance (rows) has length 2, expected 3"), "{error}");
}

/// Half the Hessian of ε by differences of the sensitivities' gradient, against its closed
/// form on the falling body with g on a log scale, θ = ln g: y = y0 + v (t − t0) + e^θ (t − t0)²/2
/// is linear in y0 and v but not in θ, so ½∇²ε = JᵀJ + Σ (y_i − b_i) ∂²y_i/∂θ² e_θ e_θᵀ with
/// ∂²y/∂θ² = g (t − t0)²/2, and the rest of the matrix is JᵀJ. The residuals are large
/// here (ε ≈ 1.6e4), so the added term is most of the (θ, θ) entry.
#[test]
fn the_differenced_hessian_is_the_full_hessian() {
    use sysid_core::method::{Evaluations, differenced_hessian};
    let problem = Problem::builder(fall())
        .t0(1.0)
        .unknown("y", 0.5)
        .unknown("v", 2.0)
        .unknown_with(Unknown::new("g", 30.0).log())
        .data(table())
        .build()
        .unwrap();
    let z = problem.unknowns().coordinates(&[0.5, 2.0, 30.0]);
    let ev = Evaluations::new(&problem, 100);
    let lin = ev.linearize(&z).unwrap();
    let h = differenced_hessian(&ev, &lin).unwrap().unwrap();
    // With s = (t − t0)²/2 and g = 30: the residual term Σ (y − b) g s, and the θ-derivative
    // of the (θ, θ) entry, 3 Σ (g s)² + Σ (y − b) g s.
    let (t, b) = ([0.0f64, 1.0, 2.0, 3.0], [0.0, 15.0, 65.0, 145.0]);
    let terms = t.iter().zip(b).map(|(t, b)| {
        let gs = 30.0 * (t - 1.0).powi(2) / 2.0;
        (0.5 + 2.0 * (t - 1.0) + gs - b, gs)
    });
    let second: f64 = terms.clone().map(|(r, gs)| r * gs).sum();
    let third: f64 = terms.map(|(r, gs)| 3.0 * gs * gs + r * gs).sum();
    assert!(second.abs() > lin.normal[(2, 2)], "the residual term dominates");
    // The forward difference in θ (h = √rtol·ln 30) is off by its first-order term, h/2
    // times the θ-derivative of the entry: `third` for (θ, θ), and the entry itself for
    // (y0, θ) and (v, θ) (each linear in g), halved there by the symmetrisation since the
    // other column, in y0 or v where U is linear, is exact. The falling body integrates
    // exactly, so what remains is O(h²).
    let h_theta = problem.integrator().rtol.sqrt() * 30f64.ln();
    for i in 0..3 {
        for j in 0..3 {
            let exact = lin.normal[(i, j)];
            let expected = match (i, j) {
                (2, 2) => exact + second + h_theta / 2.0 * third,
                (2, _) | (_, 2) => exact * (1.0 + h_theta / 4.0),
                _ => exact,
            };
            assert_close(h[(i, j)], expected, 1e-6);
        }
    }
}

/// A rate the data barely see (g at t ≤ 2e-3 against data 100 off): flat. Its descent points
/// at its lower bound; 3.3e-4 away (on its log scale) the move is one the cost cannot feel,
/// and `onto_bounds` puts it there; with no bound, or one 690 e-folds away, it stays where it
/// is (undetermined). With the data on the other side its descent points at its upper bound,
/// 1.2 e-folds away, a move the first-order test does not feel either: it still goes onto
/// the nearer bound, the hair's breadth (the sign of a flat unknown's slope says little).
#[test]
fn a_flat_unknown_a_hair_from_its_bound_is_moved_onto_it() {
    let with_data = |g: Unknown, b: f64| {
        Problem::builder(fall())
            .known("y", 0.0)
            .known("v", 0.0)
            .unknown_with(g)
            .data(Data::discrete().series("y", &[1e-3, 2e-3], &[b, b]))
            .build()
            .unwrap()
    };
    let with = |g: Unknown| with_data(g, -100.0);
    let other = with_data(Unknown::new("g", 30.0).log().min(29.99).max(100.0), 100.0);
    let lin = other.linearize(&other.unknowns().coordinates(&[30.0])).unwrap();
    assert!(lin.gradient[0] < 0.0, "descent points up, at 100: {}", lin.gradient[0]);
    let far = lin.normal[(0, 0)].sqrt() * (100f64 / 30.0).ln();
    assert!(far <= 1e-6 * lin.norm, "the far bound is within the first-order test's reach");
    let z = sysid_core::method::onto_bounds(&other, &lin, 1e-6).expect("moved");
    assert_eq!(z[0].to_bits(), 29.99f64.ln().to_bits(), "onto the nearer bound");
    let near = with(Unknown::new("g", 30.0).log().min(29.99).max(100.0));
    let lin = near.linearize(&near.unknowns().coordinates(&[30.0])).unwrap();
    let measure = sysid_core::method::optimality(&near, &lin, 1e-6);
    assert!(measure.flat[0] && measure.active[0].is_none(), "flat, off its bound: {measure:?}");
    let z = sysid_core::method::onto_bounds(&near, &lin, 1e-6).expect("moved");
    assert_eq!(z[0].to_bits(), 29.99f64.ln().to_bits(), "exactly on it");
    let moved = near.linearize(&z).unwrap();
    let held = sysid_core::method::optimality(&near, &moved, 1e-6);
    assert_eq!(held.active[0], Some(sysid_core::Bound::Lower), "held on it");
    for far in [Unknown::new("g", 30.0).log(), Unknown::new("g", 30.0).log().min(1e-299)] {
        let p = with(far);
        let lin = p.linearize(&p.unknowns().coordinates(&[30.0])).unwrap();
        assert!(sysid_core::method::optimality(&p, &lin, 1e-6).flat[0]);
        assert_eq!(sysid_core::method::onto_bounds(&p, &lin, 1e-6), None);
    }
}

/// A point with one coordinate too few took the guess for the missing unknown and gave a cost
/// for a point never asked for (found by a probe of the library): it panics, naming the
/// counts, as its `# Panics` says.
#[test]
#[should_panic(expected = "a point of 1 coordinates for 3 free unknowns (y, v, g)")]
fn a_point_of_the_wrong_length_is_not_evaluated() {
    let p = Problem::builder(fall())
        .data(table())
        .unknown("y", 0.0)
        .unknown("v", 0.0)
        .unknown("g", 32.0)
        .build()
        .unwrap();
    let _ = p.cost(&[1.0]);
}
