//! Every claim of convergence, checked by a search the methods do not share.
//!
//! Every method (at most [`MAX_ITERATIONS`] iterations) runs on every catalogue system and every stress case
//! (`sysid_systems::stress`: an optimum on a bound, a residual norm of 1e5, rates of 1e-5, a
//! 23-unknown bounded chain, a blow-up, a singular direction away from the start) from the
//! default start and from seeded random starts at ±30 % and ±90 % around the truth. Whenever
//! a method says converged, a bounded Levenberg–Marquardt search written here (central
//! finite differences on an integration 1000 times tighter than the fits', projection on the
//! bounds) starts at the returned point and must not find a cost lower by more than 1e-6
//! relative (or 1e-20 ‖W^½ b‖², the exact-fit floor). Whenever it says not converged, its
//! JSON report is printed and parses, with the best point it kept. In every case the reported
//! cost is the cost at the reported values.

use std::sync::Mutex;

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sysid::core::{Problem, Termination, method::exact_fit_tolerance};
use sysid::montecarlo::perturb;
use sysid::ode::{Integrator, System};
use sysid::registry::{Boxed, Registry, Settings};
use sysid::systems::{self, Case, Visit, stress};

/// Most iterations of a run here. The claims are what is checked, not how far a budget
/// takes a method: at 1 000, quasilinearization's run on van-der-pol-three-point
/// that never converges took 80 of the test's 160 seconds alone.
const MAX_ITERATIONS: usize = 250;

/// The laboratory's methods, from the registry, with the default settings but
/// [`MAX_ITERATIONS`].
fn methods<S: System>() -> Vec<Boxed<S>> {
    let mut settings = Settings::default();
    settings.driver.max_iterations = MAX_ITERATIONS;
    Registry::<S>::standard().build_all(&settings).into_iter().map(|(_, m)| m).collect()
}

/// The cost an independent search may find below a certified point: 1e-6 relative, or the
/// exact-fit floor for a zero-residual problem.
fn allowance<S: System>(problem: &Problem<S>, cost: f64) -> f64 {
    1e-6 * cost + (exact_fit_tolerance(problem) * problem.data_norm()).powi(2)
}

/// The same problem integrated 1000 times tighter (rtol not below 1e-12).
fn tight<S: System + Clone>(problem: &Problem<S>) -> Problem<S> {
    let i = *problem.integrator();
    let integrator = Integrator {
        rtol: (i.rtol / 1000.0).max(1e-12),
        atol: i.atol / 1000.0,
        max_steps: i.max_steps.max(1_000_000),
        ..i
    };
    problem.clone().with_integrator(integrator).expect("a valid integrator")
}

/// A bounded Levenberg–Marquardt search from z (coordinates) on `problem`'s residuals, with
/// central-difference Jacobians: the lowest cost it finds in a few iterations.
fn search<S: System>(problem: &Problem<S>, z0: &[f64]) -> f64 {
    let unknowns = problem.unknowns();
    let bounds: Vec<(f64, f64)> = unknowns.list().iter().map(|u| u.coordinate_bounds()).collect();
    let residuals = |z: &[f64]| problem.residuals(z).ok().map(|(r, _)| r);
    let Some(mut r) = residuals(z0) else { return f64::NAN };
    let mut z = z0.to_vec();
    let mut cost = r.norm_squared();
    let mut lambda = 1e-3;
    for _ in 0..8 {
        let k = z.len();
        let mut jacobian = DMatrix::zeros(r.len(), k);
        for j in 0..k {
            let h = 1e-6 * z[j].abs().max(1e-3 * z0[j].abs()).max(1e-12);
            let (mut up, mut down) = (z.clone(), z.clone());
            up[j] += h;
            down[j] -= h;
            let (Some(ru), Some(rd)) = (residuals(&up), residuals(&down)) else { return cost };
            jacobian.set_column(j, &((ru - rd) / (up[j] - down[j])));
        }
        let g = jacobian.tr_mul(&r);
        let a = jacobian.tr_mul(&jacobian);
        let mut improved = false;
        for _ in 0..12 {
            let damped = DMatrix::from_fn(k, k, |i, j| {
                a[(i, j)] + if i == j { lambda * a[(i, i)].max(1e-300) } else { 0.0 }
            });
            let Some(step) = damped.lu().solve(&(-&g)) else { break };
            let trial: Vec<f64> = z
                .iter()
                .zip(step.iter())
                .zip(&bounds)
                .map(|((z, d), (lo, hi))| (z + d).clamp(*lo, *hi))
                .collect();
            match residuals(&trial) {
                Some(rt) if rt.norm_squared() < cost => {
                    cost = rt.norm_squared();
                    (z, r) = (trial, rt);
                    lambda = (lambda / 3.0).max(1e-12);
                    improved = true;
                    break;
                }
                _ => lambda *= 4.0,
            }
        }
        if !improved {
            break;
        }
    }
    cost
}

/// What the harness found, for the summary.
#[derive(Default)]
struct Tally {
    certified: usize,
    not_converged: usize,
    lines: Vec<String>,
}

impl Tally {
    fn add(&mut self, other: Tally) {
        self.certified += other.certified;
        self.not_converged += other.not_converged;
        self.lines.extend(other.lines);
    }
}

struct Check;

impl Visit for Check {
    type Output = Tally;
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Tally {
        let problem = case.problem(1).unwrap_or_else(|e| panic!("{}: {e}", case.name));
        let reference = tight(&problem);
        let truth = case.expected_values().unwrap_or_else(|| problem.guesses());
        // Two random starts per spread; one for the 23-unknown chain, whose failing runs
        // (argmin's line search on the flattened change of variables) take seconds each.
        let draws: &[(u64, f64)] = if problem.unknowns().len() > 10 {
            &[(0, 0.3), (2, 0.9)]
        } else {
            &[(0, 0.3), (1, 0.3), (2, 0.9), (3, 0.9)]
        };
        let mut starts = vec![problem.guesses()];
        for &(stream, rho) in draws {
            let mut rng = ChaCha8Rng::seed_from_u64(2026);
            rng.set_stream(stream);
            starts.push(
                problem
                    .unknowns()
                    .list()
                    .iter()
                    .zip(&truth)
                    .map(|(u, &t)| perturb(u, t, rho, rng.random_range(-1.0..=1.0)))
                    .collect(),
            );
        }
        // Points already searched from, with the cost found: methods often agree.
        let searched: Mutex<Vec<(Vec<f64>, f64)>> = Mutex::new(Vec::new());
        // The methods in parallel too: one system's runs would otherwise hold a core while
        // the other has finished its systems (the wall time was 1.6 times the CPU time / 2).
        let per_method = methods::<S>().into_par_iter().map(|method| {
            let mut tally = Tally::default();
            for (s, start) in starts.iter().enumerate() {
                let label = format!("{} / {} / start {s}", case.name, method.name());
                let e = match method.fit_from(&problem, start) {
                    Ok(e) => e,
                    Err(error) => panic!("{label}: {error}"),
                };
                // The JSON report, converged or not, parses and agrees with the estimate.
                let text = serde_json::to_string(&e.record(case.name)).unwrap();
                let json: serde_json::Value = serde_json::from_str(&text).unwrap();
                assert_eq!(json["converged"], e.converged(), "{label}: {json}");
                assert_eq!(json["termination_code"], e.termination.code(), "{label}");
                assert_eq!(e.converged(), e.certificate.holds(), "{label}");
                match &e.termination {
                    Termination::Converged(_) => assert!(e.converged(), "{label}"),
                    Termination::Stalled { .. } => assert!(!e.converged(), "{label}"),
                    _ => {}
                }
                let z = problem.unknowns().coordinates(&e.values);
                if !e.start_failed() {
                    assert!(e.values.iter().all(|v| v.is_finite()), "{label}: {:?}", e.values);
                    // The reported cost belongs to the reported values.
                    if let (Ok((cost, _)), true) = (problem.cost(&z), e.cost.is_finite()) {
                        assert!(
                            (cost - e.cost).abs()
                                <= 1e-5 * cost + 1e-20 * problem.data_norm().powi(2),
                            "{label}: reported cost {} but {cost} at the reported values",
                            e.cost
                        );
                    }
                }
                if !e.converged() {
                    tally.not_converged += 1;
                    tally.lines.push(format!(
                        "{label}: {} [{}]",
                        e.verdict(),
                        e.termination.code()
                    ));
                    continue;
                }
                tally.certified += 1;
                let at = reference.cost(&z).map(|(c, _)| c).unwrap_or(f64::NAN);
                let close = |a: &[f64]| {
                    a.iter().zip(&z).all(|(x, y)| (x - y).abs() <= 1e-9 * y.abs().max(1e-300))
                };
                let known = searched.lock().unwrap().iter().find(|(p, _)| close(p)).map(|s| s.1);
                let lowest = known.unwrap_or_else(|| {
                    let c = search(&reference, &z);
                    searched.lock().unwrap().push((z.clone(), c));
                    c
                });
                assert!(
                    at - lowest <= allowance(&reference, at),
                    "{label}: says converged ({}) at cost {at}, but an independent search finds {lowest} ({:.2e} lower, relative)",
                    e.verdict(),
                    (at - lowest) / at
                );
            }
            tally
        });
        let mut tally = Tally::default();
        for t in per_method.collect::<Vec<Tally>>() {
            tally.add(t);
        }
        tally
    }
}

#[test]
fn every_claim_of_convergence_survives_an_independent_search() {
    // The systems in parallel, and each system's methods (the search is single-threaded),
    // in the catalogue's order for the summary.
    let cases: Vec<(bool, &str)> = systems::NAMES
        .iter()
        .map(|n| (true, *n))
        .chain(stress::NAMES.iter().map(|n| (false, *n)))
        .collect();
    let tallies: Vec<Tally> = cases
        .par_iter()
        .map(|&(catalogue, name)| match catalogue {
            true => systems::visit(name, Check),
            false => stress::visit(name, Check),
        })
        .map(|t| t.expect("a listed name"))
        .collect();
    let mut tally = Tally::default();
    for t in tallies {
        tally.add(t);
    }
    println!(
        "{} certified fits confirmed, {} runs that said they did not converge:",
        tally.certified, tally.not_converged
    );
    for line in &tally.lines {
        println!("  {line}");
    }
    // The harness checks something: most runs converge, and some do not.
    assert!(
        tally.certified > 200 && tally.not_converged > 20,
        "{} / {}",
        tally.certified,
        tally.not_converged
    );
}
