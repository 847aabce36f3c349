//! Hard real problems: `hard/boehm-fixed-sigma/<method>`, a default fit of Boehm et al.'s
//! STAT5 problem (examples/boehm) with the three noise s.d. fixed at their published values,
//! from the published optimum moved by ±0.1–0.3 decades per rate (the start of
//! tests/hard.rs). The target for Levenberg–Marquardt: ≤ 87 ms per fit, a tenth of
//! AMICI + fides (0.87 s from nominal + 0.1); `hybrid-newton` and `quasilinearization`
//! beside it.
//! `hard/boehm-fixed-sigma/profiles`: the six
//! profile likelihoods from that fit (target ≤ 5 s on two cores).

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid::core::Problem;
use sysid::model::{Model, ModelSystem};
use sysid::profile::{ProfileOptions, profile};
use sysid::registry::{Registry, Settings};

/// The published noise s.d. of the three observables.
const SIGMA: [(&str, f64); 3] = [
    ("sd_pSTAT5A_rel", 3.852_611_978_446_77),
    ("sd_pSTAT5B_rel", 6.591_478_186_734_19),
    ("sd_rSTAT5A_rel", 3.152_712_756_485_27),
];

/// The start: each rate's guess moved by this many decades.
const SHIFT: [f64; 6] = [0.2, -0.15, 0.25, -0.1, -0.3, 0.12];

/// examples/boehm with σ fixed and the start moved, written to a scratch directory.
fn problem() -> Problem<ModelSystem> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("sysid-bench-hard-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(root.join("examples/boehm/data.csv"), dir.join("data.csv")).unwrap();
    let mut text = std::fs::read_to_string(root.join("examples/boehm/model.toml")).unwrap();
    for (name, sigma) in SIGMA {
        text = text.replace(&format!("sigma = \"{name}\""), &format!("sigma = {sigma}"));
    }
    let mut rate = 0;
    let mut model = String::new();
    for line in text.lines().filter(|l| !l.starts_with("sd_")) {
        match line.split_once(" = { guess = ") {
            Some((name, rest)) => {
                let (value, tail) = rest.split_once(',').unwrap();
                let mut decades = value.parse::<f64>().unwrap().log10() + SHIFT[rate];
                // Reflected into the bounds [1e-5, 1e5], as tests/hard.rs does.
                if decades < -5.0 {
                    decades = -10.0 - decades;
                } else if decades > 5.0 {
                    decades = 10.0 - decades;
                }
                rate += 1;
                model += &format!("{name} = {{ guess = {:e},{tail}\n", 10f64.powf(decades));
            }
            None => model += &format!("{line}\n"),
        }
    }
    let path = dir.join("model.toml");
    std::fs::write(&path, model).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    problem
}

fn hard(c: &mut Criterion) {
    let mut group = c.benchmark_group("hard");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(5))
        .sample_size(20);
    let problem = problem();
    // Quasilinearization with its safeguard, the Fletcher–Xu hybrid that adds the differenced
    // Hessian once ε falls slowly, and Levenberg–Marquardt; the last, LM, is kept for the
    // profiles.
    let fitted = ["quasilinearization", "hybrid-newton", "levenberg-marquardt"].map(|name| {
        let method = Registry::standard().build(name, &Settings::default()).unwrap();
        let e = method.fit(&problem).unwrap();
        eprintln!(
            "hard/boehm-fixed-sigma/{name}: {} iterations, {} integrations, converged {}, χ² {}",
            e.iterations,
            e.counts.integrations,
            e.converged(),
            e.cost
        );
        group.bench_function(format!("boehm-fixed-sigma/{name}"), |b| {
            b.iter(|| method.fit(black_box(&problem)).unwrap())
        });
        (method, e)
    });
    let [_, _, (method, e)] = fitted;
    // All six profile likelihoods from that fit, on both cores (issue 31's target: ≤ 5 s).
    let options = ProfileOptions::default();
    group.sample_size(10).measurement_time(Duration::from_secs(60));
    group.bench_function("boehm-fixed-sigma/profiles", |b| {
        b.iter(|| profile(&*method, black_box(&problem), &e, &[], &options).unwrap())
    });
    group.finish();
}

criterion_group!(benches, hard);
criterion_main!(benches);
