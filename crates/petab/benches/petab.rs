//! Every PEtab problem of tests/data/petab (23 of Benchmark-Models-PEtab): `petab/import/<problem>`,
//! reading the YAML, the SBML and the tables and compiling the model file and its problem
//! (target ≤ 100 ms each; AMICI's code generation and compile take 10–13 s);
//! `petab/nll-gradient/<problem>`, the NLL and its gradient (forward sensitivities) at the
//! nominal parameters (targets: Boehm ≤ 1 ms, AMICI 6.8 ms; Bachmann ≤ 200 ms, AMICI 2.03 s).
//! `cargo bench -p sysid-petab -- Boehm` runs one problem's.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};

/// The problems: every folder of tests/data/petab, sorted.
fn problems() -> Vec<String> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/petab");
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("tests/data/petab")
        .filter_map(Result::ok)
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn yaml(problem: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/petab")
        .join(problem)
        .join(format!("{problem}.yaml"))
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("petab/import");
    group.sample_size(10).warm_up_time(Duration::from_millis(500));
    for problem in &problems() {
        let path = yaml(problem);
        group.bench_function(problem, |b| {
            b.iter(|| {
                let imported = sysid_petab::import(black_box(&path)).expect("imports");
                black_box(imported.model.problem(None).expect("a problem"))
            })
        });
    }
    group.finish();
    let mut group = c.benchmark_group("petab/nll-gradient");
    group.sample_size(10).warm_up_time(Duration::from_millis(500));
    for problem in &problems() {
        let imported = sysid_petab::import(&yaml(problem)).expect("imports");
        let p = imported.model.problem(None).expect("a problem");
        let z = p.unknowns().coordinates(&p.guesses());
        group.bench_function(problem, |b| {
            b.iter(|| {
                // A preequilibration's steady state is solved afresh, as at a new point.
                p.forget_cached();
                let lin = p.linearize(black_box(&z)).expect("integrates");
                black_box((p.nll(&lin), lin.gradient.norm()))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
