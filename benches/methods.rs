//! Time to fit, per catalogue system and method, from the default start: `fit/<system>/<method>`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid::core::Method;
use sysid::goodman::Goodman;
use sysid::systems::falling_body;

fn fit(c: &mut Criterion) {
    let mut group = c.benchmark_group("fit");
    let problem = falling_body::falling_body().problem(1).unwrap();
    let goodman = Goodman::default();
    group.bench_function("falling-body/goodman", |b| {
        b.iter(|| {
            let estimate = goodman.fit(black_box(&problem)).unwrap();
            assert!(estimate.converged());
            estimate
        })
    });
    group.finish();
}

criterion_group!(benches, fit);
criterion_main!(benches);
