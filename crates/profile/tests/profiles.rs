//! Profiles against closed forms: on a model linear in its unknowns every profile is the
//! exact parabola, so each interval is θ̂ ± √(χ²₁(0.95)·(A⁻¹)_ii) with A the Fisher
//! information (ε = ‖r‖², NLL = ε/2 + const); with y′ = −k1·k2·y only the product is
//! identifiable, and both profiles are flat.

use sysid_core::{Data, Problem, Unknown};
use sysid_ode::{Scalar, Signature, System};
use sysid_profile::{Label, Outcome, POINTWISE_95, ProfileOptions, profile, threshold_95};
use sysid_registry::{Registry, Settings};

/// The catalogue's falling body (data of seed 1), Goodman's method and its fit there: a
/// model linear in its unknowns, whose optimum the one Newton step reaches.
fn falling_body_fitted() -> (
    Problem<sysid_systems::FallingBody>,
    sysid_registry::Boxed<sysid_systems::FallingBody>,
    sysid_core::Estimate,
) {
    let problem = sysid_systems::falling_body::falling_body().problem(1).unwrap();
    let goodman = Registry::standard().build("goodman", &Settings::default()).unwrap();
    let optimum = goodman.fit(&problem).unwrap();
    (problem, goodman, optimum)
}

/// The falling body on Goodman's Table I, y and v starting at 0, with `g` as given.
fn table_i_with(g: Unknown) -> Problem<sysid_systems::FallingBody> {
    let case = sysid_systems::falling_body::falling_body();
    let (t, y) = sysid_systems::falling_body::TABLE_I;
    Problem::builder(case.system.clone())
        .unknown_with(Unknown::new("y", 0.0))
        .unknown_with(Unknown::new("v", 0.0))
        .unknown_with(g)
        .data(Data::discrete().series("y", &t, &y))
        .build()
        .unwrap()
}

#[test]
fn a_linear_model_has_the_exact_parabola() {
    let (problem, goodman, optimum) = falling_body_fitted();
    assert!(optimum.converged());
    let z = problem.unknowns().coordinates(&optimum.values);
    let a = problem.linearize(&z).unwrap().normal;
    let inverse = a.try_inverse().unwrap();
    let options = ProfileOptions::default();
    let Outcome::Profiles(profiles) =
        profile(&*goodman, &problem, &optimum, &[], &options).unwrap()
    else {
        panic!("a better optimum than Goodman's one-step fit of a linear model");
    };
    assert_eq!(profiles.len(), 3);
    for (i, p) in profiles.iter().enumerate() {
        let half = (2.0 * options.threshold * inverse[(i, i)]).sqrt();
        let theta = optimum.values[i];
        assert_eq!(p.label, Label::Identifiable, "{}", p.name);
        let [lo, hi] = p.interval;
        let (lo, hi) = (lo.unwrap(), hi.unwrap());
        assert!((lo - (theta - half)).abs() <= 1e-6 * half, "{}: {lo} vs {}", p.name, theta - half);
        assert!((hi - (theta + half)).abs() <= 1e-6 * half, "{}: {hi} vs {}", p.name, theta + half);
        // Every point on the parabola: ΔNLL = (θ − θ̂)²/(2 (A⁻¹)_ii).
        let base = p.points.iter().map(|q| q.nll).fold(f64::INFINITY, f64::min);
        for q in &p.points {
            let expected = (q.value - theta).powi(2) / (2.0 * inverse[(i, i)]);
            assert!((q.nll - base - expected).abs() <= 1e-8 * (1.0 + expected), "{}", p.name);
        }
    }

    // Profiles around a point that is not the optimum (the start: no iteration) find a
    // lower one and say so instead of tracing from there.
    let settings = Settings {
        driver: sysid_core::DriverOptions { max_iterations: 0, ..Default::default() },
        ..Default::default()
    };
    let start = Registry::standard().build("goodman", &settings).unwrap().fit(&problem).unwrap();
    match profile(&*goodman, &problem, &start, &[0], &options).unwrap() {
        Outcome::BetterOptimum(point) => assert!(point.nll < start.nll.unwrap() - 1e-3),
        Outcome::Profiles(_) => panic!("traced from a point that is not the optimum"),
    }
}

/// With a normal prior on g (mean 30, sd 0.5) the profiles trace what the fit minimises, the
/// NLL plus the prior's term: the posterior's exact parabola, curvature A = ΦᵀΦ + e_g e_gᵀ/sd²
/// (rows (1, t, t²/2), unit weights), around the fit's estimate. (Traced on the NLL alone,
/// every profile found a "better optimum" the prior pulled the fit from, and failed.)
#[test]
fn a_prior_pulls_the_profile_as_it_pulls_the_fit() {
    use sysid_core::{Prior, Transform};
    let problem =
        table_i_with(Unknown::new("g", 30.0).prior(Prior::normal(30.0, 0.5, Transform::Lin)));
    let goodman = Registry::standard().build("goodman", &Settings::default()).unwrap();
    let optimum = goodman.fit(&problem).unwrap();
    assert!(optimum.converged() && optimum.prior.is_some(), "{}", optimum.termination);
    let phi = nalgebra::DMatrix::from_fn(4, 3, |m, j| [1.0, m as f64, (m * m) as f64 / 2.0][j]);
    let mut a = phi.transpose() * &phi;
    a[(2, 2)] += 1.0 / (0.5 * 0.5);
    let inverse = a.try_inverse().unwrap();
    let options = ProfileOptions::default();
    let traced = profile(&*goodman, &problem, &optimum, &[], &options).unwrap();
    let Outcome::Profiles(profiles) = traced else { panic!("{traced:?}") };
    for (i, p) in profiles.iter().enumerate() {
        let half = (2.0 * options.threshold * inverse[(i, i)]).sqrt();
        let theta = optimum.values[i];
        assert_eq!(p.label, Label::Identifiable, "{}", p.name);
        let (lo, hi) = (p.interval[0].unwrap(), p.interval[1].unwrap());
        assert!((lo - (theta - half)).abs() <= 1e-6 * half, "{}: {lo} vs {}", p.name, theta - half);
        assert!((hi - (theta + half)).abs() <= 1e-6 * half, "{}: {hi} vs {}", p.name, theta + half);
        for q in &p.points {
            let expected = (q.value - theta).powi(2) / (2.0 * inverse[(i, i)]);
            let rise = q.nll - optimum.objective();
            assert!((rise - expected).abs() <= 1e-8 * (1.0 + expected), "{}", p.name);
        }
    }
}

/// y′ = −k1·k2·y.
#[derive(Clone)]
struct Product(Signature);

impl System for Product {
    fn signature(&self) -> &Signature {
        &self.0
    }
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], _u: &[f64], dy: &mut [T]) {
        dy[0] = -(p[0] * p[1] * y[0]);
    }
}

/// y′ = −k1·k2·y, y(0) = 1, sampled at 0.5 … 4: k1·k2 = 0.5, with a little deterministic
/// scatter so that the minimum is not exact.
fn product_problem() -> Problem<Product> {
    let sys = Product(Signature::new(&["y"], &["k1", "k2"]));
    let times: Vec<f64> = (1..=8).map(|i| 0.5 * i as f64).collect();
    let values: Vec<f64> = times
        .iter()
        .enumerate()
        .map(|(m, t)| (-0.5 * t).exp() * (1.0 + 0.01 * if m % 2 == 0 { 1.0 } else { -1.0 }))
        .collect();
    Problem::builder(sys)
        .known("y", 1.0)
        .unknown_with(Unknown::new("k1", 1.0).log())
        .unknown_with(Unknown::new("k2", 0.4).log())
        .data(Data::discrete().series("y", &times, &values))
        .build()
        .unwrap()
}

#[test]
fn only_a_product_identifiable_is_structurally_non_identifiable() {
    let problem = product_problem();
    let method = Registry::standard().build("levenberg-marquardt", &Settings::default()).unwrap();
    let optimum = method.fit(&problem).unwrap();
    let options = ProfileOptions { max_steps: 20, ..ProfileOptions::default() };
    let Outcome::Profiles(profiles) = profile(&*method, &problem, &optimum, &[], &options).unwrap()
    else {
        panic!("a better optimum");
    };
    for p in &profiles {
        assert_eq!(p.label, Label::StructurallyNonIdentifiable, "{}: {:?}", p.name, p.points);
        assert_eq!(p.interval, [None, None], "{}", p.name);
        // Walked far (20 steps each way, up to a factor e per step), never rising.
        let (first, last) = (p.points[0].value, p.points[p.points.len() - 1].value);
        assert!(p.points.len() > 20 && last / first > 1e6, "{}: {first} to {last}", p.name);
        // The other unknown compensates: the product stays at the optimum's.
        let product = optimum.values[0] * optimum.values[1];
        for q in &p.points {
            let along = q.estimates[0] * q.estimates[1];
            assert!((along - product).abs() <= 1e-6 * product, "{}: {along} vs {product}", p.name);
        }
    }
}

/// The same flat profiles from an optimum whose certificate fails (a gtol of 1e-15, which
/// the minimum cannot meet) are not called structural: that is a property of the model at a
/// minimum, and the point is not known to be one.
#[test]
fn a_flat_profile_from_an_uncertified_optimum_is_not_called_structural() {
    let problem = product_problem();
    let mut settings = Settings::default();
    settings.driver.gtol = Some(1e-15);
    settings.driver.max_iterations = 30;
    let method = Registry::standard().build("levenberg-marquardt", &settings).unwrap();
    let optimum = method.fit(&problem).unwrap();
    assert!(!optimum.converged(), "{}", optimum.termination);
    let options = ProfileOptions { max_steps: 20, ..ProfileOptions::default() };
    let Outcome::Profiles(profiles) = profile(&*method, &problem, &optimum, &[], &options).unwrap()
    else {
        panic!("a better optimum");
    };
    for p in &profiles {
        let rise = p.points.iter().map(|q| q.nll - optimum.objective()).fold(0.0, f64::max);
        assert!(rise < 1e-3 * options.threshold, "{}: flat, rise {rise}", p.name);
        assert_eq!(p.label, Label::PracticallyNonIdentifiable, "{}", p.name);
    }
}

#[test]
fn thresholds_are_half_the_chi_square_quantiles() {
    // χ²₁(0.95) = 1.959963984540054², χ²₃(0.95) = 7.814727903251178 (tables).
    assert!((POINTWISE_95 - 1.959_963_984_540_054_f64.powi(2) / 2.0).abs() < 1e-14);
    assert_eq!(threshold_95(None).to_bits(), POINTWISE_95.to_bits());
    assert_eq!(threshold_95(Some(1)).to_bits(), POINTWISE_95.to_bits());
    assert!((threshold_95(Some(3)) - 7.814_727_903_251_178 / 2.0).abs() < 1e-14);
    // χ²₂'s CDF is 1 − e^(−x/2): its quantile is −2 ln 0.05 in closed form (cdflib's own
    // inverse was 2.1e-9 off, relative).
    let two = -(0.05f64.ln());
    assert!(
        (threshold_95(Some(2)) - two).abs() <= 4.0 * f64::EPSILON * two,
        "{}",
        threshold_95(Some(2))
    );
}

/// Goodman's method, except that the fits along `name`'s profile panic from the `after`-th
/// on, as a defect would.
struct Panics<'a, S: System> {
    inner: &'a (dyn sysid_core::Method<S> + Sync),
    name: String,
    after: usize,
    calls: std::sync::atomic::AtomicUsize,
}

impl<S: System> sysid_core::Method<S> for Panics<'_, S> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn fit_from(
        &self,
        problem: &Problem<S>,
        start: &[f64],
    ) -> Result<sysid_core::Estimate, sysid_core::FitError> {
        let profiling = !problem.unknowns().list().iter().any(|u| u.name == self.name);
        if profiling
            && self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1 >= self.after
        {
            panic!("a finite move");
        }
        self.inner.fit_from(problem, start)
    }
}

/// A fit that panics along one unknown's profile ends that profile's tracing as `failed`, with
/// the panic's message and the points walked before it; the other unknowns' profiles are the
/// ones traced without the panics, and the JSON says `failed` (null for the others).
#[test]
fn a_fit_that_panics_fails_its_profile_and_the_others_stand() {
    let (problem, goodman, optimum) = falling_body_fitted();
    let options = ProfileOptions::default();
    let Outcome::Profiles(plain) = profile(&*goodman, &problem, &optimum, &[], &options).unwrap()
    else {
        panic!("a better optimum than Goodman's one-step fit of a linear model");
    };
    let name = problem.names()[1].clone();
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let panics = Panics { inner: &*goodman, name: name.clone(), after: 4, calls };
    let Outcome::Profiles(some) = profile(&panics, &problem, &optimum, &[], &options)
        .expect("the profiles survive the panics")
    else {
        panic!("a better optimum");
    };
    assert_eq!(some.len(), plain.len());
    for (p, q) in some.iter().zip(&plain) {
        if p.name != name {
            assert_eq!(p, q, "{} is traced as without the panics", p.name);
            assert_eq!(p.failed, None);
            continue;
        }
        assert_eq!(p.label, Label::Failed);
        assert_eq!(p.interval, [None, None], "no crossing is claimed");
        assert_eq!(p.failed.as_deref(), Some("a finite move"));
        // The optimum and the fits before the 4th (a step retried shorter discards its fit).
        assert!((2..=4).contains(&p.points.len()), "{:?}", p.points);
        for point in &p.points {
            assert!(q.points.contains(point), "{point:?} is a point of the profile without panics");
        }
        let record = serde_json::to_value(p.record()).unwrap();
        assert_eq!(record["label"], "failed");
        assert_eq!(record["failed"], "a finite move");
    }
    let other = plain.iter().find(|p| p.name != name).unwrap();
    assert!(serde_json::to_value(other.record()).unwrap()["failed"].is_null());
}

/// A budget too short to walk anywhere decides nothing: with two points the profiles of the
/// falling body's identifiable unknowns had risen by nothing yet and were called structurally
/// non-identifiable. With the budget that crosses (the test above), they are identifiable.
#[test]
fn a_budget_too_short_to_walk_is_undecided() {
    let (problem, goodman, optimum) = falling_body_fitted();
    for max_steps in [1, 2] {
        let options = ProfileOptions { max_steps, ..ProfileOptions::default() };
        let Outcome::Profiles(profiles) =
            profile(&*goodman, &problem, &optimum, &[], &options).unwrap()
        else {
            panic!("a better optimum");
        };
        for p in &profiles {
            assert_eq!(p.label, Label::Undecided, "{max_steps}: {}: {:?}", p.name, p.points);
            // The budget counts points walked, the optimum's aside: a step retried at half
            // its length had used it up, and left a side of one point with none.
            assert_eq!(
                p.points.len(),
                1 + 2 * max_steps,
                "{max_steps}: {}: {:?}",
                p.name,
                p.points
            );
        }
    }
    // Profiles asked for in another order come in the problem's.
    let options = ProfileOptions { max_steps: 1, ..ProfileOptions::default() };
    let Outcome::Profiles(profiles) =
        profile(&*goodman, &problem, &optimum, &[2, 0], &options).unwrap()
    else {
        panic!("a better optimum");
    };
    let names: Vec<&str> = profiles.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["y", "g"]);
}

/// An optimum on a bound (the falling body with g ≤ 32, its free optimum 32.5): the side
/// toward the bound is open there at once, walks no point (a fit held at the bound repeated
/// the optimum's value with another last digit, a hair below it), and decides the verdict
/// whatever the other side's budget left: `practically_non_identifiable`, where a budget of
/// one point had said `undecided`.
#[test]
fn a_side_from_an_optimum_on_its_bound_is_open_at_once() {
    let problem = table_i_with(Unknown::new("g", 30.0).max(32.0));
    let method = Registry::standard().build("levenberg-marquardt", &Settings::default()).unwrap();
    let optimum = method.fit(&problem).unwrap();
    assert!(optimum.converged(), "{}", optimum.termination);
    assert_eq!(
        optimum.values[2].to_bits(),
        32f64.to_bits(),
        "g on its bound: {}",
        optimum.values[2]
    );
    for max_steps in [1, 60] {
        let options = ProfileOptions { max_steps, ..ProfileOptions::default() };
        let traced = profile(&*method, &problem, &optimum, &[2], &options).unwrap();
        let Outcome::Profiles(profiles) = traced else { panic!("{traced:?}") };
        let g = &profiles[0];
        assert_eq!(g.label, Label::PracticallyNonIdentifiable, "{max_steps}: {:?}", g.points);
        assert!(g.interval[1].is_none(), "{:?}", g.interval);
        assert!(g.points.iter().all(|q| q.value <= 32.0), "{:?}", g.points);
        let at_bound = g.points.iter().filter(|q| q.value.to_bits() == 32f64.to_bits()).count();
        assert_eq!(at_bound, 1, "{max_steps}: the optimum's point once: {:?}", g.points);
        if max_steps == 60 {
            assert!(g.interval[0].is_some_and(|lo| lo < 32.0), "{:?}", g.interval);
        }
    }
}

/// What cannot be traced is refused, not traced into a verdict (found by a probe of the
/// library): a threshold of −1 made every profile "identifiable" with a zero-width interval,
/// an index beyond the unknowns panicked, and the optimum of another problem gave zero-width
/// intervals (here a fit with g held).
#[test]
fn what_cannot_be_traced_is_refused() {
    let (problem, goodman, optimum) = falling_body_fitted();
    let refused =
        |only: &[usize], options: ProfileOptions, optimum: &sysid_core::Estimate| match profile(
            &*goodman, &problem, optimum, only, &options,
        ) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("traced: {only:?}"),
        };
    let options = |threshold: f64| ProfileOptions { threshold, ..ProfileOptions::default() };
    for threshold in [-1.0, 0.0, f64::NAN, f64::INFINITY] {
        let e = refused(&[], options(threshold), &optimum);
        assert!(e.starts_with("the threshold must be a finite positive ΔNLL"), "{e}");
    }
    let e = refused(&[5], ProfileOptions::default(), &optimum);
    assert_eq!(e, "unknown 5 to profile: the problem has 3 (y, v, g)");
    let other = problem.clone().with_fixed(&[("g".to_string(), 32.0)]).unwrap();
    let elsewhere = goodman.fit(&other).unwrap();
    let e = refused(&[], ProfileOptions::default(), &elsewhere);
    assert!(e.starts_with("the optimum is a fit of other unknowns ("), "{e}");
}

/// Profiles asked to stop (`sysid_core::observer::stop_when`; Ctrl-C in the command line and
/// Python) fit no further point: asked before they begin, every profile is labelled
/// `stopped` and holds the optimum alone.
#[test]
fn profiles_asked_to_stop_fit_no_further_point() {
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;
    let (problem, goodman, optimum) = falling_body_fitted();
    let options = ProfileOptions::default();
    let stop = Arc::new(AtomicBool::new(true));
    let stopped = sysid_core::observer::stop_when(stop, || {
        profile(&*goodman, &problem, &optimum, &[], &options)
    });
    let Ok(Outcome::Profiles(profiles)) = stopped else { panic!("{stopped:?}") };
    assert_eq!(profiles.len(), 3);
    for p in &profiles {
        assert_eq!((p.label, p.points.len(), p.interval), (Label::Stopped, 1, [None, None]));
    }
}

/// Stopped part-way, on one thread: the first profile keeps the points fitted before the stop
/// (each one a fit that ended before it: at or above the optimum's NLL, converged) under the
/// verdict `stopped`, the others hold the optimum alone; the JSON's label is "stopped".
#[test]
fn a_stopped_profile_keeps_the_points_fitted_before_the_stop() {
    use std::cell::Cell;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let (problem, goodman, optimum) = falling_body_fitted();
    let options = ProfileOptions::default();
    let flag = Arc::new(AtomicBool::new(false));
    let set = Arc::clone(&flag);
    let heard = Cell::new(0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    // Every fit along the profiles is heard of on the one thread; the stop comes at the 40th
    // iterate, within the first profile (y's: the assertions below fail otherwise).
    let traced = pool.install(|| {
        sysid_core::observer::observe(
            move |_| {
                heard.set(heard.get() + 1);
                if heard.get() == 40 {
                    set.store(true, Ordering::Relaxed);
                }
            },
            || {
                sysid_core::observer::stop_when(flag, || {
                    profile(&*goodman, &problem, &optimum, &[], &options)
                })
            },
        )
    });
    let Ok(Outcome::Profiles(profiles)) = traced else { panic!("{traced:?}") };
    let first = &profiles[0];
    assert_eq!(first.label, Label::Stopped);
    assert!(first.points.len() > 2, "{} points", first.points.len());
    let base = sysid_profile::objective(&optimum);
    for p in &first.points {
        assert!(p.converged && p.nll >= base - 1e-9 * base.abs(), "{p:?}");
    }
    assert!(profiles[1..].iter().all(|p| p.label == Label::Stopped && p.points.len() == 1));
    let record = serde_json::to_value(first.record()).unwrap();
    assert_eq!(record["label"], "stopped");
}
