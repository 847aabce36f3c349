//! Model files against the same systems written in Rust.
//!
//! * `model/<system>/{rust,file,file-dual}`: one Goodman fit each, from the catalogue's
//!   default start on its seed-1 data, with the same integrator. `file` is the system's
//!   model-file twin (`tests/twins/`) as sysid runs it: symbolic Jacobians in one
//!   straight-line program, compiled by Cranelift; `file-dual` is the same model file
//!   differentiated by dual numbers, the reference path (and how model files ran before).
//! * `products/<system>/{rust,file}`: 1000 evaluations of the right-hand side with
//!   J_y S + J_α, the kernel of the sensitivity equations, at one point (K = n_α columns).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid::core::{Method, Problem};
use sysid::goodman::Goodman;
use sysid::ode::System;
use sysid::systems::{fitzhugh_nagumo, lotka_volterra, robertson, short_period, van_der_pol};

#[path = "../tests/twins/mod.rs"]
mod twins;

fn compare<S: System>(c: &mut Criterion, name: &str, rust: Problem<S>) {
    let file = twins::file_problem(name, 1, false);
    let dual = twins::file_problem(name, 1, true);
    let goodman = Goodman::default();
    // All three fits reach the same answer.
    let reference = goodman.fit(&rust).expect("the Rust fit").cost;
    for problem in [&file, &dual] {
        let cost = goodman.fit(problem).expect("the model-file fit").cost;
        assert!((cost - reference).abs() <= 1e-8 * reference, "{name}: {cost} vs {reference}");
    }
    let mut group = c.benchmark_group("model");
    group.warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    group.bench_function(format!("{name}/rust"), |b| b.iter(|| goodman.fit(black_box(&rust))));
    group.bench_function(format!("{name}/file"), |b| b.iter(|| goodman.fit(black_box(&file))));
    group.bench_function(format!("{name}/file-dual"), |b| b.iter(|| goodman.fit(black_box(&dual))));
    group.finish();
}

fn model_files(c: &mut Criterion) {
    let problem = "a catalogue problem";
    compare(c, "van-der-pol", van_der_pol::van_der_pol().problem(1).expect(problem));
    compare(c, "lotka-volterra", lotka_volterra::lotka_volterra().problem(1).expect(problem));
    compare(c, "fitzhugh-nagumo", fitzhugh_nagumo::fitzhugh_nagumo().problem(1).expect(problem));
    compare(c, "short-period", short_period::short_period().problem(1).expect(problem));
    compare(c, "robertson", robertson::robertson().problem(1).expect(problem));
}

fn products<S: System>(c: &mut Criterion, name: &str, rust: &S) {
    use sysid::ode::{Function, JacobianProducts};
    let file = twins::file_problem(name, 1, false);
    let sys = file.system();
    let sig = sys.signature();
    let (n, np) = (sig.n_states(), sig.n_parameters());
    let k = np;
    let mut vp = vec![0.0; np * k];
    for q in 0..np {
        vp[q * k + q] = 1.0;
    }
    let y: Vec<f64> = (0..n).map(|i| 0.3 + 0.1 * i as f64).collect();
    let p: Vec<f64> = (0..np).map(|i| 0.5 + 0.2 * i as f64).collect();
    let u = vec![0.1; sig.n_inputs()];
    let vy: Vec<f64> = (0..n * k).map(|i| 0.1 * i as f64).collect();
    let (mut value, mut out) = (vec![0.0; n], vec![0.0; n * k]);
    let mut a = JacobianProducts::new(n, &p, &vp, n, k);
    c.bench_function(&format!("products/{name}/rust"), |b| {
        b.iter(|| {
            for _ in 0..1000 {
                a.eval(rust, Function::Rhs, (0.0, black_box(&y), &u), &vy, &mut value, &mut out);
            }
            out[0]
        })
    });
    let mut a = JacobianProducts::new(n, &p, &vp, n, k);
    c.bench_function(&format!("products/{name}/file"), |b| {
        b.iter(|| {
            for _ in 0..1000 {
                a.eval(sys, Function::Rhs, (0.0, black_box(&y), &u), &vy, &mut value, &mut out);
            }
            out[0]
        })
    });
}

fn kernels(c: &mut Criterion) {
    products(c, "van-der-pol", &van_der_pol::van_der_pol().system);
    products(c, "fitzhugh-nagumo", &fitzhugh_nagumo::fitzhugh_nagumo().system);
    products(c, "lotka-volterra", &lotka_volterra::lotka_volterra().system);
    products(c, "robertson", &robertson::robertson().system);
}
criterion_group!(fits, model_files);
criterion_group!(products_group, kernels);
criterion_main!(fits, products_group);
