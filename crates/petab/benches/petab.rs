//! Every PEtab problem of tests/data/petab (23 of Benchmark-Models-PEtab): `petab/import/<problem>`,
//! reading the YAML, the SBML and the tables and compiling the model file and its problem
//! (target ≤ 100 ms each; AMICI's code generation and compile take 10–13 s);
//! `petab/nll-gradient/<problem>`, the NLL and its gradient (forward sensitivities) at the
//! nominal parameters (targets: Boehm ≤ 1 ms, AMICI 6.8 ms; Bachmann ≤ 200 ms, AMICI 2.03 s);
//! `petab/nll-gradient-adjoint/<problem>`, the same by adjoints (`Sensitivities::Adjoint`);
//! `petab/nll-gradient-auto/<problem>`, the same by each experiment's faster way
//! (`Sensitivities::Auto`, what `sysid evaluate --gradient` and Python's gradients do: its
//! measuring first gradient falls in the warm-up).
//! `cargo bench -p sysid-petab -- Boehm` runs one problem's. `SYSID_PETAB_DIR=DIR` benches the
//! problems of another folder instead (a clone of the whole collection:
//! `SYSID_PETAB_DIR=…/Benchmark-Models cargo bench -p sysid-petab -- petab/import/Laske`);
//! a problem there that does not import is left out, with its error on stderr.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use sysid_core::Sensitivities;

/// The folder of the problems: `SYSID_PETAB_DIR`, else tests/data/petab.
fn folder() -> PathBuf {
    match std::env::var_os("SYSID_PETAB_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/petab"),
    }
}

/// The problems: every folder of [`folder`] whose problem imports, sorted.
fn problems() -> Vec<String> {
    let dir = folder();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(Result::ok)
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| match sysid_petab::import(&yaml(name)).map(|i| i.model.problem(None)) {
            Ok(Ok(_)) => true,
            Ok(Err(e)) => {
                eprintln!("{name} left out: {e}");
                false
            }
            Err(e) => {
                eprintln!("{name} left out: {e}");
                false
            }
        })
        .collect();
    names.sort();
    names
}

/// The problem's YAML file: NAME.yaml, else `problem.yaml` (Bertozzi's in the collection).
fn yaml(problem: &str) -> PathBuf {
    let dir = folder().join(problem);
    let named = dir.join(format!("{problem}.yaml"));
    match named.exists() {
        true => named,
        false => dir.join("problem.yaml"),
    }
}

fn bench(c: &mut Criterion) {
    let problems = problems();
    let mut group = c.benchmark_group("petab/import");
    group.sample_size(10).warm_up_time(Duration::from_millis(500));
    for problem in &problems {
        let path = yaml(problem);
        group.bench_function(problem, |b| {
            b.iter(|| {
                let imported = sysid_petab::import(black_box(&path)).expect("imports");
                black_box(imported.model.problem(None).expect("a problem"))
            })
        });
    }
    group.finish();
    // Each posed once for both gradient groups.
    let posed: Vec<_> = problems
        .iter()
        .map(|problem| {
            let imported = sysid_petab::import(&yaml(problem)).expect("imports");
            let p = imported.model.problem(None).expect("a problem");
            let z = p.unknowns().coordinates(&p.guesses());
            (problem, p, z)
        })
        .collect();
    // Forward sensitivities (the linearization the fits use), adjoints, and the faster of the
    // two per experiment.
    for (name, how) in [
        ("petab/nll-gradient", None),
        ("petab/nll-gradient-adjoint", Some(Sensitivities::Adjoint)),
        ("petab/nll-gradient-auto", Some(Sensitivities::Auto)),
    ] {
        let mut group = c.benchmark_group(name);
        group.sample_size(10).warm_up_time(Duration::from_millis(500));
        for (problem, p, z) in &posed {
            group.bench_function(*problem, |b| {
                b.iter(|| {
                    // A preequilibration's steady state is solved afresh, as at a new point.
                    p.forget_cached();
                    if let Some(how) = how {
                        let e = p.nll_gradient(black_box(z.as_slice()), how);
                        black_box(e.expect("integrates"));
                    } else {
                        let lin = p.linearize(black_box(z.as_slice())).expect("integrates");
                        black_box((p.nll(&lin), lin.gradient.norm()));
                    }
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
