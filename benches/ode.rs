//! Integration with and without forward sensitivities: `ode/<system>/<what>`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid::ode::{Integrator, Ivp, Scheme, Wrt};
use sysid::systems::{Robertson, VanDerPol};

fn van_der_pol(c: &mut Criterion) {
    let mut group = c.benchmark_group("ode");
    // μ = 1, x(0) = 2, v(0) = 0 on [0, 20], rtol 1e-8; output at t = 0, 0.2, ..., 20.
    let sys = VanDerPol::default();
    let (y0, p) = ([2.0, 0.0], [1.0]);
    let integrator = Integrator::dopri5(1e-8, 1e-10);
    let times: Vec<f64> = (0..=100).map(|i| 0.2 * i as f64).collect();
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0), Wrt::InitialValue(1)];
    group.bench_function("van-der-pol/sensitivities", |b| {
        b.iter(|| {
            Ivp::new(&sys, 0.0, black_box(&y0), black_box(&p))
                .solve_sensitivities(&integrator, &wrt, &times)
                .unwrap()
        })
    });
    group.bench_function("van-der-pol/states", |b| {
        b.iter(|| {
            Ivp::new(&sys, 0.0, black_box(&y0), black_box(&p)).solve(&integrator, &times).unwrap()
        })
    });
    group.finish();
}

fn robertson(c: &mut Criterion) {
    let mut group = c.benchmark_group("ode");
    // The catalogue case at the truth: y(0) = (1, 0, 0), k = (0.04, 3e7, 1e4), output at its 20
    // log-spaced times in [0.01, 100]; Rodas4 at the case's tolerances (rtol 1e-8,
    // atol 1e-16), sensitivities to the three rates.
    let case = sysid::systems::robertson::robertson();
    let sys = Robertson::default();
    let (y0, p) = ([1.0, 0.0, 0.0], [0.04, 3e7, 1e4]);
    let times = sysid::systems::robertson::times();
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::Parameter(2)];
    let ivp = |y0, p| Ivp::new(&sys, 0.0, y0, p);
    group.bench_function("robertson/sensitivities", |b| {
        b.iter(|| {
            ivp(black_box(&y0), black_box(&p))
                .solve_sensitivities(&case.integrator, &wrt, &times)
                .unwrap()
        })
    });
    group.bench_function("robertson/states", |b| {
        b.iter(|| ivp(black_box(&y0), black_box(&p)).solve(&case.integrator, &times).unwrap())
    });
    // The same with the automatic choice, and with the explicit integrator for comparison.
    let auto = Integrator { scheme: Scheme::Auto, ..case.integrator };
    group.bench_function("robertson/states-auto", |b| {
        b.iter(|| ivp(black_box(&y0), black_box(&p)).solve(&auto, &times).unwrap())
    });
    let explicit = Integrator { scheme: Scheme::Dopri5, max_steps: 10_000_000, ..case.integrator };
    group.sample_size(10);
    group.bench_function("robertson/states-dopri5", |b| {
        b.iter(|| ivp(black_box(&y0), black_box(&p)).solve(&explicit, &times).unwrap())
    });
    group.finish();
}

criterion_group!(benches, van_der_pol, robertson);
criterion_main!(benches);
