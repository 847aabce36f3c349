//! A fit over 1, 4 and 16 experiments of one model: `experiments/<count>/<method>`.
//!
//! The model is the two-dose example's (`examples/two-doses/model.toml`: A → B → C, Bm
//! measured with an estimated noise s.d., C on the log10 scale with a known one) with one
//! experiment per dose 1, 2, …, each with its own instrument scale for Bm except the first;
//! the data are the model at the truth plus seeded noise, written to a scratch directory
//! outside the timed loop. Each experiment adds 40 measured values and one unknown.

use std::fmt::Write as _;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sysid::core::Problem;
use sysid::model::{Model, ModelSystem};
use sysid::registry::{Registry, Settings};

/// The truth of the rates, the noise s.d. of Bm and the scales.
const K1: f64 = 0.7;
const KP: f64 = 0.5;
const K2: f64 = 0.25;
const SIGMA_B: f64 = 0.03;

/// A model file of `count` experiments with its data, in a scratch directory.
fn problem(count: usize) -> Problem<ModelSystem> {
    let dir = std::env::temp_dir()
        .join(format!("sysid-bench-experiments-{count}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a scratch directory");
    let mut model = String::from(
        "states = [\"A\", \"B\", \"C\"]\nparameters = [\"k1\", \"kp\", \"k2\", \"dose\", \"scale\"]\n\
         [equations]\nA = \"-k1 * A\"\nB = \"kp * A - k2 * B\"\nC = \"k2 * B\"\n\
         [initial]\nA = \"dose\"\nB = 0.0\nC = 0.0\n\
         [outputs]\nBm = { value = \"scale * B\", sigma = \"sigma_B\" }\n\
         Ct = { value = \"C\", sigma = 0.02, transform = \"log10\" }\n\
         [unknowns]\nk1 = { guess = 0.5, min = 1e-4, max = 100.0, log = true }\n\
         kp = { guess = 0.3, min = 1e-4, max = 100.0, log = true }\n\
         k2 = { guess = 0.2, min = 1e-4, max = 100.0, log = true }\n\
         sigma_B = { guess = 0.05, min = 1e-6, max = 10.0, log = true }\n",
    );
    for e in 1..count {
        writeln!(model, "scale_{e} = {{ guess = 1.0, min = 1e-3, max = 1e3, log = true }}")
            .unwrap();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let normal = Normal::new(0.0, 1.0).expect("a normal distribution");
    for e in 0..count {
        let dose = (e + 1) as f64;
        let scale_value = 1.0 + 0.1 * e as f64;
        let scale = if e == 0 { "1.0".to_string() } else { format!("\"scale_{e}\"") };
        writeln!(model, "[[experiments]]\nname = \"e{e}\"\nfile = \"e{e}.csv\"\nset = {{ dose = {dose}, scale = {scale} }}").unwrap();
        let mut csv = String::from("t,Bm,Ct\n");
        for m in 1..=20 {
            let t = 0.5 * m as f64;
            let a_b = dose * KP / (K2 - K1) * ((-K1 * t).exp() - (-K2 * t).exp());
            // C = ∫ k2 B: the closed form of the linear chain.
            let c = dose * KP * K2 / (K2 - K1)
                * ((1.0 - (-K1 * t).exp()) / K1 - (1.0 - (-K2 * t).exp()) / K2);
            let bm = scale_value * a_b + SIGMA_B * normal.sample(&mut rng);
            let ct = 10f64.powf(c.log10() + 0.02 * normal.sample(&mut rng));
            writeln!(csv, "{t},{bm},{ct}").unwrap();
        }
        std::fs::write(dir.join(format!("e{e}.csv")), csv).expect("a data file");
    }
    let path: PathBuf = dir.join("model.toml");
    std::fs::write(&path, model).expect("a model file");
    Model::load(&path).expect("the model").problem(None).expect("the problem")
}

fn experiments(c: &mut Criterion) {
    let mut group = c.benchmark_group("experiments");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3))
        .sample_size(10);
    for count in [1, 4, 16] {
        let problem = problem(count);
        for name in ["goodman", "levenberg-marquardt"] {
            let method = Registry::standard().build(name, &Settings::default()).expect("a method");
            let e = method.fit(&problem).expect("a fit");
            eprintln!(
                "experiments/{count}/{name}: {} iterations, converged {}, nll {:?}",
                e.iterations,
                e.converged(),
                e.nll
            );
            group.bench_function(format!("{count}/{name}"), |b| {
                b.iter(|| method.fit(black_box(&problem)).expect("a fit"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, experiments);
criterion_main!(benches);
