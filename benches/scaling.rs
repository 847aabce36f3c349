//! How the cost of one Goodman iteration grows with the number of states n, of unknowns k
//! and of measurements M, on Lorenz-96:
//!
//!   x_i' = (x_{i+1} − x_{i−2}) x_{i−1} − d_i x_i + F,   i = 1 … n (cyclic),
//!
//! with the forcing F and the per-state damping d_i as parameters. One iteration is what
//! Goodman's method does per step: integrate the states with their sensitivities to the k
//! unknowns, sum ε, U = Σ r S and A = Σ SᵀWS over the data, and solve A Δz = −U.
//!
//! * `scaling/n/<n>`: n = 4 … 256; k = 4 (F, d_1, d_2, d_3), x_1 … x_4 measured 50 times;
//! * `scaling/k/<k>`: k = 2 … 64 (F and d_1 … d_{k−1}); n = 64, M = 200 as above;
//! * `scaling/m/<M>`: M = 50 … 1600 values (x_1 … x_4 at M/4 times); n = 16, k = 4.
//!
//! `sysid report` reads the medians and fits the exponents p of time ∝ size^p.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use sysid::core::{Data, Problem, Unknown};
use sysid::ode::{Integrator, Ivp, Scalar, Signature, System};

/// Lorenz-96 with n states; parameters F, d_1 … d_n.
#[derive(Clone, Debug)]
struct Lorenz96 {
    signature: Signature,
    n: usize,
}

impl Lorenz96 {
    fn new(n: usize) -> Self {
        let states: Vec<String> = (1..=n).map(|i| format!("x{i}")).collect();
        let parameters: Vec<String> =
            std::iter::once("F".to_string()).chain((1..=n).map(|i| format!("d{i}"))).collect();
        let states: Vec<&str> = states.iter().map(String::as_str).collect();
        let parameters: Vec<&str> = parameters.iter().map(String::as_str).collect();
        Self { signature: Signature::new(&states, &parameters), n }
    }
}

impl System for Lorenz96 {
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        let n = self.n;
        for i in 0..n {
            let (next, prev, prev2) = ((i + 1) % n, (i + n - 1) % n, (i + n - 2) % n);
            dy[i] = (y[next] - y[prev2]) * y[prev] - p[1 + i] * y[i] + p[0];
        }
    }
}

/// The problem with n states, k unknowns (F and d_1 … d_{k−1}) and `samples` times of
/// x_1 … x_4 on (0, 1], data from F = 8, d = 1; the point z where the iteration is timed
/// lies 5 % off the truth.
fn problem(n: usize, k: usize, samples: usize) -> (Problem<Lorenz96>, Vec<f64>) {
    let system = Lorenz96::new(n);
    let (f, d) = (8.0, 1.0);
    let y0: Vec<f64> = (0..n).map(|i| f + 0.5 * ((i + 1) as f64).sin()).collect();
    let mut p = vec![d; n + 1];
    p[0] = f;
    let times: Vec<f64> = (1..=samples).map(|m| m as f64 / samples as f64).collect();
    let truth = Ivp::new(&system, 0.0, &y0, &p)
        .solve(&Integrator::dopri5(1e-11, 1e-13), &times)
        .expect("Lorenz-96 integrates");
    let mut data = Data::discrete();
    for i in 0..4.min(n) {
        let values: Vec<f64> = (0..samples).map(|m| truth.state(m)[i]).collect();
        data = data.series(&format!("x{}", i + 1), &times, &values);
    }
    let mut builder =
        Problem::builder(system).t0(0.0).integrator(Integrator::dopri5(1e-8, 1e-10)).data(data);
    for (i, &y) in y0.iter().enumerate() {
        builder = builder.known(&format!("x{}", i + 1), y);
    }
    builder = builder.unknown_with(Unknown::new("F", f));
    for i in 1..=n {
        let name = format!("d{i}");
        builder = if i < k {
            builder.unknown_with(Unknown::new(&name, d))
        } else {
            builder.known(&name, d)
        };
    }
    let problem = builder.build().expect("a valid problem");
    let values: Vec<f64> = (0..k).map(|j| 1.05 * if j == 0 { f } else { d }).collect();
    let z = problem.unknowns().coordinates(&values);
    (problem, z)
}

/// One Goodman iteration at z: the linearisation and the Newton step (an LU solve: far
/// dampings barely reach the measured states, so A may be numerically singular at large k,
/// which changes nothing in the cost measured here).
fn iteration(problem: &Problem<Lorenz96>, z: &[f64]) -> Option<nalgebra::DVector<f64>> {
    let lin = problem.linearize(z).expect("the model integrates");
    lin.normal.clone().lu().solve(&(-&lin.gradient))
}

fn scaling(c: &mut Criterion) {
    let mut group = c.benchmark_group("scaling");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    let mut run = |dimension: &str, size: usize, n: usize, k: usize, samples: usize| {
        let (problem, z) = problem(n, k, samples);
        group.bench_function(BenchmarkId::new(dimension, size), |b| {
            b.iter(|| iteration(black_box(&problem), black_box(&z)))
        });
    };
    for n in [4, 8, 16, 32, 64, 128, 256] {
        run("n", n, n, 4, 50);
    }
    for k in [2, 4, 8, 16, 32, 64] {
        run("k", k, 64, k, 50);
    }
    for m in [50, 100, 200, 400, 800, 1600] {
        run("m", m, 16, 4, m / 4);
    }
    group.finish();
}

criterion_group!(benches, scaling);
criterion_main!(benches);
