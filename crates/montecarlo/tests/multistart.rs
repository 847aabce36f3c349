//! Multistart: the Latin hypercube's design, and the minima of lotka-volterra, whose
//! catalogue start leads the line-search methods to a spurious minimum (ε ≈ 56 116).

use sysid_core::Unknown;
use sysid_montecarlo::multistart::{SAME_MINIMUM_RTOL, starts};
use sysid_montecarlo::{MultistartOptions, Sampling, multistart};
use sysid_ode::testing::assert_close;
use sysid_registry::{Registry, Settings};

#[test]
fn the_latin_hypercube_puts_one_start_in_every_stratum() {
    // compartment-chain: 23 unknowns bounded below only, spread ±ρ around the guess.
    let case = sysid_systems::compartment_chain::compartment_chain();
    let problem = case.problem(1).unwrap();
    let options = MultistartOptions {
        starts: 21,
        seed: 7,
        sampling: Sampling::LatinHypercube,
        ..Default::default()
    };
    let list = starts(&problem, &options);
    assert_eq!(list.len(), 21);
    assert_eq!(list[0], problem.guesses(), "the guess is the first start");
    for (i, u) in problem.unknowns().list().iter().enumerate() {
        // u = (value/guess − 1)/ρ lies in [−1, 1]; its 20 strata of width 0.1 hold one each.
        let mut strata: Vec<usize> = list[1..]
            .iter()
            .map(|s| {
                assert!(s[i] >= u.min.unwrap_or(f64::NEG_INFINITY), "{} below its bound", u.name);
                let t = if u.guess == 0.0 { s[i] / 0.5 } else { (s[i] / u.guess - 1.0) / 0.5 };
                assert!((-1.0..=1.0).contains(&t), "{}: {t}", u.name);
                (((t + 1.0) / 2.0 * 20.0).floor() as usize).min(19)
            })
            .collect();
        if u.guess != 0.0 && u.min.is_none_or(|m| m <= u.guess * 0.5) {
            strata.sort_unstable();
            assert_eq!(strata, (0..20).collect::<Vec<_>>(), "{}", u.name);
        }
    }
    assert_eq!(starts(&problem, &options), list, "seeded: the same starts again");
    let other = starts(&problem, &MultistartOptions { seed: 8, ..options });
    assert_ne!(other, list, "another seed, other starts");
}

#[test]
fn an_unknown_with_two_bounds_is_drawn_from_its_box_on_its_scale() {
    let mut case = sysid_systems::lotka_volterra::lotka_volterra();
    case.unknowns[0] = Unknown::new("a", 1.2).min(0.5).max(2.5);
    case.unknowns[1] = Unknown::new("b", 0.8).min(0.01).max(100.0).log();
    let problem = case.problem(1).unwrap();
    let list = starts(
        &problem,
        &MultistartOptions {
            starts: 11,
            seed: 3,
            sampling: Sampling::LatinHypercube,
            ..Default::default()
        },
    );
    let mut a: Vec<usize> =
        list[1..].iter().map(|s| ((s[0] - 0.5) / 2.0 * 10.0) as usize).collect();
    let mut b: Vec<usize> =
        list[1..].iter().map(|s| ((s[1] / 0.01).log10() / 4.0 * 10.0) as usize).collect();
    a.sort_unstable();
    b.sort_unstable();
    assert_eq!(a, (0..10).collect::<Vec<_>>(), "a: one start per tenth of [0.5, 2.5]");
    assert_eq!(b, (0..10).collect::<Vec<_>>(), "b: one start per tenth of [ln 0.01, ln 100]");
}

#[test]
fn lotka_volterra_multistart_finds_the_true_minimum_and_counts_the_others() {
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let registry = Registry::standard();
    let method = registry.build("gauss-newton-ls", &Settings::default()).unwrap();
    // The independent reference: Goodman's method from the truth.
    let goodman = registry.build("goodman", &Settings::default()).unwrap();
    let truth = goodman.fit_from(&problem, &case.expected_values().unwrap()).unwrap();
    assert!(truth.converged());
    let single = method.fit(&problem).unwrap();
    assert!(single.cost > 1e4, "from the guess alone: the spurious minimum, ε = {}", single.cost);

    let options = MultistartOptions { starts: 12, seed: 1, ..Default::default() };
    let run = multistart(&*method, &problem, &options).unwrap();
    let s = &run.starts;
    assert!(run.best.converged());
    assert_close(run.best.cost, truth.cost, 1e-9);
    assert_eq!(s.count, 12);
    assert_eq!(
        s.minima[0].cost.to_bits(),
        run.best.cost.to_bits(),
        "the best is the first minimum"
    );
    // Reached: converged within 0.1 of the best objective, the one minimum included.
    assert!(s.minima[0].count <= s.reached_best);
    assert!(s.reached_best >= 1 && s.reached_best < s.converged, "{s:?}");
    assert!(s.minima.len() >= 2, "the spurious minimum of the guess is among them: {s:?}");
    assert!(s.minima.windows(2).all(|w| w[0].cost * (1.0 + SAME_MINIMUM_RTOL) < w[1].cost));
    assert_eq!(s.minima.iter().map(|m| m.count).sum::<usize>(), s.converged);
    // The guess (start 0) fits to the single fit's spurious minimum, which is among the
    // minima (reported by the start that reached it lowest, not necessarily the guess).
    let guess = s.waterfall.iter().find(|w| w.start == 0).expect("the guess's row");
    let guess_cost = guess.cost.expect("the guess's fit began");
    assert_close(guess_cost, single.cost, 1e-9);
    let spurious =
        s.minima.iter().find(|m| (m.cost - guess_cost).abs() <= SAME_MINIMUM_RTOL * guess_cost);
    assert!(spurious.is_some_and(|m| m.cost <= guess_cost), "the guess's minimum: {s:?}");
    // Fits run on rayon, results do not depend on it.
    let again = multistart(&*method, &problem, &options).unwrap();
    assert_eq!(again.starts.minima, s.minima);
}

/// An unknown with an initialization is drawn from it (PEtab's initializationPriorType):
/// 2 000 uniform draws of a normal one on log10 have the normal's mean and sd on log10 (to
/// the sampling error, 4 standard errors), and never leave the bounds; a Latin hypercube of a
/// Laplace one puts each stratum's draw at that stratum's quantiles.
#[test]
fn an_initialization_is_the_distribution_of_the_starts() {
    use sysid_core::{Distribution, Initialization, Transform};
    let mut case = sysid_systems::lotka_volterra::lotka_volterra();
    let normal = Initialization {
        distribution: Distribution::Normal,
        a: -1.0,
        b: 0.5,
        on: Transform::Log10,
    };
    case.unknowns[0] = Unknown::new("a", 0.1).min(1e-3).max(10.0).log().initialization(normal);
    let laplace =
        Initialization { distribution: Distribution::Laplace, a: 2.0, b: 0.1, on: Transform::Lin };
    case.unknowns[1] = Unknown::new("b", 2.0).min(1.8).initialization(laplace);
    let problem = case.problem(1).unwrap();
    let n = 2000;
    let options = MultistartOptions { starts: n, seed: 5, guess: false, ..Default::default() };
    let list = starts(&problem, &options);
    assert_eq!(list.len(), n, "without the guess every start is drawn");
    let x: Vec<f64> = list.iter().map(|s| s[0].log10()).collect();
    assert!(list.iter().all(|s| (1e-3..=10.0).contains(&s[0]) && s[1] >= 1.8), "within bounds");
    let mean = x.iter().sum::<f64>() / n as f64;
    let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    // log10 a is normal(−1, 0.5) truncated at ±4 sd (the bounds −3 and 1): mean and sd are
    // the normal's to well below the sampling error.
    assert!((mean + 1.0).abs() < 4.0 * 0.5 / (n as f64).sqrt(), "mean {mean}");
    assert!((sd - 0.5).abs() < 4.0 * 0.5 / (2.0 * n as f64).sqrt(), "sd {sd}");
    // b: Laplace(2, 0.1) moved onto its bound 1.8 below it (a share e^{−2}/2 ≈ 6.8 %).
    let on_bound = list.iter().filter(|s| s[1] <= 1.8).count() as f64 / n as f64;
    assert!((on_bound - (-2f64).exp() / 2.0).abs() < 4.0 * (0.068f64 * 0.932 / n as f64).sqrt());
    // A Latin hypercube: stratum j's draw lies between the quantiles j/N and (j+1)/N.
    let lhs = MultistartOptions {
        starts: 11,
        seed: 2,
        sampling: Sampling::LatinHypercube,
        ..Default::default()
    };
    let mut b: Vec<f64> = starts(&problem, &lhs)[1..].iter().map(|s| s[1]).collect();
    b.sort_by(f64::total_cmp);
    for (j, v) in b.iter().enumerate() {
        let (lo, hi) = (laplace.quantile(j as f64 / 10.0), laplace.quantile((j + 1) as f64 / 10.0));
        assert!(*v >= lo.max(1.8) && *v <= hi.max(1.8), "stratum {j}: {v} not in [{lo}, {hi}]");
    }
}

#[test]
fn a_time_budget_fits_the_first_starts_and_counts_the_rest() {
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let method = Registry::standard().build("levenberg-marquardt", &Settings::default()).unwrap();
    let options = MultistartOptions { starts: 12, seed: 4, ..Default::default() };
    let all = multistart(&*method, &problem, &options).unwrap().starts;
    assert_eq!((all.count, all.not_started, all.waterfall.len()), (12, 0, 12));
    // A budget spent before the first start ends: the first start still runs (one per
    // thread may have begun), no start after the budget begins.
    let budget = Some(std::time::Duration::from_nanos(1));
    let cut = multistart(&*method, &problem, &MultistartOptions { budget, ..options }).unwrap();
    let s = &cut.starts;
    assert!(s.count >= 1 && s.count <= rayon::current_num_threads(), "{} fitted", s.count);
    assert_eq!(s.count + s.not_started, 12);
    // The fitted starts are the first ones, each ending where it ends without a budget.
    let mut fitted: Vec<usize> = s.waterfall.iter().map(|o| o.start).collect();
    fitted.sort_unstable();
    assert_eq!(fitted, (0..s.count).collect::<Vec<_>>());
    for o in &s.waterfall {
        let same = all.waterfall.iter().find(|a| a.start == o.start).unwrap();
        assert_eq!((o.objective, o.iterations), (same.objective, same.iterations));
    }
    assert!(s.to_string().contains("not begun within the time budget") || s.not_started == 0);
}

/// levenberg-marquardt, except that a fit from a start whose first value is above `above`
/// panics, as a defect would.
struct Panics<'a, S: sysid_ode::System> {
    inner: &'a (dyn sysid_core::Method<S> + Sync),
    above: f64,
}

impl<S: sysid_ode::System> sysid_core::Method<S> for Panics<'_, S> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn fit_from(
        &self,
        problem: &sysid_core::Problem<S>,
        start: &[f64],
    ) -> Result<sysid_core::Estimate, sysid_core::FitError> {
        if start[0] > self.above {
            panic!("a finite move");
        }
        self.inner.fit_from(problem, start)
    }
}

/// A start whose fit panics is reported as such (`panicked`, not converged, no objective, its
/// start as its values) and the multistart goes on: every other start ends where it ends
/// without the panicking ones.
#[test]
fn a_start_that_panics_is_reported_and_the_others_stand() {
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let method = Registry::standard().build("levenberg-marquardt", &Settings::default()).unwrap();
    let options = MultistartOptions { starts: 12, seed: 4, guess: false, ..Default::default() };
    let all = multistart(&*method, &problem, &options).unwrap();
    let mut first: Vec<f64> = all
        .starts
        .waterfall
        .iter()
        .map(|o| o.start_values.values().next().unwrap().as_f64().unwrap())
        .collect();
    first.sort_by(f64::total_cmp);
    let above = first[8];
    let panics = Panics { inner: &*method, above };
    let some = multistart(&panics, &problem, &options).expect("the multistart survives");
    let s = &some.starts;
    assert_eq!(s.count, 12);
    let mut n = 0;
    for o in &s.waterfall {
        let same = all.starts.waterfall.iter().find(|a| a.start == o.start).unwrap();
        assert_eq!(o.start_values, same.start_values, "start {}", o.start);
        if o.start_values.values().next().unwrap().as_f64().unwrap() > above {
            n += 1;
            assert_eq!(o.termination_code, "panicked", "start {}", o.start);
            assert!(!o.converged && o.objective.is_none() && o.iterations == 0);
            assert_eq!(o.estimates, o.start_values, "its values are its start");
        } else {
            assert_eq!((o.objective, o.iterations), (same.objective, same.iterations));
            assert_eq!(o.termination_code, same.termination_code);
        }
    }
    assert_eq!(n, 3, "the three starts above the 9th of 12 panic");
    assert!(some.best.converged(), "{}", some.best.termination);
    assert!(s.to_string().contains("3 fits panicked"), "{s}");
}

/// levenberg-marquardt whose whole fit (`fit_from`, which may retry from the same start) is
/// refused: only its single run (`fit_once_from`) may be called.
struct OnceOnly<'a, S: sysid_ode::System> {
    inner: &'a (dyn sysid_core::Method<S> + Sync),
}

impl<S: sysid_ode::System> sysid_core::Method<S> for OnceOnly<'_, S> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn fit_from(
        &self,
        _: &sysid_core::Problem<S>,
        _: &[f64],
    ) -> Result<sysid_core::Estimate, sysid_core::FitError> {
        panic!("a start of a multistart ran the whole fit, retry included");
    }

    fn fit_once_from(
        &self,
        problem: &sysid_core::Problem<S>,
        start: &[f64],
    ) -> Result<sysid_core::Estimate, sysid_core::FitError> {
        self.inner.fit_once_from(problem, start)
    }
}

/// Each start of a multistart is one run of its method (docs/methods.md, "The cautious
/// retry": among many starts, the next start is the retry): no start panics in `fit_from`,
/// and each ends where the method's single run from it ends, with no `retry`.
#[test]
fn each_start_is_one_run() {
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let method = Registry::standard().build("levenberg-marquardt", &Settings::default()).unwrap();
    let options = MultistartOptions { starts: 6, seed: 4, guess: false, ..Default::default() };
    let once = OnceOnly { inner: &*method };
    let run = multistart(&once, &problem, &options).expect("runs");
    let s = &run.starts;
    assert_eq!(s.count, 6);
    for o in &s.waterfall {
        assert_ne!(o.termination_code, "panicked", "start {}", o.start);
    }
    assert!(run.best.retry.is_none());
}

/// After every start has run, the start that ended at the iteration limit lowest, below every
/// converged start, is fitted on once from where it stopped, and only that one. Checked
/// against each start's fit run again on its own: the continued row's iterations are both
/// fits', its objective the lower of the two, and no other row is continued.
#[test]
fn the_lowest_start_at_the_limit_is_fitted_on_once() {
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let mut settings = Settings::default();
    settings.driver.max_iterations = 2;
    let method = Registry::standard().build("levenberg-marquardt", &settings).unwrap();
    let options = MultistartOptions { starts: 6, seed: 4, guess: false, ..Default::default() };
    let run = multistart(&*method, &problem, &options).expect("runs");
    assert_eq!(run.starts.redrawn, 0, "the starts are the drawn ones");
    let first: Vec<_> = starts(&problem, &options)
        .iter()
        .map(|s| method.fit_once_from(&problem, s).expect("fits"))
        .collect();
    let at_limit = |f: &sysid_core::Estimate| f.termination.code() == "max_iterations";
    let lowest = (0..first.len())
        .filter(|&j| at_limit(&first[j]))
        .min_by(|&a, &b| first[a].objective().total_cmp(&first[b].objective()))
        .expect("a start at the limit");
    assert!(
        first.iter().filter(|f| f.converged()).all(|f| first[lowest].objective() < f.objective()),
        "the case needs the lowest start at the limit below every converged one"
    );
    let on = method.fit_once_from(&problem, &first[lowest].values).expect("fits on");
    assert!(on.objective() <= first[lowest].objective(), "the case needs it to end no higher");
    let said = run.starts.to_string();
    assert!(said.contains(&format!("start {lowest} fitted on from the iteration limit")), "{said}");
    for row in &run.starts.waterfall {
        assert_eq!(row.continued, row.start == lowest, "start {}", row.start);
        let f = &first[row.start];
        if row.start == lowest {
            assert_eq!(row.iterations, f.iterations + on.iterations);
            assert_eq!(row.objective.unwrap().to_bits(), on.objective().to_bits());
        } else {
            assert_eq!(row.iterations, f.iterations, "start {}", row.start);
            assert_eq!(row.objective.unwrap().to_bits(), f.objective().to_bits());
        }
    }
    // Reported as the best, the continued start is both fits as one: the iterations, the
    // history on one count (the continuation's first row in place of the first fit's last)
    // and the best iterate counted on from the first fit's.
    assert_eq!(run.starts.best_start, lowest, "the case needs the continued start the best");
    let (f, best) = (&first[lowest], &run.best);
    assert_eq!(best.iterations, f.iterations + on.iterations);
    assert_eq!(best.best_iteration, f.iterations + on.best_iteration);
    assert_eq!(best.history.len(), f.history.len() + on.history.len() - 1);
    assert!(best.history.iter().enumerate().all(|(i, row)| row.iteration == i));
    assert_eq!(
        best.history.last(),
        on.history
            .last()
            .map(|row| sysid_core::Iteration { iteration: best.iterations, ..row.clone() })
            .as_ref()
    );
    assert_eq!(best.counts.integrations, f.counts.integrations + on.counts.integrations);
}

/// A run asked to stop (`sysid_core::observer::stop_when`, Python's Ctrl-C) ends its running
/// fits at their next iteration, `interrupted`, each with its best point so far, and begins
/// no other start; a fit asked before it begins stops at its start, which it returns as it
/// stands. A flag never set changes nothing.
#[test]
fn a_stopped_run_ends_its_fits_and_begins_no_other_start() {
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;
    use sysid_core::observer::stop_when;
    let case = sysid_systems::lotka_volterra::lotka_volterra();
    let problem = case.problem(1).unwrap();
    let method = Registry::standard().build("levenberg-marquardt", &Settings::default()).unwrap();
    let unset = Arc::new(AtomicBool::new(false));
    let alone = method.fit(&problem).unwrap();
    let beside = stop_when(unset, || method.fit(&problem)).unwrap();
    assert_eq!((beside.values, beside.iterations), (alone.values.clone(), alone.iterations));
    let set = Arc::new(AtomicBool::new(true));
    let stopped = stop_when(set.clone(), || method.fit(&problem)).unwrap();
    assert_eq!(stopped.termination.code(), "interrupted");
    assert_eq!(stopped.iterations, 0);
    for (got, want) in stopped.values.iter().zip(problem.guesses()) {
        assert_close(*got, want, 1e-15);
    }
    assert!(!stopped.converged());
    let options = MultistartOptions { starts: 12, seed: 4, ..Default::default() };
    let run = stop_when(set, || multistart(&*method, &problem, &options)).unwrap();
    let s = &run.starts;
    assert!(s.count >= 1 && s.count <= rayon::current_num_threads(), "{} fitted", s.count);
    assert_eq!(s.count + s.not_started, 12);
    assert!(s.waterfall.iter().all(|o| o.termination_code == "interrupted"));
    assert!(s.to_string().contains("not begun: the run was stopped"), "{s}");
}
