//! The result of a fit: values, uncertainty, and how the method got there.

use std::time::Duration;

use nalgebra::DMatrix;
use serde::ser::{SerializeMap, SerializeStruct};
use serde::{Serialize, Serializer};
use sysid_ode::Counts;

use crate::certificate::{Bound, Certificate};
use crate::confidence::t95;
use crate::format::shortest;
use crate::step::Diagnostics;
use crate::termination::Termination;

/// One row of the iteration history, for the iterate z_i.
#[derive(Clone, Debug, PartialEq)]
pub struct Iteration {
    /// i = number of updates before this iterate.
    pub iteration: usize,
    /// ε at the iterate.
    pub cost: f64,
    /// |U| (Euclidean norm of half the gradient of ε).
    pub gradient_norm: f64,
    /// Norm of the update that led here (None for the start).
    pub step_norm: Option<f64>,
    /// Condition number of the matrix the step from this iterate solved with.
    pub condition: Option<f64>,
    /// The certificate's first-order optimality measure at the iterate, where the method
    /// computed the model's sensitivities there.
    pub optimality: Option<f64>,
    /// The unknowns at the iterate (values).
    pub values: Vec<f64>,
    /// What the method measured at the iterate besides ε, by name
    /// ([`Iterate::diagnostics`](crate::method::Iterate::diagnostics)).
    pub diagnostics: Diagnostics,
}

impl Iteration {
    /// The method's diagnostic `name` at this iterate, if it attached one.
    pub fn diagnostic(&self, name: &str) -> Option<f64> {
        self.diagnostics.get(name)
    }
}

/// The estimate of the unknowns with its uncertainty and the record of the run.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The method that produced it.
    pub method: String,
    /// Names of the unknowns.
    pub names: Vec<String>,
    /// Estimated values.
    pub values: Vec<f64>,
    /// Standard errors, sqrt(diag Cov) (None when the fit did not converge, when there is no
    /// residual variance — as many data as unknowns, or a record given as a function — or
    /// when A is singular).
    pub std_errors: Option<Vec<f64>>,
    /// 95 % intervals with Student's t for `dof` degrees of freedom (on a log scale formed
    /// for ln(value) and mapped back); NaN for an unknown held on a bound.
    pub intervals: Option<Vec<[f64; 2]>>,
    /// Covariance of the values: s² A⁻¹ with s² = ε/(N − k).
    pub covariance: Option<DMatrix<f64>>,
    /// ε at the estimate, from the integration the certificate was computed on (the same for
    /// every method), so that methods at the same point report the same cost.
    pub cost: f64,
    /// Degrees of freedom N − k_free: measured values less the unknowns not held on a bound
    /// (None for a record given as a function).
    pub dof: Option<usize>,
    /// Number of updates of the unknowns the method made.
    pub iterations: usize,
    /// Which iterate is reported: the last one when a stopping rule ended the run, the best
    /// one (lowest cost) when a failure or a budget did.
    pub best_iteration: usize,
    /// Why the method stopped.
    pub termination: Termination,
    /// The first-order verdict on the reported point: it decides [`converged`](Self::converged).
    pub certificate: Certificate,
    /// One row per iterate, the start first.
    pub history: Vec<Iteration>,
    /// Wall-clock time of the fit.
    pub elapsed: Duration,
    /// Work done by all integrations of the fit.
    pub counts: Counts,
    /// The negative log-likelihood at the estimate, PEtab's constants included (None for a
    /// continuous record). With relative weights w (no noise model) σ = 1/√w: ε/2 +
    /// Σ ½ ln(2π/w).
    pub nll: Option<f64>,
    /// The negative log-prior at the estimate, apart from [`nll`](Self::nll) (None without
    /// priors): what a fit with priors minimises is nll + prior.
    pub prior: Option<f64>,
    /// Each experiment's name, measured values and negative log-likelihood.
    pub experiments: Vec<ExperimentFit>,
    /// The noise scales set in closed form (σ = s·f), estimated with the rest.
    pub scales: Vec<ScaleEstimate>,
    /// Whether the problem has a noise model (tables then show the likelihood).
    pub noise_model: bool,
    /// Where the fit was run twice from its start ([`Estimate::retried`]): how the first run
    /// ended. `None` for a fit of one run.
    pub retry: Option<Box<FirstRun>>,
}

/// How the first run of a fit run twice from its start ended ([`Estimate::retried`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FirstRun {
    /// Why it stopped.
    pub termination: Termination,
    /// Its [`objective`](Estimate::objective) at the point it reported.
    pub objective: f64,
    /// Its updates of the unknowns.
    pub iterations: usize,
    /// Whether the estimate reported is this first run's (the second did no better).
    pub reported: bool,
}

/// One experiment's share of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ExperimentFit {
    /// Its name.
    pub name: String,
    /// Its measured values.
    pub points: usize,
    /// Its negative log-likelihood at the estimate.
    pub nll: Option<f64>,
}

impl ExperimentFit {
    /// Each experiment of `problem` with its negative log-likelihood from `nlls` (one per
    /// experiment, in order; none where the point has no likelihood).
    pub(crate) fn all<S: sysid_ode::System>(
        problem: &crate::Problem<S>,
        nlls: Option<&[f64]>,
    ) -> Vec<ExperimentFit> {
        problem
            .experiments()
            .iter()
            .enumerate()
            .map(|(i, e)| ExperimentFit {
                name: e.name().to_string(),
                points: e.data().n_observations().unwrap_or(0),
                nll: nlls.map(|list| list[i]),
            })
            .collect()
    }
}

/// A noise scale's estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleEstimate {
    /// The unknown's name.
    pub name: String,
    /// Its value.
    pub value: f64,
    /// Its standard error s/√(2n) from the Fisher information (n its samples), when the fit
    /// converged.
    pub std_error: Option<f64>,
    /// Its 95 % interval (Student's t on the fit's degrees of freedom).
    pub interval: Option<[f64; 2]>,
    /// The bound it is held on, when the closed form falls outside its bounds.
    pub bound: Option<Bound>,
}

impl Estimate {
    /// The integration error of [`nll`](Self::nll): half the certificate's `cost_error` (the
    /// NLL is ε/2 plus terms that do not depend on the integration). None where `nll` is.
    pub fn nll_error(&self) -> Option<f64> {
        self.nll.map(|_| 0.5 * self.certificate.cost_error)
    }

    /// Whether the fit converged: the reported point passes the certificate (a first-order
    /// optimality test that does not trust the method's stopping rule).
    pub fn converged(&self) -> bool {
        self.certificate.holds()
    }

    /// The estimate of a fit from `start` that panicked with `message` after `elapsed`: the
    /// start, not converged, with no cost and no history ([`Termination::Panicked`]). For a
    /// caller that runs many fits (multistart) and keeps the others when one of them hits a
    /// defect.
    pub fn panicked<S: sysid_ode::System>(
        problem: &crate::Problem<S>,
        method: &str,
        start: &[f64],
        message: String,
        elapsed: Duration,
    ) -> Estimate {
        let gtol = crate::DriverOptions::default().gtol_for(problem.integrator().rtol);
        Estimate {
            method: method.to_string(),
            names: problem.names(),
            values: start.to_vec(),
            std_errors: None,
            intervals: None,
            covariance: None,
            cost: f64::NAN,
            dof: None,
            iterations: 0,
            best_iteration: 0,
            termination: Termination::Panicked(message),
            certificate: Certificate::failed(start.len(), gtol),
            history: Vec::new(),
            elapsed,
            counts: Counts::default(),
            nll: None,
            prior: None,
            experiments: ExperimentFit::all(problem, None),
            scales: Vec::new(),
            noise_model: problem.has_noise_model(),
            retry: None,
        }
    }

    /// What the fit minimises at the reported point, in units of ε/2: the negative
    /// log-likelihood plus the priors' term where the fit has a likelihood (it differs from
    /// ε/2 by a constant when σ is known, and is the objective when noise scales are
    /// estimated, where ε at every round's end is about the number of data), else ε/2. NaN
    /// where the point could not be evaluated.
    pub fn objective(&self) -> f64 {
        self.nll.map_or(self.cost / 2.0, |nll| nll + self.prior.unwrap_or(0.0))
    }

    /// Makes this fit and `next`, a fit begun where this one ended, one fit: `next`'s end,
    /// with the iterations, evaluations and time of both, and both histories on one count of
    /// iterations. `next`'s first row (this fit's end, evaluated again: at new noise scales
    /// in a new round of the driver, or at the problem's in a multistart's continuation)
    /// replaces this fit's last.
    pub fn continue_with(&mut self, mut next: Estimate) {
        let before = self.iterations;
        let mut history = std::mem::take(&mut self.history);
        if !next.history.is_empty() {
            history.pop();
        }
        history.extend(next.history.into_iter().map(|mut row| {
            row.iteration += before;
            row
        }));
        next.history = history;
        next.iterations += before;
        next.best_iteration += before;
        // The iteration its termination names, on the same count.
        match &mut next.termination {
            Termination::Stalled { iteration, .. } | Termination::Failed { iteration, .. } => {
                *iteration += before;
            }
            _ => {}
        }
        next.counts += self.counts;
        next.elapsed += self.elapsed;
        *self = next;
    }

    /// One fit of two runs from the same start: the second run's estimate where it is the
    /// better (certified where the first is not, else the lower [`objective`](Self::objective);
    /// a point that could not be evaluated is never the better), otherwise the first's, with
    /// the first run's ending in [`retry`](Self::retry) and the work and time of both runs.
    pub fn retried(first: Estimate, second: Estimate) -> Estimate {
        let rank = |e: &Estimate| {
            let objective = e.objective();
            (e.converged(), if objective.is_nan() { f64::NEG_INFINITY } else { -objective })
        };
        let second_better = rank(&second) > rank(&first);
        let record = FirstRun {
            termination: first.termination.clone(),
            objective: first.objective(),
            iterations: first.iterations,
            reported: !second_better,
        };
        let (mut kept, other) = if second_better { (second, first) } else { (first, second) };
        kept.counts += other.counts;
        kept.elapsed += other.elapsed;
        kept.retry = Some(Box::new(record));
        kept
    }

    /// Whether the start could not be evaluated (a bad start or bad data, not a result).
    pub fn start_failed(&self) -> bool {
        matches!(self.termination, Termination::StartFailed(_))
    }

    /// The unknowns held on a bound, with which (noise scales included).
    pub fn active_bounds(&self) -> Vec<(&str, Bound)> {
        self.names
            .iter()
            .zip(&self.certificate.active)
            .filter_map(|(n, b)| b.map(|b| (n.as_str(), b)))
            .chain(self.scales.iter().filter_map(|s| s.bound.map(|b| (s.name.as_str(), b))))
            .collect()
    }

    /// The unknowns the model does not respond to at the reported point, off their bounds:
    /// the data do not determine them ([`Certificate::undetermined`]).
    pub fn undetermined(&self) -> Vec<&str> {
        self.certificate.undetermined().into_iter().map(|i| self.names[i].as_str()).collect()
    }

    /// Every estimated unknown's name: the free ones, then the noise scales.
    pub fn all_names(&self) -> Vec<String> {
        self.names.iter().cloned().chain(self.scales.iter().map(|s| s.name.clone())).collect()
    }

    /// The number of measured values N (None for a record given as a function).
    fn n_observations(&self) -> Option<usize> {
        self.experiments.iter().map(|e| Some(e.points)).sum::<Option<usize>>().filter(|&n| n > 0)
    }

    /// Akaike's information criterion 2k + 2·NLL, k every estimated unknown (noise scales
    /// included, those held on a bound too).
    pub fn aic(&self) -> Option<f64> {
        let k = (self.names.len() + self.scales.len()) as f64;
        self.nll.map(|nll| 2.0 * k + 2.0 * nll)
    }

    /// The Bayesian information criterion k ln N + 2·NLL.
    pub fn bic(&self) -> Option<f64> {
        let k = (self.names.len() + self.scales.len()) as f64;
        let n = self.n_observations()? as f64;
        self.nll.map(|nll| k * n.ln() + 2.0 * nll)
    }
    /// Same as [`converged`](Self::converged).
    pub fn succeeded(&self) -> bool {
        self.converged()
    }
    /// What a 95 % band of a prediction needs: the covariance of the values and Student's t
    /// quantile for the fit's degrees of freedom (N − k_free: an unknown held on a bound is
    /// not estimated). `None` without a covariance.
    pub fn band(&self) -> Option<(&DMatrix<f64>, f64)> {
        self.covariance.as_ref().zip(self.dof.and_then(t95))
    }

    /// The estimate of one unknown by name.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.names.iter().position(|n| n == name).map(|i| self.values[i])
    }

    /// The fit as the object of the `sysid fit --format json` contract (docs/json.md),
    /// keys in the contract's order: serialise it with serde_json.
    pub fn record<'a>(&'a self, system: &'a str) -> FitRecord<'a> {
        FitRecord { system, estimate: self }
    }
}

/// The `sysid fit --format json` object: the contract keys in the contract's order, then the
/// extensions (termination and its code, the certificate, degrees of freedom and intervals,
/// gradient norm, condition and optimality per iteration, work counts).
pub struct FitRecord<'a> {
    /// The system's name.
    pub system: &'a str,
    /// The fit.
    pub estimate: &'a Estimate,
}

/// Names paired with values, serialised as an object in their order.
struct Named<'a, T>(&'a [String], &'a [T]);
impl<T: Serialize> Serialize for Named<'_, T> {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in self.0.iter().zip(self.1) {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

/// A float that is written as null when it is not finite (JSON has no NaN).
struct Num(f64);
impl Serialize for Num {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        if self.0.is_finite() { s.serialize_f64(self.0) } else { s.serialize_none() }
    }
}

impl Serialize for Iteration {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        let mut st = s.serialize_struct("Iteration", 7)?;
        st.serialize_field("iteration", &self.iteration)?;
        st.serialize_field("cost", &Num(self.cost))?;
        st.serialize_field("step_norm", &self.step_norm.map(Num))?;
        st.serialize_field("gradient_norm", &Num(self.gradient_norm))?;
        st.serialize_field("condition", &self.condition.map(Num))?;
        st.serialize_field("optimality", &self.optimality.map(Num))?;
        for (name, value) in self.diagnostics.iter() {
            st.serialize_field(name, &Num(value))?;
        }
        st.end()
    }
}

impl Serialize for FitRecord<'_> {
    fn serialize<Z: Serializer>(&self, s: Z) -> Result<Z::Ok, Z::Error> {
        let e = self.estimate;
        let mut st = s.serialize_struct("Fit", 28)?;
        st.serialize_field("system", self.system)?;
        st.serialize_field("method", &e.method)?;
        st.serialize_field("converged", &e.converged())?;
        st.serialize_field("iterations", &e.iterations)?;
        st.serialize_field("cost", &Num(e.cost))?;
        let names = e.all_names();
        let values: Vec<Num> =
            e.values.iter().chain(e.scales.iter().map(|s| &s.value)).map(|&v| Num(v)).collect();
        st.serialize_field("estimates", &Named(&names, &values))?;
        let scale_errors = e.scales.iter().map(|s| Num(s.std_error.unwrap_or(f64::NAN)));
        // The scales' own, as the table shows them, also where the free unknowns have none
        // (all of them fixed: the scale's error was null here and printed in the table).
        let free = 0..e.values.len();
        let errors: Vec<Num> = free
            .clone()
            .map(|i| Num(e.std_errors.as_ref().map_or(f64::NAN, |se| se[i])))
            .chain(scale_errors)
            .collect();
        st.serialize_field("std_errors", &Named(&names, &errors))?;
        st.serialize_field("history", &e.history)?;
        st.serialize_field("elapsed_ms", &(e.elapsed.as_secs_f64() * 1e3))?;
        st.serialize_field("termination", &e.termination.to_string())?;
        st.serialize_field("termination_code", &e.termination.code())?;
        st.serialize_field("optimality", &Num(e.certificate.optimality))?;
        st.serialize_field("optimality_error", &Num(e.certificate.error))?;
        st.serialize_field("cost_error", &Num(e.certificate.cost_error))?;
        if let Some(moved) = e.certificate.scales {
            st.serialize_field("scale_optimality", &Num(moved))?;
        }
        st.serialize_field("gtol", &e.certificate.gtol)?;
        st.serialize_field("exact_fit", &e.certificate.exact_fit)?;
        st.serialize_field("corner", &e.certificate.corner())?;
        let active = e.active_bounds();
        let (held, bounds): (Vec<String>, Vec<Bound>) =
            active.iter().map(|(n, b)| (n.to_string(), *b)).unzip();
        st.serialize_field("active_bounds", &Named(&held, &bounds))?;
        st.serialize_field("undetermined", &e.undetermined())?;
        st.serialize_field("dof", &e.dof)?;
        let finite =
            |&[a, b]: &[f64; 2]| (a.is_finite() && b.is_finite()).then_some([Num(a), Num(b)]);
        let scale_intervals = e.scales.iter().map(|s| s.interval.as_ref().and_then(finite));
        let intervals: Vec<Option<[Num; 2]>> = free
            .map(|i| e.intervals.as_ref().and_then(|list| finite(&list[i])))
            .chain(scale_intervals)
            .collect();
        st.serialize_field("intervals", &Named(&names, &intervals))?;
        st.serialize_field("best_iteration", &e.best_iteration)?;
        if let Some(at) = e.termination.failure().and_then(|f| f.at()) {
            let at: Vec<Num> = at.iter().map(|&v| Num(v)).collect();
            st.serialize_field("failed_at", &Named(&e.names, &at))?;
        }
        if let Some(space) = &e.certificate.null_space {
            st.serialize_field(
                "unidentifiable",
                &serde_json::json!({
                    "unknowns": space.unknowns,
                    "condition": space.condition.is_finite().then_some(space.condition),
                    "direction": space.direction,
                }),
            )?;
        }
        st.serialize_field("counts", &e.counts)?;
        st.serialize_field("nll", &e.nll.map(Num))?;
        st.serialize_field("nll_error", &e.nll_error().map(Num))?;
        if let Some(prior) = e.prior {
            st.serialize_field("prior", &Num(prior))?;
        }
        let experiments: Vec<serde_json::Value> = e
            .experiments
            .iter()
            .map(|x| {
                serde_json::json!({
                    "name": x.name,
                    "points": x.points,
                    "nll": x.nll.filter(|v| v.is_finite()),
                })
            })
            .collect();
        st.serialize_field("experiments", &experiments)?;
        st.serialize_field("aic", &e.aic().map(Num))?;
        st.serialize_field("bic", &e.bic().map(Num))?;
        if let Some(first) = &e.retry {
            st.serialize_field(
                "retry",
                &serde_json::json!({
                    "first_termination_code": first.termination.code(),
                    "first_objective": first.objective.is_finite().then_some(first.objective),
                    "first_iterations": first.iterations,
                    "reported": if first.reported { "first" } else { "second" },
                }),
            )?;
        }
        st.end()
    }
}

impl Estimate {
    /// The certificate's verdict in words: "yes (first-order optimality 3.1e-9 ≤ gtol 1e-6)".
    pub fn verdict(&self) -> String {
        let c = &self.certificate;
        if !c.optimality.is_finite() {
            "no (the reported point could not be evaluated)".into()
        } else if c.unresolved {
            format!(
                "no (the integration does not resolve the model there: ε moves by {:.2e} in the integration that checks it)",
                c.cost_error
            )
        } else if c.plateau() {
            let names = self.undetermined();
            if names.is_empty() {
                "no (a plateau: the model responds to no unknown there)".into()
            } else {
                format!(
                    "no (a plateau: the model responds to no unknown there; not determined: {})",
                    names.join(", ")
                )
            }
        } else if c.has_undetermined() {
            let names = self.undetermined();
            format!(
                "no ({} {} not determined: the model does not respond to {} there; a flat direction, not a minimum)",
                names.join(", "),
                if names.len() == 1 { "is" } else { "are" },
                if names.len() == 1 { "it" } else { "them" }
            )
        } else if let Some(moved) = c.scales.filter(|m| m.is_nan() || *m > c.gtol)
            && (c.exact_fit || c.optimality + c.error <= c.gtol)
        {
            format!(
                "no (the noise scales' closed form would still move them by {moved:.2e} relative > gtol {:.0e})",
                c.gtol
            )
        } else if c.unconfirmed() {
            format!(
                "no (first-order optimality {:.2e} ≤ gtol {:.0e} at the working integration, unconfirmed: the integration that measures its error fails)",
                c.optimality, c.gtol
            )
        } else if c.exact_fit {
            "yes (the model passes through the data: ε = 0 to rounding)".into()
        } else if c.holds() && c.corner() {
            format!(
                "yes (first-order optimality {:.2e}{} ≤ gtol {:.0e}{}), at a corner of the box: every unknown on a bound",
                c.optimality,
                plus_error(c),
                c.gtol,
                unmeasured(c)
            )
        } else if c.holds() {
            format!(
                "yes (first-order optimality {:.2e}{} ≤ gtol {:.0e}{})",
                c.optimality,
                plus_error(c),
                c.gtol,
                unmeasured(c)
            )
        } else if c.error.is_infinite() {
            format!(
                "no (first-order optimality {:.2e} > gtol {:.0e}; its integration error unmeasured)",
                c.optimality, c.gtol
            )
        } else {
            format!(
                "no (first-order optimality {:.2e}{} > gtol {:.0e}{})",
                c.optimality,
                plus_error(c),
                c.gtol,
                unmeasured(c)
            )
        }
    }

    /// Where the run failed, "a = 1.2, b = −3", if it failed at a point.
    pub fn failed_at(&self) -> Option<String> {
        let at = self.termination.failure()?.at()?;
        Some(
            self.names
                .iter()
                .zip(at)
                .map(|(n, v)| format!("{n} = {}", shortest(*v)))
                .collect::<Vec<_>>()
                .join(", "),
        )
    }
}

/// " ± e" after an optimality whose integration error `e` was measured; nothing where it
/// was not ([`Certificate::error_measured`]): a 0 there is not a measured 0.
fn plus_error(c: &Certificate) -> String {
    match c.error_measured {
        true => format!(" ± {:.0e}", c.error),
        false => String::new(),
    }
}

/// Where the optimality's integration error was not measured
/// ([`Certificate::error_measured`]: at the finest rtol, the other scheme it is measured
/// against could not integrate the model), the words that say so.
fn unmeasured(c: &Certificate) -> String {
    match c.error_measured {
        true => String::new(),
        false => format!(
            "; its integration error unmeasured: at the finest rtol, {:.0e}, another scheme could not integrate the model to compare",
            crate::evaluations::FINEST_RTOL
        ),
    }
}
