//! Time to fit, per catalogue system and method, from the default start on the default
//! data (seed 1): `fit/<system>/<method>`; and the bounded compartment chain against the same
//! problem without its bounds: `bounds/<bounded|unbounded>/<method>`. Problems are built
//! outside the timed loop.

use std::hint::black_box;
use std::time::Duration;

use criterion::{
    BenchmarkGroup, Criterion, criterion_group, criterion_main, measurement::WallTime,
};
use sysid::core::Method;
use sysid::ode::System;
use sysid::registry::{Registry, Settings};
use sysid::systems::{self, Case, Visit};

/// Every method of the registry, by its command-line name, with the default settings.
fn methods<S: System>() -> Vec<(&'static str, Box<dyn Method<S> + Send + Sync>)> {
    let settings = Settings::default();
    Registry::<S>::standard().build_all(&settings)
}

struct Bench<'g, 'c> {
    group: &'g mut BenchmarkGroup<'c, WallTime>,
}

impl Visit for Bench<'_, '_> {
    type Output = ();
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) {
        let problem = case.problem(1).expect("catalogue problems build");
        for (name, method) in methods::<S>() {
            self.group.bench_function(format!("{}/{name}", case.name), |b| {
                b.iter(|| method.fit(black_box(&problem)).expect("valid problem"))
            });
        }
    }
}

fn fit(c: &mut Criterion) {
    let mut group = c.benchmark_group("fit");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(20);
    for name in systems::NAMES {
        systems::visit(name, Bench { group: &mut group });
    }
    group.finish();
}

/// The compartment chain with its 23 bounds and without them (the unbounded optimum has
/// d1 < 0): what a bounded step costs against a free one.
fn bounds(c: &mut Criterion) {
    let mut group = c.benchmark_group("bounds");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(20);
    let mut case = systems::compartment_chain::compartment_chain();
    let bounded = case.problem(1).expect("the catalogue's chain builds");
    for u in &mut case.unknowns {
        u.min = None;
    }
    let unbounded = case.problem(1).expect("the chain builds without bounds");
    for (label, problem) in [("bounded", &bounded), ("unbounded", &unbounded)] {
        for (name, method) in methods() {
            let e = method.fit(problem).expect("valid problem");
            eprintln!(
                "bounds/{label}/{name}: {} iterations, {} integrations, converged {}",
                e.iterations,
                e.counts.integrations,
                e.converged()
            );
            group.bench_function(format!("{label}/{name}"), |b| {
                b.iter(|| method.fit(black_box(problem)).expect("valid problem"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, fit, bounds);
criterion_main!(benches);
