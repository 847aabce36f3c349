//! Studies: determinism across thread counts and shards, resume after a kill, the
//! Cramér–Rao bound against a closed form, and Goodman's efficiency on van der Pol.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde_json::Value;
use sysid_montecarlo::files::{self, DirLock, RunOptions, Shard};
use sysid_montecarlo::{Scenario, SharedMethod, Study, StudySpec};
use sysid_ode::System;
use sysid_registry::{Registry, Settings};
use sysid_systems::Case;

fn method<S: System + Clone + Send + Sync>(name: &str) -> SharedMethod<S> {
    Registry::standard().build(name, &Settings::default()).unwrap()
}

fn study<S: System + Clone + Send + Sync>(
    case: &Case<S>,
    methods: &[&str],
    trials: usize,
    perturb: f64,
) -> Study<S> {
    let spec = StudySpec {
        system: case.name.into(),
        methods: methods.iter().map(|m| m.to_string()).collect(),
        reference: "goodman-halving".into(),
        trials,
        noise: 1.0,
        perturb,
        seed: 7,
        fixed: Vec::new(),
        driver: Default::default(),
        settings: Default::default(),
    };
    let methods = methods.iter().map(|m| method(m)).collect();
    Study::new(spec, Scenario::from_case(case).unwrap(), methods, method("goodman-halving"))
        .unwrap()
}

/// A scratch directory, removed at the end.
struct Scratch(PathBuf);
impl Scratch {
    fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("sysid-study-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        Self(dir)
    }
    fn join(&self, p: &str) -> PathBuf {
        self.0.join(p)
    }
}
impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A JSON value without its measured times (`time_ms` anywhere): what must be identical.
fn untimed(mut v: Value) -> Value {
    match &mut v {
        Value::Object(map) => {
            map.remove("time_ms");
            for (_, x) in map.iter_mut() {
                *x = untimed(x.take());
            }
        }
        Value::Array(items) => {
            for x in items.iter_mut() {
                *x = untimed(x.take());
            }
        }
        _ => {}
    }
    v
}

/// A study directory's results without the times: trials.jsonl line by line, summary.json
/// and study.json.
fn results(dir: &Path) -> (Vec<Value>, Value, Value) {
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    let lines =
        read("trials.jsonl").lines().map(|l| untimed(serde_json::from_str(l).unwrap())).collect();
    (
        lines,
        untimed(serde_json::from_str(&read("summary.json")).unwrap()),
        serde_json::from_str(&read("study.json")).unwrap(),
    )
}

/// A new study: neither resumed nor forced.
fn fresh() -> RunOptions {
    RunOptions::default()
}

/// Continue (or start) the study.
fn resume() -> RunOptions {
    RunOptions { resume: true, ..RunOptions::default() }
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

#[test]
fn results_do_not_depend_on_threads_shards_or_interruptions() {
    let case = sysid_systems::van_der_pol::van_der_pol();
    let study = study(&case, &["goodman", "gauss-newton-ls"], 12, 0.3);
    let scratch = Scratch::new("determinism");
    let quiet = |_: usize, _: usize| {};

    // One thread and two threads.
    let one = scratch.join("one");
    pool(1).install(|| files::run(&study, &one, fresh(), &quiet)).unwrap();
    let two = scratch.join("two");
    pool(2).install(|| files::run(&study, &two, fresh(), &quiet)).unwrap();
    let reference = results(&one);
    assert_eq!(reference.0.len(), 12 * 3, "a line per trial and method, the reference included");
    assert_eq!(results(&two), reference);
    // Bit-identical estimates, not just close: compare the raw text of one line.
    let line = |d: &Path| {
        std::fs::read_to_string(d.join("trials.jsonl")).unwrap().lines().nth(4).unwrap().to_string()
    };
    let strip = |l: String| l.split("\"time_ms\"").next().unwrap().to_string();
    assert_eq!(strip(line(&one)), strip(line(&two)));

    // Three shards, merged.
    let shards: Vec<PathBuf> = (1..=3).map(|i| scratch.join(&format!("shard{i}"))).collect();
    for (i, dir) in shards.iter().enumerate() {
        let shard = Shard { index: i + 1, count: 3 };
        files::run(&study, dir, RunOptions { shard: Some(shard), ..fresh() }, &quiet).unwrap();
    }
    let merged = scratch.join("merged");
    files::merge(&shards, &merged, false).unwrap();
    assert_eq!(results(&merged), reference);
    // Merging again (a requeued merge job) gives the same files; into another study, no.
    files::merge(&shards, &merged, false).unwrap();
    assert_eq!(results(&merged), reference);
    let other = scratch.join("other");
    let different = self::study(&case, &["goodman", "gauss-newton-ls"], 2, 0.3);
    files::run(&different, &other, fresh(), &quiet).unwrap();
    let e = files::merge(&shards, &other, false).unwrap_err().to_string();
    assert!(e.contains("already holds another study: trials 2 vs 12"), "{e}");
    // A missing shard and a shard given twice are refused.
    let e = files::merge(&shards[..2], &scratch.join("partial"), false).unwrap_err().to_string();
    assert!(
        e.contains("4 of 12 trials are in none of the shards")
            && e.contains("3/3 (no directory given)"),
        "{e}"
    );
    let twice = [shards[0].clone(), shards[0].clone(), shards[1].clone(), shards[2].clone()];
    let e = files::merge(&twice, &scratch.join("twice"), false).unwrap_err().to_string();
    assert!(e.contains("twice"), "{e}");

    // A killed run: keep the first 14 lines (4 trials and part of a fifth) and half of the
    // next line, as a kill in the middle of a write leaves them; resume.
    let killed = scratch.join("killed");
    std::fs::create_dir_all(&killed).unwrap();
    std::fs::copy(one.join("study.json"), killed.join("study.json")).unwrap();
    let text = std::fs::read_to_string(one.join("trials.jsonl")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let torn = format!("{}\n{}", lines[..14].join("\n"), &lines[14][..lines[14].len() / 2]);
    std::fs::write(killed.join("trials.jsonl"), torn).unwrap();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let count = |n: usize, _: usize| {
        done.fetch_max(n, std::sync::atomic::Ordering::Relaxed);
    };
    files::run(&study, &killed, resume(), &count).unwrap();
    assert_eq!(done.into_inner(), 12 - 4, "only the trials not complete run again");
    assert_eq!(results(&killed), reference);

    // A stopped run (Ctrl-C in the command line): the flag set once 3 trials are written, on
    // two threads. No trial is begun after it, the trial running then is not written, no
    // summary is written, and a resumed run ends where the uninterrupted one did.
    let stopped = scratch.join("stopped");
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stop = |n: usize, _: usize| {
        if n >= 3 {
            flag.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    };
    let run = || files::run(&study, &stopped, fresh(), &stop);
    let e = pool(2).install(|| sysid_core::observer::stop_when(flag.clone(), run)).unwrap_err();
    assert!(matches!(e, sysid_montecarlo::StudyError::Interrupted(_)), "{e:?}");
    let kept = std::fs::read_to_string(stopped.join("trials.jsonl")).unwrap();
    let kept: Vec<Value> =
        kept.lines().map(|l| untimed(serde_json::from_str(l).unwrap())).collect();
    // The third trial written set the flag; the other thread's trial then running is dropped
    // (or, where it was written between the third's write and its count, kept whole).
    let n = kept.len() / 3;
    assert!(kept.len().is_multiple_of(3) && (3..=4).contains(&n), "{kept:?}");
    assert!(kept.iter().all(|r| reference.0.contains(r)), "a kept trial differs");
    assert!(e.to_string().contains(&format!("stopped: {n} of the 12 trials are complete")), "{e}");
    assert!(!stopped.join("summary.json").exists());
    files::run(&study, &stopped, resume(), &quiet).unwrap();
    assert_eq!(results(&stopped), reference);
}

#[test]
fn directories_are_never_overwritten_or_mixed() {
    let case = sysid_systems::falling_body::falling_body();
    let scratch = Scratch::new("mismatch");
    let dir = scratch.join("a");
    let quiet = |_: usize, _: usize| {};
    // Resuming where nothing was started starts the study.
    files::run(&study(&case, &["goodman"], 3, 0.1), &dir, resume(), &quiet).unwrap();
    let e = files::run(&study(&case, &["goodman"], 3, 0.1), &dir, fresh(), &quiet).unwrap_err();
    assert!(e.to_string().contains("already holds a study"), "{e}");
    let e = files::run(&study(&case, &["goodman"], 5, 0.1), &dir, resume(), &quiet).unwrap_err();
    assert!(e.to_string().contains("trials 3 vs 5"), "{e}");

    // Settings that change results are recorded and named: the integrator, method options,
    // the inputs' hashes.
    let mut loose = sysid_systems::falling_body::falling_body();
    loose.integrator.rtol = 1e-6;
    let spec = study(&case, &["goodman"], 3, 0.1).spec().clone();
    // Goodman against the reference, with these settings, on this case.
    let goodman = |spec: StudySpec, case: &Case<_>| {
        let scenario = Scenario::from_case(case).unwrap();
        Study::new(spec, scenario, vec![method("goodman")], method("goodman-halving")).unwrap()
    };
    let other = goodman(spec.clone(), &loose);
    let e = files::run(&other, &dir, resume(), &quiet).unwrap_err().to_string();
    assert!(e.contains("integrator.rtol 1e-8 vs 1e-6"), "{e}");
    let mut with_model = spec.clone();
    with_model.settings.insert("model".into(), "sha256:ab12".into());
    let with_model = goodman(with_model, &case);
    let e = files::run(&with_model, &dir, resume(), &quiet).unwrap_err().to_string();
    assert!(e.contains("settings.model (not recorded) vs sha256:ab12"), "{e}");
    let mut gtol = spec;
    gtol.driver.gtol = Some(1e-3);
    let gtol = goodman(gtol, &case);
    let e = files::run(&gtol, &dir, resume(), &quiet).unwrap_err().to_string();
    assert!(e.contains("driver.gtol (not recorded) vs 0.001"), "{e}");

    // A second run into a directory another holds is refused at once, naming the holder.
    let held = DirLock::acquire(&dir).unwrap();
    let e = files::run(&study(&case, &["goodman"], 3, 0.1), &dir, resume(), &quiet).unwrap_err();
    let pid = format!("pid {}", std::process::id());
    assert!(
        e.to_string().contains("another sysid is writing to") && e.to_string().contains(&pid),
        "{e}"
    );
    drop(held);
    files::run(&study(&case, &["goodman"], 3, 0.1), &dir, resume(), &quiet).unwrap();

    // Files sysid did not write are never replaced: refused unless forced, and then kept.
    let user = scratch.join("user");
    std::fs::create_dir_all(&user).unwrap();
    std::fs::write(user.join("summary.md"), "my notes").unwrap();
    let e = files::run(&study(&case, &["goodman"], 3, 0.1), &user, fresh(), &quiet).unwrap_err();
    assert!(e.to_string().contains("holds files sysid did not write (summary.md)"), "{e}");
    assert_eq!(std::fs::read_to_string(user.join("summary.md")).unwrap(), "my notes");
    std::fs::write(dir.join("notes.txt"), "mine").unwrap();
    let e = files::run(&study(&case, &["goodman"], 3, 0.1), &dir, resume(), &quiet).unwrap_err();
    assert!(e.to_string().contains("(notes.txt)"), "{e}");
    let forced = RunOptions { force: true, ..resume() };
    files::run(&study(&case, &["goodman"], 3, 0.1), &dir, forced, &quiet).unwrap();
    assert_eq!(std::fs::read_to_string(dir.join("notes.txt")).unwrap(), "mine");

    // An I/O error names the user's path and says the system's words once.
    let file = scratch.join("a-file");
    std::fs::write(&file, "").unwrap();
    let e = files::run(&study(&case, &["goodman"], 3, 0.1), &file, fresh(), &quiet).unwrap_err();
    let e = format!("{:#}", anyhow::Error::from(e));
    assert!(e.starts_with(&file.display().to_string()), "{e}");
    assert_eq!(e.matches("os error").count(), 1, "{e}");

    assert_eq!("2/4".parse::<Shard>(), Ok(Shard { index: 2, count: 4 }));
    for bad in ["0/4", "5/4", "2", "a/b"] {
        assert!(bad.parse::<Shard>().is_err(), "{bad}");
    }
}

#[test]
fn cramer_rao_bound_of_the_falling_body_is_the_regression_covariance() {
    // y(t) = y0 + v0 t + g t²/2 is linear in the unknowns: the bound is exact,
    // σ² (ΦᵀΦ)⁻¹ with rows (1, t, t²/2), σ² = ε/(N − k) = 1.25 of the paper's fit, times the
    // noise multiple squared.
    let case = sysid_systems::falling_body::falling_body();
    let scenario = Scenario::from_case(&case).unwrap();
    let phi = DMatrix::from_fn(4, 3, |m, j| [1.0, m as f64, (m * m) as f64 / 2.0][j]);
    let expected = (phi.transpose() * &phi).try_inverse().unwrap() * 1.25;
    for noise in [1.0, 3.0] {
        let crb = scenario.cramer_rao(noise).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let e = expected[(i, j)] * noise * noise;
                assert!(
                    (crb[(i, j)] - e).abs() <= 1e-9 * e.abs().max(1.0),
                    "({i}, {j}): {} vs {e}",
                    crb[(i, j)]
                );
            }
        }
    }
}

/// With a normal prior on g (mean 30, sd 0.5), the bound adds the prior's information, not
/// scaled by the noise: (ΦᵀΦ/(noise² σ²) + e_g e_gᵀ/sd²)⁻¹, σ² = 1.25 the data's own. (Before,
/// the prior's row, after the data's, was read past the data's weights: a panic.)
#[test]
fn cramer_rao_bound_with_a_prior_adds_its_information() {
    use sysid_core::{Prior, Problem, Transform, Unknown};
    let case = sysid_systems::falling_body::falling_body();
    let (t, y) = sysid_systems::falling_body::TABLE_I;
    let sigma = 1.25f64.sqrt();
    // Weights (σ² = 1.25 of the data) and a noise model of known σ: the two ways the bound
    // is formed.
    let weighted = sysid_core::Data::discrete().series("y", &t, &y);
    let known = sysid_core::Noise::Known(vec![sigma; 4]);
    let modelled =
        sysid_core::Data::discrete().series_with_noise("y", &t, &y, known, Transform::Lin);
    let phi = DMatrix::from_fn(4, 3, |m, j| [1.0, m as f64, (m * m) as f64 / 2.0][j]);
    for data in [weighted, modelled] {
        let prior = Prior::normal(30.0, 0.5, Transform::Lin);
        let problem = Problem::builder(case.system.clone())
            .unknown_with(Unknown::new("y", -0.25))
            .unknown_with(Unknown::new("v", -0.25))
            .unknown_with(Unknown::new("g", 32.5).prior(prior))
            .data(data)
            .build()
            .unwrap();
        let scenario = Scenario::new(problem, vec![-0.25, -0.25, 32.5], vec![sigma; 4]).unwrap();
        for noise in [1.0, 3.0] {
            let mut fisher = phi.transpose() * &phi / (1.25 * noise * noise);
            fisher[(2, 2)] += 1.0 / (0.5 * 0.5);
            let expected = fisher.try_inverse().unwrap();
            let crb = scenario.cramer_rao(noise).unwrap();
            for i in 0..3 {
                for j in 0..3 {
                    let (got, e) = (crb[(i, j)], expected[(i, j)]);
                    let tol = 1e-9 * e.abs().max(1e-3);
                    assert!((got - e).abs() <= tol, "({i}, {j}): {got} vs {e}");
                }
            }
        }
    }
}

#[test]
fn goodman_is_efficient_for_mu_on_van_der_pol() {
    // 200 trials at ρ = 0.1: the spread of Goodman's μ against the Cramér–Rao bound. With
    // 200 samples the variance ratio has a relative standard error of about 10 %.
    let case = sysid_systems::van_der_pol::van_der_pol();
    let study = study(&case, &["goodman"], 200, 0.1);
    let scratch = Scratch::new("efficiency");
    let summary = files::run(&study, &scratch.join("vdp"), fresh(), &|_, _| {}).unwrap();
    let goodman = &summary.methods[1];
    assert_eq!(goodman.method, "goodman");
    assert!(goodman.success_rate > 0.99, "{}", goodman.success_rate);
    let mu = &goodman.accuracy[0];
    assert_eq!(mu.name, "mu");
    let efficiency = mu.efficiency.unwrap();
    assert!((0.8..=1.25).contains(&efficiency), "efficiency {efficiency}");
    // The fits' own 95 % intervals cover the truth about 95 % of the time.
    let coverage = mu.coverage.unwrap();
    assert!((0.9..=0.99).contains(&coverage), "coverage {coverage}");
}

#[test]
fn intervals_with_one_degree_of_freedom_cover_95_percent() {
    // The paper's falling body: 4 data, 3 unknowns, N − k = 1. A linear model with Gaussian
    // noise: estimate ± t_{0.975, 1}·se (t = 12.71) covers the truth 95 % of the time
    // exactly; ±1.96·se covers 70 % (P(|T₁| ≤ 1.96) = 2 arctan(1.96)/π). 2000 trials: the
    // binomial standard deviation of a coverage is 0.5 %, so [92 %, 98 %] is six of them.
    let case = sysid_systems::falling_body::falling_body();
    let study = study(&case, &["goodman"], 2000, 0.3);
    let scratch = Scratch::new("coverage");
    let summary = files::run(&study, &scratch.join("fb"), fresh(), &|_, _| {}).unwrap();
    let goodman = &summary.methods[1];
    assert_eq!(goodman.successes, 2000);
    for a in &goodman.accuracy {
        let coverage = a.coverage.unwrap();
        assert!((0.92..=0.98).contains(&coverage), "{}: coverage {coverage}", a.name);
    }
    // The normal quantile would cover far less: recount with ±1.96 se from the records.
    let (records, _, _) = results(&scratch.join("fb"));
    let fits: Vec<&Value> = records.iter().filter(|r| r["method"] == "goodman").collect();
    let truth = study.scenario().truth();
    let inside = fits
        .iter()
        .filter(|r| {
            let (v, se) = (&r["values"], &r["std_errors"]);
            (v[2].as_f64().unwrap() - truth[2]).abs() <= 1.959964 * se[2].as_f64().unwrap()
        })
        .count();
    let normal = inside as f64 / fits.len() as f64;
    let expected = 2.0 * 1.959964f64.atan() / std::f64::consts::PI;
    assert!((normal - expected).abs() < 0.03, "±1.96 se covers {normal}, expected {expected}");
}
