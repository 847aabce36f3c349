//! PEtab problems of tests/data/petab: `petab/import/<problem>`, reading the YAML, the SBML
//! and the tables and compiling the model file and its problem (target ≤ 100 ms each; AMICI's
//! code generation and compile take 10–13 s); `petab/nll-gradient/<problem>`, the NLL and its
//! gradient (forward sensitivities) at the nominal parameters (targets: Boehm ≤ 1 ms, AMICI
//! 6.8 ms; Bachmann ≤ 200 ms, AMICI 2.03 s).

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};

const PROBLEMS: [&str; 10] = [
    "Boehm_JProteomeRes2014",
    "Fujita_SciSignal2010",
    "Bachmann_MSB2011",
    "Crauste_CellSystems2017",
    "Elowitz_Nature2000",
    "Fiedler_BMCSystBiol2016",
    "Bruno_JExpBot2016",
    "Sneyd_PNAS2002",
    "Borghans_BiophysChem1997",
    // 109 states, 367 reactions: the largest, measured beside the target.
    "Smith_BMCSystBiol2013",
];

fn yaml(problem: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/petab")
        .join(problem)
        .join(format!("{problem}.yaml"))
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("petab/import");
    group.sample_size(10).warm_up_time(Duration::from_millis(500));
    for problem in PROBLEMS {
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
    for problem in ["Boehm_JProteomeRes2014", "Bachmann_MSB2011", "Fujita_SciSignal2010"] {
        let imported = sysid_petab::import(&yaml(problem)).expect("imports");
        let p = imported.model.problem(None).expect("a problem");
        let z = p.unknowns().coordinates(&p.guesses());
        group.bench_function(problem, |b| {
            b.iter(|| {
                let lin = p.linearize(black_box(&z)).expect("integrates");
                black_box((p.nll(&lin), lin.gradient.norm()))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
