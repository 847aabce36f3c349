//! A Monte-Carlo study: 1 000 trials on `van-der-pol` (noise 1·σ, starts perturbed by
//! ρ = 0.2), each trial the reference fit from the truth plus Goodman's fit, written to a
//! study directory as `sysid study` writes it; on one thread and on two:
//! `study/van-der-pol-goodman-1000/threads-<n>`. Trials per second per core is
//! 1000 / time / threads.

use std::time::Duration;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use sysid::montecarlo::{Scenario, Study, StudySpec, files};
use sysid::registry::{Registry, Settings};

fn study(c: &mut Criterion) {
    let case = sysid::systems::van_der_pol::van_der_pol();
    let spec = StudySpec {
        system: case.name.into(),
        methods: vec!["goodman".into()],
        reference: "goodman-halving".into(),
        trials: 1000,
        noise: 1.0,
        perturb: 0.2,
        seed: 1,
        fixed: Vec::new(),
        driver: Default::default(),
        settings: Default::default(),
    };
    // The methods as `sysid study` builds them: from the registry, default settings.
    let registry = Registry::standard();
    let build = |name| registry.build(name, &Settings::default()).expect("a registered method");
    let study = Study::new(
        spec,
        Scenario::from_case(&case).expect("the catalogue case"),
        vec![build("goodman")],
        build("goodman-halving"),
    )
    .expect("a valid study");
    let dir = std::env::temp_dir().join(format!("sysid-bench-study-{}", std::process::id()));
    let mut group = c.benchmark_group("study");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(25));
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a pool");
        group.bench_function(format!("van-der-pol-goodman-1000/threads-{threads}"), |b| {
            b.iter_batched(
                || {
                    let _ = std::fs::remove_dir_all(&dir);
                },
                |()| {
                    pool.install(|| files::run(&study, &dir, Default::default(), &|_, _| {}))
                        .expect("the study runs")
                },
                BatchSize::PerIteration,
            )
        });
    }
    group.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, study);
criterion_main!(benches);
