//! Goodman's method beyond the paper's example: convergence rate, termination reasons,
//! initial time inside the data, outputs, scales and bounds.

use sysid_core::{Data, Driven, Failure, FitError, Method, Problem, Termination, Unknown};
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_ode::testing::{Decay, assert_close};
use sysid_ode::{Integrator, Ivp, OdeError, Scalar, Signature, System};
use sysid_systems::{LotkaVolterra, VanDerPol};

fn tight() -> Integrator {
    Integrator::dopri5(1e-12, 1e-14)
}

/// Exact measurements of `observed` states of `sys` at `times`.
fn exact_data<S: System>(
    sys: &S,
    t0: f64,
    y0: &[f64],
    p: &[f64],
    times: &[f64],
    observed: &[usize],
) -> Data {
    let sol = Ivp::new(sys, t0, y0, p).solve(&tight(), times).unwrap();
    observed.iter().fold(Data::discrete(), |data, &i| {
        let values: Vec<f64> = (0..times.len()).map(|m| sol.state(m)[i]).collect();
        data.series(&sys.signature().states()[i], times, &values)
    })
}

fn vdp_problem(start: [f64; 3]) -> Problem<VanDerPol> {
    let sys = VanDerPol::default();
    let times: Vec<f64> = (0..=50).map(|i| 0.2 * i as f64).collect();
    let data = exact_data(&sys, 0.0, &[2.0, 0.0], &[1.0], &times, &[0]);
    Problem::builder(sys)
        .unknown("mu", start[0])
        .unknown("x", start[1])
        .unknown("v", start[2])
        .data(data)
        .integrator(tight())
        .build()
        .unwrap()
}

#[test]
fn converges_quadratically_on_a_zero_residual_problem() {
    let problem = vdp_problem([1.2, 1.9, 0.1]);
    let estimate = Goodman::default().fit(&problem).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    for (v, truth) in estimate.values.iter().zip([1.0, 2.0, 0.0]) {
        assert!((v - truth).abs() < 1e-9, "{:?}", estimate.values);
    }
    let errors: Vec<f64> = estimate
        .history
        .iter()
        .map(|h| {
            h.values.iter().zip([1.0, 2.0, 0.0]).map(|(v, t)| (v - t).powi(2)).sum::<f64>().sqrt()
        })
        .collect();
    // ‖e_{k+1}‖ / ‖e_k‖² stays bounded while the error is above the integration noise.
    let ratios: Vec<f64> =
        errors.windows(2).filter(|e| e[0] > 1e-6).map(|e| e[1] / (e[0] * e[0])).collect();
    assert!(ratios.len() >= 3, "errors {errors:?}");
    assert!(ratios.iter().all(|&r| r < 5.0), "ratios {ratios:?} (errors {errors:?})");
    assert!(estimate.cost < 1e-20, "{}", estimate.cost);
}

#[test]
fn iteration_limit_is_a_result_not_an_error() {
    let problem = vdp_problem([1.5, 1.5, 0.5]);
    let estimate =
        Goodman::new(GoodmanOptions::default().with_max_iterations(1)).fit(&problem).unwrap();
    // One iteration: too few for the window over which the fall is measured.
    assert_eq!(
        estimate.termination,
        Termination::MaxIterations { fell: None, moving: vec![], unresolved_gradient: None }
    );
    assert_eq!(estimate.iterations, 1);
    assert!(!estimate.converged());
    assert_eq!(estimate.history.len(), 2);
}

/// x' = −(a + b) x: only a + b influences the data.
#[derive(Clone)]
struct TwoRates(Signature);
impl System for TwoRates {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -(p[0] + p[1]) * y[0];
    }
}

/// A direction the data do not see is not a stop: the singular Newton system is
/// regularised at the solver's limit, the iteration goes on in the directions the data
/// determine, and the certificate at the returned point names the combination they cannot.
#[test]
fn a_singular_normal_matrix_is_regularised_and_named() {
    let sys = TwoRates(Signature::new(&["x"], &["a", "b", "c"]));
    let times = [0.5, 1.0, 2.0, 3.0];
    let data = exact_data(&sys, 0.0, &[1.0], &[0.3, 0.4, 0.0], &times, &[0]);
    // c does not appear in the model; a and b only through their sum.
    let problem = Problem::builder(sys.clone())
        .known("x", 1.0)
        .known("c", 0.0)
        .unknown("a", 0.2)
        .unknown("b", 0.2)
        .data(data.clone())
        .build()
        .unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    // The data came from a + b = 0.7: the valley of minima, reached exactly; the steps moved
    // a and b alike (the regularised step has no component along δa = −δb beyond what the
    // rounding of a matrix of condition ∞ leaves: 7e-8 here).
    let (a, b) = (estimate.values[0], estimate.values[1]);
    assert!((a + b - 0.7).abs() < 1e-8, "a + b = {}", a + b);
    assert!((a - b).abs() < 1e-6, "a − b = {}", a - b);
    let space = estimate.certificate.null_space.as_ref().expect("singular at the minimum");
    assert_eq!(space.unknowns, ["a", "b"]);
    assert!((space.direction[0] + space.direction[1]).abs() < 1e-8, "{:?}", space.direction);
    assert_eq!(space.combination(), "a − b");
    assert!(estimate.std_errors.is_none(), "no standard errors along a valley");

    // An unknown the model does not use keeps its value; the other is fitted.
    let problem = Problem::builder(sys)
        .known("x", 1.0)
        .known("a", 0.3)
        .unknown("b", 0.2)
        .unknown("c", 1.0)
        .data(data)
        .build()
        .unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    // c is not determined by the data: no convergence is claimed, and c is named.
    assert!(!estimate.converged(), "{}", estimate.termination);
    assert_eq!(estimate.undetermined(), ["c"]);
    assert!((estimate.values[0] - 0.4).abs() < 1e-8, "{:?}", estimate.values);
    assert_eq!(estimate.values[1].to_bits(), 1f64.to_bits(), "c keeps its value exactly");
    let space = estimate.certificate.null_space.as_ref().expect("c is not seen");
    assert_eq!(space.unknowns, ["c"]);
}

/// x' = p x²: x = 1/(1 − p t) blows up at t = 1/p.
#[derive(Clone)]
struct Riccati(Signature);
impl System for Riccati {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = p[0] * y[0] * y[0];
    }
}

#[test]
fn integration_failure_reports_where() {
    let sys = Riccati(Signature::new(&["x"], &["p"]));
    let times = [0.5, 1.0, 1.5, 2.0];
    let data = exact_data(&sys, 0.0, &[1.0], &[0.2], &times, &[0]);
    // From p = 1 the model blows up at t = 1, inside the data.
    let problem =
        Problem::builder(sys).known("x", 1.0).unknown("p", 1.0).data(data).build().unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    match &estimate.termination {
        Termination::StartFailed(Failure::Integration {
            error: OdeError::BlowUp { t, .. },
            at,
        }) => {
            assert!((t - 1.0).abs() < 1e-6, "{}", estimate.termination);
            assert_eq!(at, &[1.0]);
        }
        other => panic!("unexpected {other}"),
    }
    assert!(estimate.start_failed());
    assert!(estimate.cost.is_nan(), "no cost where the model cannot be integrated");
    assert_eq!(estimate.iterations, 0);
}

fn decay_problem(t0: f64, k: Unknown) -> Problem<Decay> {
    let sys = Decay::new();
    let times = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0];
    let data = exact_data(&sys, 0.0, &[2.0], &[0.8], &times, &[0]);
    let x0 = 2.0 * (-0.8 * t0).exp();
    Problem::builder(sys)
        .t0(t0)
        .unknown("x", x0 * 1.1)
        .unknown_with(k)
        .data(data)
        .integrator(tight())
        .build()
        .unwrap()
}

#[test]
fn initial_time_inside_the_data() {
    // x(t0 = 2) and k from data on [0, 4]: integration runs both ways from t0.
    let estimate = Goodman::default().fit(&decay_problem(2.0, Unknown::new("k", 0.6))).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    assert_close(estimate.value("x").unwrap(), 2.0 * (-1.6f64).exp(), 1e-9);
    assert_close(estimate.value("k").unwrap(), 0.8, 1e-9);
}

#[test]
fn log_scale_reports_values_and_bounds_hold() {
    let estimate =
        Goodman::default().fit(&decay_problem(0.0, Unknown::new("k", 0.3).log())).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    assert_close(estimate.value("k").unwrap(), 0.8, 1e-9);

    // With k ≥ 1 the best fit lies on the bound; every iterate respects it.
    let estimate =
        Goodman::default().fit(&decay_problem(0.0, Unknown::new("k", 1.3).min(1.0))).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    assert!(estimate.history.iter().all(|h| h.values[1] >= 1.0));
    assert_close(estimate.value("k").unwrap(), 1.0, 0.0);
    // With k held at 1 the model is linear in x(0): x = Σ b_m e^{−t_m} / Σ e^{−2 t_m}.
    let times = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0];
    let b = |t: f64| 2.0 * (-0.8 * t).exp();
    let x0 = times.iter().map(|&t| b(t) * (-t).exp()).sum::<f64>()
        / times.iter().map(|&t| (-2.0 * t).exp()).sum::<f64>();
    assert_close(estimate.value("x").unwrap(), x0, 1e-9);
}

#[test]
fn step_halving_keeps_the_cost_from_rising() {
    // From k = 4 the full Newton step on an exponential overshoots far past the answer.
    let plain = Goodman::default().fit(&decay_problem(0.0, Unknown::new("k", 4.0))).unwrap();
    let rises = plain.history.windows(2).any(|h| h[1].cost > h[0].cost);
    let halving = Goodman::new(GoodmanOptions::default().with_step_halving(true))
        .fit(&decay_problem(0.0, Unknown::new("k", 4.0)))
        .unwrap();
    assert!(halving.converged(), "{}", halving.termination);
    assert_close(halving.value("k").unwrap(), 0.8, 1e-9);
    assert!(halving.history.windows(2).all(|h| h[1].cost <= h[0].cost));
    assert!(rises || !plain.converged(), "the example should show what halving is for");
}

/// Lotka–Volterra measured only through the total x + y, an output function.
#[test]
fn measured_outputs_that_are_not_states() {
    let sys = LotkaVolterra::with_total();
    let times: Vec<f64> = (1..=40).map(|i| 0.25 * i as f64).collect();
    let sol =
        Ivp::new(&sys, 0.0, &[1.0, 1.0], &[1.5, 1.0, 3.0, 1.0]).solve(&tight(), &times).unwrap();
    let total: Vec<f64> = (0..times.len()).map(|m| sol.state(m)[0] + sol.state(m)[1]).collect();
    let problem = Problem::builder(sys)
        .knowns(&[("x", 1.0), ("y", 1.0), ("b", 1.0), ("d", 1.0)])
        .unknown("a", 1.4)
        .unknown("g", 3.2)
        .data(Data::discrete().series("total", &times, &total))
        .integrator(tight())
        .build()
        .unwrap();
    let estimate = Goodman::default().fit(&problem).unwrap();
    assert!(estimate.converged(), "{}", estimate.termination);
    assert_close(estimate.value("a").unwrap(), 1.5, 1e-9);
    assert_close(estimate.value("g").unwrap(), 3.0, 1e-9);
}

#[test]
fn misuse_is_an_error() {
    let problem = decay_problem(0.0, Unknown::new("k", 0.5));
    let method = Goodman::default();
    assert!(matches!(method.fit_from(&problem, &[1.0]), Err(FitError::InvalidStart(_))));
    assert!(matches!(method.fit_from(&problem, &[1.0, f64::NAN]), Err(FitError::InvalidStart(_))));
    let mut options = GoodmanOptions::default();
    options.driver.step_tolerance = -1.0;
    let bad = Goodman::new(options);
    assert!(matches!(bad.fit(&problem), Err(FitError::InvalidOptions(_))));
}

#[test]
fn step_halving_stops_when_the_cost_changes_only_by_noise() {
    // With noisy data the cost at the minimum moves only by integration noise, so a tiny
    // Newton step can look like an increase; halving must then declare convergence rather
    // than shrink steps to nothing (it once took 50 iterations of 31 integrations here).
    let case = sysid_systems::van_der_pol::van_der_pol();
    let problem = case.problem(1).unwrap();
    let plain = Goodman::default().fit(&problem).unwrap();
    let halving =
        Goodman::new(GoodmanOptions::default().with_step_halving(true)).fit(&problem).unwrap();
    assert!(
        plain.converged() && halving.converged(),
        "{} / {}",
        plain.termination,
        halving.termination
    );
    assert!(
        halving.iterations <= plain.iterations + 2,
        "{} vs {}",
        halving.iterations,
        plain.iterations
    );
    assert!(
        halving.counts.integrations <= 2 * plain.counts.integrations + 4,
        "{:?}",
        halving.counts
    );
    assert_close(halving.cost, plain.cost, 1e-10);
}

/// The unknowns on a bound at each iterate of a fit.
fn active_sets(e: &sysid_core::Estimate, problem: &Problem<impl System>) -> Vec<Vec<bool>> {
    e.history
        .iter()
        .map(|h| {
            problem
                .unknowns()
                .list()
                .iter()
                .zip(&h.values)
                .map(|(u, &v)| u.min == Some(v) || u.max == Some(v))
                .collect()
        })
        .collect()
}

#[test]
fn bounds_are_not_entered_and_left_on_alternate_iterations() {
    // The projected step solves the bounded quadratic model exactly, so an unknown is held by
    // the model's multiplier, not by the gradient's sign at the iterate: on the bounded cases
    // no unknown enters and leaves its bound repeatedly (the old sign rule let a rate
    // alternate until the iteration limit), the active set settles for the last iterates,
    // and step halving accepts only steps that lower the cost.
    let rates = sysid_systems::stress::rate_on_bound().problem(1).unwrap();
    check_monotone_active_sets(&rates, "rate-on-bound");
    let chain = sysid_systems::compartment_chain::compartment_chain().problem(1).unwrap();
    check_monotone_active_sets(&chain, "compartment-chain");
}

fn check_monotone_active_sets<S: System>(problem: &Problem<S>, name: &str) {
    for halving in [false, true] {
        let e = Goodman::new(GoodmanOptions::default().with_step_halving(halving))
            .fit(problem)
            .unwrap();
        assert!(e.converged(), "{name} (halving {halving}): {}", e.termination);
        let sets = active_sets(&e, problem);
        for i in 0..problem.unknowns().len() {
            let changes = sets.windows(2).filter(|w| w[0][i] != w[1][i]).count();
            assert!(changes <= 2, "{name}: unknown {i} alternates on its bound: {sets:?}");
        }
        let last = &sets[sets.len().saturating_sub(3)..];
        assert!(last.windows(2).all(|w| w[0] == w[1]), "{name}: the active set moves at the end");
        // One integration per iteration, one for the start, and at most two at finer
        // tolerances (the driver's watch on the measure's accuracy as the fit closes in, and
        // the certificate's integration error): bounds cost nothing extra.
        if !halving {
            let n = e.counts.integrations as usize;
            assert!((e.iterations + 2..=e.iterations + 3).contains(&n), "{name}: {n}");
        } else {
            let costs: Vec<f64> = e.history.iter().map(|h| h.cost).collect();
            assert!(costs.windows(2).all(|c| c[1] < c[0]), "{name}: costs {costs:?}");
        }
    }
}
