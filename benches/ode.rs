//! Integration per catalogue system, sysid's integrators side by side with diffsol's:
//! `ode/<system>/<states|sensitivities>/<solver>`.
//!
//! Every run is the case's initial-value problem at the truth (or the reference answer), at
//! the case's tolerances (rtol, atol for states and sensitivities alike), with output at the
//! case's measurement times and, for `sensitivities`, derivatives with respect to the case's
//! unknowns; DOPRI5, DOP853 and the automatic choice also at 1e-4 of those tolerances
//! (`-tight`). Solvers: sysid's explicit DOPRI5 and DOP853, implicit Rodas4, multistep BDF
//! and the automatic choice, diffsol's explicit Tsit45 and implicit BDF (dense nalgebra LU).
//! All seven get their Jacobian products from the same dual-number evaluation of the model,
//! so the comparison is between integrators, not model code. `tests/agreement.rs` of
//! `sysid-peer-diffsol` checks that they agree.
//!
//! `SYSID_BENCH_SYSTEMS=van-der-pol,robertson cargo bench -p sysid --bench ode` limits the
//! run to some systems.

use std::hint::black_box;
use std::time::Duration;

use criterion::{
    BenchmarkGroup, Criterion, criterion_group, criterion_main, measurement::WallTime,
};
use sysid::ode::{Integrator, Ivp, MIN_RTOL, System};
use sysid::systems::{self, Case, Visit};
use sysid_peer_diffsol::{Peer, Solver};

struct Bench<'g, 'c> {
    group: &'g mut BenchmarkGroup<'c, WallTime>,
}

impl Visit for Bench<'_, '_> {
    type Output = ();
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) {
        let problem = case.problem(1).expect("catalogue problems build");
        let (y0, p) = case.true_point();
        let (times, wrt) = (&problem.sampled().times, problem.experiments()[0].slots());
        let Integrator { rtol, atol, .. } = *problem.integrator();
        let tight = (rtol * 1e-4).max(MIN_RTOL);
        // An explicit integrator on a stiff case takes ~10⁵ steps: allow them.
        let ours = [
            ("sysid-dopri5", Integrator::dopri5(rtol, atol).with_max_steps(10_000_000)),
            ("sysid-dop853", Integrator::dop853(rtol, atol).with_max_steps(10_000_000)),
            ("sysid-rodas4", Integrator::rodas4(rtol, atol).with_max_steps(10_000_000)),
            ("sysid-bdf", Integrator::bdf(rtol, atol).with_max_steps(10_000_000)),
            // The two explicit schemes at 1e-4 of the case's tolerances (rtol no tighter than
            // an integration accepts), where DOP853's order 8 is meant to pay.
            (
                "sysid-dopri5-tight",
                Integrator::dopri5(tight, atol * 1e-4).with_max_steps(10_000_000),
            ),
            (
                "sysid-dop853-tight",
                Integrator::dop853(tight, atol * 1e-4).with_max_steps(10_000_000),
            ),
            // The automatic choice at both: DOPRI5's steps, DOP853's at rtol ≤
            // AUTO_DOP853_RTOL (and Rodas5P's on a stiff case), with its stiffness tests.
            ("sysid-auto", Integrator::auto(rtol, atol).with_max_steps(10_000_000)),
            ("sysid-auto-tight", Integrator::auto(tight, atol * 1e-4).with_max_steps(10_000_000)),
        ];
        let ivp = |y0, p| Ivp::new(&case.system, case.t0, y0, p);
        let peer = |y0, p| Peer::new(&case.system, case.t0, y0, p, rtol, atol);
        let group = self.group;
        for (name, integrator) in &ours {
            group.bench_function(format!("{}/states/{name}", case.name), |b| {
                b.iter(|| ivp(black_box(&y0), black_box(&p)).solve(integrator, times).unwrap())
            });
            group.bench_function(format!("{}/sensitivities/{name}", case.name), |b| {
                b.iter(|| {
                    ivp(black_box(&y0), black_box(&p))
                        .solve_sensitivities(integrator, wrt, times)
                        .unwrap()
                })
            });
        }
        for solver in Solver::ALL {
            let name = format!("diffsol-{}", solver.name());
            group.bench_function(format!("{}/states/{name}", case.name), |b| {
                b.iter(|| peer(black_box(&y0), black_box(&p)).solve(solver, times).unwrap())
            });
            group.bench_function(format!("{}/sensitivities/{name}", case.name), |b| {
                b.iter(|| {
                    peer(black_box(&y0), black_box(&p))
                        .solve_sensitivities(solver, wrt, times)
                        .unwrap()
                })
            });
        }
    }
}

fn ode(c: &mut Criterion) {
    let mut group = c.benchmark_group("ode");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(20);
    let only = std::env::var("SYSID_BENCH_SYSTEMS").ok();
    for name in systems::NAMES {
        if only.as_ref().is_none_or(|only| only.split(',').any(|o| o == *name)) {
            systems::visit(name, Bench { group: &mut group });
        }
    }
    group.finish();
}

criterion_group!(benches, ode);
criterion_main!(benches);
