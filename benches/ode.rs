//! Integration with and without forward sensitivities: `ode/<system>/<what>`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid::ode::{Integrator, Ivp, Wrt};
use sysid::systems::VanDerPol;

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

criterion_group!(benches, van_der_pol);
criterion_main!(benches);
