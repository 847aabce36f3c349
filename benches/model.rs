//! A model file against the same system written in Rust: `model/<system>/{rust,file}`, one
//! Goodman fit each, same data (seed 1), start and integrator.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid::core::{Method, Samples};
use sysid::goodman::Goodman;
use sysid::model::Model;
use sysid::systems::fitzhugh_nagumo::fitzhugh_nagumo;

const FHN: &str = r#"states = ["V", "R"]
parameters = ["a", "b", "c"]
[equations]
V = "c * (V - V^3 / 3 + R)"
R = "-(V - a + b * R) / c"
[initial]
V = -1.0
R = 1.0
[unknowns]
a = 0.3
b = 0.3
c = 2.5
[data]
file = "data.csv"
[data.weights]
V = 400.0
R = 400.0
[integrator]
rtol = 1e-8
atol = 1e-10
"#;

fn fitzhugh_nagumo_file(c: &mut Criterion) {
    let case = fitzhugh_nagumo();
    let rust = case.problem(1).expect("catalogue problem");
    // The same data as a CSV file next to the model file.
    let data = case.data(1).expect("catalogue data");
    let dir = std::env::temp_dir().join(format!("sysid-bench-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let columns: Vec<(&String, &Vec<f64>, &Vec<f64>)> = data
        .series
        .iter()
        .map(|s| match &s.samples {
            Samples::Points { times, values } => (&s.name, times, values),
            Samples::Function(_) => unreachable!("sampled catalogue data"),
        })
        .collect();
    let mut csv = String::from("t,V,R\n");
    for m in 0..columns[0].1.len() {
        csv += &format!("{},{},{}\n", columns[0].1[m], columns[0].2[m], columns[1].2[m]);
    }
    std::fs::write(dir.join("data.csv"), csv).expect("writing data");
    std::fs::write(dir.join("model.toml"), FHN).expect("writing the model");
    let file = Model::load(&dir.join("model.toml"))
        .expect("a valid model")
        .problem(None)
        .expect("a valid problem");
    std::fs::remove_dir_all(&dir).ok();

    let goodman = Goodman::default();
    // Both fits reach the same answer.
    let (a, b) = (goodman.fit(&rust).unwrap(), goodman.fit(&file).unwrap());
    assert!((a.cost - b.cost).abs() <= 1e-8 * a.cost, "{} vs {}", a.cost, b.cost);

    let mut group = c.benchmark_group("model");
    group.warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    group.bench_function("fitzhugh-nagumo/rust", |bench| {
        bench.iter(|| goodman.fit(black_box(&rust)).unwrap())
    });
    group.bench_function("fitzhugh-nagumo/file", |bench| {
        bench.iter(|| goodman.fit(black_box(&file)).unwrap())
    });
    group.finish();
}

criterion_group!(benches, fitzhugh_nagumo_file);
criterion_main!(benches);
