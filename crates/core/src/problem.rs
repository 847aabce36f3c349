//! The identification problem: a model, its experiments, what is known, what is unknown,
//! and the data. It knows nothing of methods; it evaluates the least-squares quantities every
//! method needs.

use std::sync::Arc;

use sysid_ode::{Integrator, Observable, Ode, OdeSystem, System};

use crate::data::Data;
use crate::error::ProblemError;
use crate::experiment::{Experiment, Planned, Resolved, Setting, slots};
use crate::noise::Noise;
use crate::plan::{Plan, PlannedNoise, plan};
use crate::unknowns::{Unknown, Unknowns};

/// Default relative accuracy of the quadratures of a continuous record.
pub const QUADRATURE_RTOL: f64 = 1e-10;

/// The name of the one experiment of a problem built without experiments (the `[data]` of a
/// model file, a catalogue system's data).
pub const SINGLE_EXPERIMENT: &str = "data";

/// A model, one or more experiments of it (each with its data, inputs, t0 and settings of
/// the initial values and parameters), the unknowns with their starting guesses, and how to
/// integrate.
///
/// Build one with [`Problem::builder`]: either as one experiment (every state and parameter
/// known or unknown by name), or from [`Experiment`]s and the unknowns they use.
///
/// The unknowns the methods move (their coordinates z) are the *free* ones: not fixed with
/// [`with_fixed`](Self::with_fixed), and not noise scales, which the driver sets in closed
/// form (see [`drive`](crate::method::drive)).
///
/// Two experiments of x' = −k x sharing the rate k, one from a known initial value and one
/// from an unknown one:
///
/// ```
/// use sysid_core::{Data, Experiment, Problem, Setting};
/// use sysid_ode::testing::Decay;
///
/// let t = [1.0, 2.0];
/// let run = |name: &str, x0: Setting, b: [f64; 2]| Experiment {
///     name: name.into(),
///     also: Vec::new(),
///     system: Decay::new(),
///     t0: 0.0,
///     initial: vec![x0],
///     parameters: vec![Setting::Unknown("k".into())],
///     data: Data::discrete().series("x", &t, &b),
/// };
/// let (e1, e2) = ((-0.5f64).exp(), (-1.0f64).exp()); // k = 0.5
/// let problem = Problem::builder(Decay::new())
///     .unknown("k", 0.3)
///     .unknown("x0", 1.0)
///     .experiment(run("known start", Setting::Value(1.0), [e1, e2]))
///     .experiment(run("unknown start", Setting::Unknown("x0".into()), [3.0 * e1, 3.0 * e2]))
///     .build()?;
/// assert_eq!(problem.names(), ["k", "x0"]);
/// assert_eq!((problem.experiments().len(), problem.n_observations()), (2, Some(4)));
/// // At the truth (k = 0.5, x0 = 3) both experiments fit exactly.
/// assert!(problem.linearize(&[0.5, 3.0])?.cost < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct Problem<S> {
    /// Every unknown, in the order given.
    pub(crate) declared: Vec<Unknown>,
    /// The declared index of each free unknown, in the methods' order.
    pub(crate) free: Vec<usize>,
    /// The free unknowns.
    pub(crate) unknowns: Unknowns,
    /// The value of every declared unknown that is not free (fixed ones, and noise scales at
    /// their current value); the free ones' entries are their guesses.
    pub(crate) held: Vec<f64>,
    /// The declared indices of the noise scales set in closed form.
    pub(crate) scales: Vec<usize>,
    pub(crate) experiments: Vec<Planned<S>>,
    pub(crate) integrator: Integrator,
    pub(crate) quadrature_rtol: f64,
}

impl<S> Clone for Problem<S> {
    /// A copy that shares the systems.
    fn clone(&self) -> Self {
        Self {
            declared: self.declared.clone(),
            free: self.free.clone(),
            unknowns: self.unknowns.clone(),
            held: self.held.clone(),
            scales: self.scales.clone(),
            experiments: self.experiments.clone(),
            integrator: self.integrator,
            quadrature_rtol: self.quadrature_rtol,
        }
    }
}

impl<S> Problem<S> {
    /// The same problem with each experiment's system mapped by `f`: to an enum of several
    /// system types, say, so that code working on any of them is compiled once.
    pub fn map_system<T>(self, f: impl Fn(Arc<S>) -> T) -> Problem<T> {
        Problem {
            declared: self.declared,
            free: self.free,
            unknowns: self.unknowns,
            held: self.held,
            scales: self.scales,
            experiments: self.experiments.into_iter().map(|e| e.map_system(&f)).collect(),
            integrator: self.integrator,
            quadrature_rtol: self.quadrature_rtol,
        }
    }
}

impl<O: Ode> Problem<OdeSystem<O>> {
    /// Starts building a problem for the equations `ode` (the simple case: named states and
    /// parameters, no inputs or outputs); the same as
    /// [`builder`](Problem::builder)`(OdeSystem::new(ode))`.
    pub fn ode(ode: O) -> ProblemBuilder<OdeSystem<O>> {
        Problem::builder(OdeSystem::new(ode))
    }
}

impl<S: System> Problem<S> {
    /// Starts building a problem for `system`.
    pub fn builder(system: S) -> ProblemBuilder<S> {
        ProblemBuilder {
            system,
            t0: 0.0,
            values: Vec::new(),
            unknowns: Vec::new(),
            data: None,
            experiments: Vec::new(),
            integrator: Integrator::default(),
            quadrature_rtol: QUADRATURE_RTOL,
        }
    }

    /// The model (the first experiment's, with its inputs): the signature every experiment
    /// shares.
    pub fn system(&self) -> &S {
        &self.experiments[0].system
    }
    /// The experiments.
    pub fn experiments(&self) -> &[Planned<S>] {
        &self.experiments
    }
    /// Time of the initial values of the first experiment.
    pub fn t0(&self) -> f64 {
        self.experiments[0].t0
    }
    /// The free unknowns: what the methods move.
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }
    /// Names of the free unknowns.
    pub fn names(&self) -> Vec<String> {
        self.unknowns.names()
    }
    /// The starting guesses of the free unknowns (values).
    pub fn guesses(&self) -> Vec<f64> {
        self.unknowns.guesses()
    }
    /// Every unknown as given, free or not.
    pub fn declared(&self) -> &[Unknown] {
        &self.declared
    }
    /// The noise scales set in closed form: declared indices.
    pub fn scales(&self) -> &[usize] {
        &self.scales
    }
    /// The parameters, as PEtab and pyPESTO count them: the free unknowns, then the noise
    /// scales (which the fits set in closed form). The order of
    /// [`objective_gradient`](Self::objective_gradient).
    pub fn parameters(&self) -> Vec<&Unknown> {
        let scales = self.scales.iter().map(|&j| &self.declared[j]);
        self.unknowns.list().iter().chain(scales).collect()
    }
    /// The measurements of the first experiment.
    pub fn data(&self) -> &Data {
        &self.experiments[0].data
    }
    /// Whether any experiment's data are a continuous record.
    pub fn is_continuous(&self) -> bool {
        self.experiments.iter().any(|e| e.is_continuous())
    }
    /// The integrator.
    pub fn integrator(&self) -> &Integrator {
        &self.integrator
    }
    /// The time span the first experiment is integrated over: its data together with t0.
    pub fn span(&self) -> (f64, f64) {
        self.experiments[0].span()
    }

    /// A step tolerance as the methods apply it: not below the integrator's relative
    /// tolerance. The model is integrated to about rtol, so changes of the unknowns below
    /// it are indistinguishable from integration error; iterating on them costs
    /// integrations and changes nothing the integration can resolve.
    pub fn resolvable_step(&self, step_tolerance: f64) -> f64 {
        step_tolerance.max(self.integrator.rtol)
    }

    /// Number of measured values over all experiments (None when a record is a function).
    pub fn n_observations(&self) -> Option<usize> {
        self.experiments.iter().map(|e| e.data.n_observations()).sum()
    }

    /// Degrees of freedom N − k of the residual variance (None for a record given as a
    /// function).
    pub fn dof(&self) -> Option<usize> {
        self.n_observations().map(|n| n.saturating_sub(self.unknowns.len()))
    }

    /// Whether the likelihood has a noise model (some series gives σ): then standard errors
    /// come from the inverse Fisher information, not scaled by the residual variance.
    pub fn has_noise_model(&self) -> bool {
        self.experiments.iter().any(|e| e.data.has_noise_model())
    }

    /// The accuracy of an integrated cost ε = ‖r‖² (`norm` = ‖r‖) at this problem's
    /// tolerance: rtol·(|ε| + 2‖r‖·‖W^½ b‖). Below it the difference of two integrated costs
    /// is noise ([`actual_decrease`](crate::method::actual_decrease)). An integration errs
    /// by rtol relative to the model's values, not to the residuals, so ε is wrong by up to
    /// about 2‖r‖·rtol‖W^½ h‖ ≈ 2 rtol ‖r‖ ‖W^½ b‖ near the data ([`data_norm`](Self::data_norm)),
    /// and by rtol·ε far from them: a bound, which DOPRI5 mostly keeps well within. rtol·ε
    /// alone is far below the error where the model fits the data closely: x′ = −kx through
    /// four points given to five digits, at its minimum (ε = 5.6e-9), has ε wrong by 7.2e-14
    /// at rtol 1e-8 (against rtol 1e-12; the bound 2.7e-12, rtol·ε 5.6e-17), and nl2sol's
    /// last trials there, whose predicted decreases were near 1e-17, were judged by that
    /// noise, rejected, and the run stopped on the step rule short of certified. Where a
    /// series' σ is a function of the model ([`data_norm`](Self::data_norm) is then of the
    /// data unweighted, not in the residuals' units), or the data's norm overflows, it is
    /// rtol·|ε|.
    pub fn cost_resolution(&self, cost: f64, norm: f64) -> f64 {
        let function_noise = self
            .experiments
            .iter()
            .flat_map(|e| &e.sampled().series)
            .any(|s| matches!(s.noise, PlannedNoise::Function(_)));
        let data = self.data_norm();
        let near = match function_noise || !data.is_finite() {
            true => 0.0,
            false => 2.0 * norm * data,
        };
        self.integrator().rtol * (cost.abs() + near)
    }

    /// ‖W^½ b‖: the weighted data's norm (the record's for continuous data, by the
    /// quadrature of its residual form), the scale an exact fit is measured against.
    pub fn data_norm(&self) -> f64 {
        let entries: Vec<f64> = self
            .experiments
            .iter()
            .flat_map(|e| &e.sampled().series)
            .flat_map(|s| s.samples.iter().map(move |m| (s, m)))
            .map(|(s, m)| match s.noise {
                PlannedNoise::Function(_) => m.value,
                _ => m.sqrt_weight * m.value,
            })
            .collect();
        // Scaled by the largest entry, so that weights near the largest float do not
        // overflow the sum of squares (and pass any fit as exact).
        let top = entries.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if top == 0.0 || !top.is_finite() {
            return top;
        }
        top * entries.iter().map(|v| (v / top).powi(2)).sum::<f64>().sqrt()
    }

    /// Row `row` of the residual vector in words: "`B` at t = 3 (sample 14 of `B`)", with
    /// the experiment's name when there are several.
    pub fn describe_row(&self, row: usize) -> String {
        let signature = self.system().signature();
        let mut at = row;
        for e in &self.experiments {
            let sampled = e.sampled();
            for s in &sampled.series {
                if at < s.samples.len() {
                    let name = match s.observable {
                        Observable::State(i) => &signature.states()[i],
                        Observable::Output(i) => &signature.outputs()[i],
                    };
                    let t = sampled.times[s.samples[at].index];
                    let of = if self.experiments.len() > 1 {
                        format!(" in experiment `{}`", e.name)
                    } else {
                        String::new()
                    };
                    return format!("`{name}` at t = {t}{of} (sample {} of `{name}`)", at + 1);
                }
                at -= s.samples.len();
            }
            at = at.saturating_sub(e.noise_rows());
        }
        format!("row {row}")
    }

    /// The declared index of the unknown (free, or a noise scale) that entry `i` of `given`
    /// names, refusing a name given twice (`done`: "fixed", "started") or that is no unknown.
    fn movable(
        &self,
        given: &[(String, f64)],
        i: usize,
        done: &str,
    ) -> Result<usize, ProblemError> {
        let (name, value) = &given[i];
        if given[..i].iter().any(|(n, _)| n == name) {
            return Err(ProblemError::InvalidValue {
                what: format!("`{name}`, {done} twice: {done}"),
                value: *value,
            });
        }
        let movable: Vec<usize> = self.free.iter().chain(&self.scales).copied().collect();
        movable.iter().copied().find(|&j| &self.declared[j].name == name).ok_or_else(|| {
            let names: Vec<&str> =
                movable.iter().map(|&j| self.declared[j].name.as_str()).collect();
            ProblemError::NotAnUnknown { name: name.clone(), unknowns: names.join(", ") }
        })
    }

    /// The same problem with the unknowns named in `fixed` held at the given values: they
    /// become known, and the degrees of freedom and every method count them so.
    pub fn with_fixed(mut self, fixed: &[(String, f64)]) -> Result<Self, ProblemError> {
        if fixed.is_empty() {
            return Ok(self);
        }
        for (i, (name, value)) in fixed.iter().enumerate() {
            let j = self.movable(fixed, i, "fixed")?;
            let u = &self.declared[j];
            if !value.is_finite() || (u.log && *value <= 0.0) {
                return Err(ProblemError::InvalidValue {
                    what: match u.log {
                        true => format!("fixed `{name}` (on a log scale: it must be positive)"),
                        false => format!("fixed `{name}`"),
                    },
                    value: *value,
                });
            }
            // Within the bounds, as a start must be: a few units in the last place are
            // allowed, for a value mapped back from a bound's coordinate (a profile's last
            // point, exp(ln hi)).
            if let Some(wrong) = outside_bounds(u, *value, 8.0 * f64::EPSILON) {
                return Err(ProblemError::InvalidUnknown {
                    name: name.clone(),
                    message: format!(
                        "fixed at {}: {wrong} (a value held must lie within the unknown's bounds, as its estimate must)",
                        crate::format::shortest(*value)
                    ),
                });
            }
            self.held[j] = *value;
            self.free.retain(|&f| f != j);
            self.scales.retain(|&s| s != j);
        }
        if self.free.is_empty() && self.scales.is_empty() {
            let list: Vec<String> = fixed.iter().map(|(n, v)| format!("{n} = {v}")).collect();
            return Err(ProblemError::AllFixed(list.join(", ")));
        }
        self.replan()
    }

    /// The same problem started elsewhere: each unknown named in `start` (a free unknown or a
    /// noise scale) gets that value as its guess, the point a fit begins from. The value must
    /// be finite, within the unknown's bounds, and positive on a log scale.
    pub fn with_start(mut self, start: &[(String, f64)]) -> Result<Self, ProblemError> {
        for (i, (name, value)) in start.iter().enumerate() {
            let j = self.movable(start, i, "started")?;
            let u = &mut self.declared[j];
            let wrong = match (value.is_finite(), u.log && *value <= 0.0) {
                (false, _) => Some("it must be finite".to_string()),
                (_, true) => Some("it is on a log scale, so it must be positive".to_string()),
                _ => outside_bounds(u, *value, 0.0),
            };
            if let Some(wrong) = wrong {
                return Err(ProblemError::InvalidUnknown {
                    name: name.clone(),
                    message: format!("start {}: {wrong}", crate::format::shortest(*value)),
                });
            }
            u.guess = *value;
            self.held[j] = *value;
        }
        self.replan()
    }

    /// Makes the settings that keep results of earlier points (a preequilibration's steady
    /// state, solved once per point) forget them, so that the next evaluation at a point
    /// already met costs what it did the first time: `sysid evaluate --repeat` and the
    /// benchmarks call it before each timed evaluation. The problem's results do not change.
    pub fn forget_cached(&self) {
        for e in &self.experiments {
            e.forget_cached();
        }
    }

    /// The same problem with another integrator.
    pub fn with_integrator(mut self, integrator: Integrator) -> Result<Self, ProblemError> {
        integrator.validate().map_err(ProblemError::Integrator)?;
        self.integrator = integrator;
        for e in &mut self.experiments {
            e.integrate_with(&integrator);
        }
        Ok(self)
    }

    /// The same problem with other measurements for its one experiment (of the same kind of
    /// quantities).
    pub fn with_data(mut self, data: Data) -> Result<Self, ProblemError> {
        if self.experiments.len() != 1 {
            return Err(ProblemError::Experiments(
                "new data for a problem of several experiments: give each experiment's".into(),
            ));
        }
        self.experiments[0].data = data;
        self.replan()
    }

    /// The same problem with other measurements for every experiment, in order.
    pub fn with_experiment_data(mut self, data: Vec<Data>) -> Result<Self, ProblemError> {
        if data.len() != self.experiments.len() {
            return Err(ProblemError::Experiments(format!(
                "{} data sets for {} experiments",
                data.len(),
                self.experiments.len()
            )));
        }
        for (e, d) in self.experiments.iter_mut().zip(data) {
            e.data = d;
        }
        self.replan()
    }

    /// The same problem with the noise scales at `sigma` (one per [`scales`](Self::scales)):
    /// what the methods fit between two closed-form updates of the scales.
    pub fn with_scales(&self, sigma: &[f64]) -> Self {
        let mut out = self.clone();
        for (&j, &s) in self.scales.iter().zip(sigma) {
            out.held[j] = s;
        }
        out.weigh_scales();
        out
    }

    /// The current values of the noise scales.
    pub fn scale_values(&self) -> Vec<f64> {
        self.scales.iter().map(|&j| self.held[j]).collect()
    }

    /// The value of every declared unknown at the free unknowns' coordinates z. Every
    /// evaluation of the problem at z (cost, residuals, linearization, predictions) goes
    /// through it.
    ///
    /// # Panics
    ///
    /// Where z has not one coordinate per free unknown: a shorter z took the guess for the
    /// unknowns it lacked, and a cost came back for a point never asked for.
    pub fn values_at(&self, z: &[f64]) -> Vec<f64> {
        assert_eq!(
            z.len(),
            self.free.len(),
            "a point of {} coordinates for {} free unknowns ({})",
            z.len(),
            self.free.len(),
            self.unknowns.names().join(", ")
        );
        let mut v = self.held.clone();
        for ((u, &j), &zi) in self.unknowns.list().iter().zip(&self.free).zip(z) {
            v[j] = u.value(zi);
        }
        v
    }

    /// The free index of every declared unknown (None for one that is not free).
    pub fn free_index(&self) -> Vec<Option<usize>> {
        let mut index = vec![None; self.declared.len()];
        for (f, &j) in self.free.iter().enumerate() {
            index[j] = Some(f);
        }
        index
    }

    /// y(t0) and α of the first experiment at coordinates z.
    pub fn point(&self, z: &[f64]) -> (Vec<f64>, Vec<f64>) {
        self.experiments[0].point(&self.values_at(z))
    }

    /// d value / d z for each free unknown at z: the chain rule of log-scale unknowns.
    pub(crate) fn chain(&self, z: &[f64]) -> Vec<f64> {
        self.unknowns.list().iter().zip(z).map(|(u, &zi)| u.scale(zi)).collect()
    }

    /// Plans every experiment again (after the unknowns or the data changed). Fewer data than
    /// unknowns is a problem like any other: the fit names what the data cannot determine.
    fn replan(mut self) -> Result<Self, ProblemError> {
        let is_free: Vec<bool> = (0..self.declared.len()).map(|j| self.free.contains(&j)).collect();
        let declared = &self.declared;
        let find = |name: &str| declared.iter().position(|u| u.name == name);
        for e in &mut self.experiments {
            e.plan = plan(e.system.as_ref(), &e.data, &find)
                .map_err(|err| in_experiment(&e.name, err))?;
            e.slots = slots(&e.initial, &e.parameters, &is_free);
            // Other columns: the choice between forward and adjoint is measured again.
            e.adjoint_cheaper = Default::default();
        }
        self.unknowns = Unknowns::new(self.free.iter().map(|&j| declared[j].clone()).collect());
        // A noise scale is σ itself (times positive factors): σ = −1 fitted as 1 and was
        // reported converged at −1, its interval reversed. (0 is left to the evaluation,
        // which names the residual it makes infinite: a PEtab problem whose nominal σ is 0
        // still imports, for starts elsewhere.)
        let scaled = self.experiments.iter().flat_map(|e| e.sampled().series.iter());
        for series in scaled {
            if let PlannedNoise::Scale { unknown, .. } = series.noise {
                let value = self.held[unknown];
                if value < 0.0 || !value.is_finite() {
                    return Err(ProblemError::InvalidUnknown {
                        name: declared[unknown].name.clone(),
                        message: format!(
                            "a noise scale is a σ: it must not be negative, and finite, got {}",
                            crate::format::shortest(value)
                        ),
                    });
                }
            }
        }
        self.weigh_scales();
        Ok(self)
    }

    /// Sets √w of the samples whose σ is a noise scale from its held value.
    fn weigh_scales(&mut self) {
        let held = &self.held;
        for e in &mut self.experiments {
            if let Plan::Discrete(sampled) = &mut e.plan {
                for series in &mut sampled.series {
                    if let PlannedNoise::Scale { unknown, factors } = &series.noise {
                        for (sample, f) in series.samples.iter_mut().zip(factors) {
                            sample.sqrt_weight = 1.0 / (held[*unknown] * f);
                        }
                    }
                }
            }
        }
    }
}

/// An error of one experiment, named when there are several.
fn in_experiment(name: &str, e: ProblemError) -> ProblemError {
    match name {
        SINGLE_EXPERIMENT => e,
        _ => ProblemError::Experiments(format!("experiment `{name}`: {e}")),
    }
}

/// Builder of a [`Problem`].
pub struct ProblemBuilder<S> {
    system: S,
    t0: f64,
    /// Known initial values and parameters, in the order given.
    values: Vec<(String, f64)>,
    unknowns: Vec<Unknown>,
    data: Option<Data>,
    experiments: Vec<Experiment<S>>,
    integrator: Integrator,
    quadrature_rtol: f64,
}

impl<S: System> ProblemBuilder<S> {
    /// Time of the initial values (default 0). Data may lie on both sides. (One experiment.)
    pub fn t0(mut self, t0: f64) -> Self {
        self.t0 = t0;
        self
    }
    /// A known initial value (state name) or parameter value. (One experiment.)
    pub fn known(mut self, name: &str, value: f64) -> Self {
        self.values.push((name.into(), value));
        self
    }
    /// Known values for several names. (One experiment.)
    pub fn knowns(mut self, values: &[(&str, f64)]) -> Self {
        self.values.extend(values.iter().map(|(n, v)| (n.to_string(), *v)));
        self
    }
    /// An unknown initial value (state name) or parameter, with its starting guess.
    pub fn unknown(self, name: &str, guess: f64) -> Self {
        self.unknown_with(Unknown::new(name, guess))
    }
    /// An unknown with bounds or a log scale. With experiments, any name their settings and
    /// noise models use; without, a state (its initial value), a parameter, or an unknown of
    /// the data's noise models (the s of a [`Noise::Scale`], an unknown a noise function
    /// uses).
    pub fn unknown_with(mut self, unknown: Unknown) -> Self {
        self.unknowns.push(unknown);
        self
    }
    /// The measurements. (One experiment.)
    pub fn data(mut self, data: Data) -> Self {
        self.data = Some(data);
        self
    }
    /// An experiment; a problem of experiments takes its data, t0, known values and
    /// unknowns' places from them.
    pub fn experiment(mut self, experiment: Experiment<S>) -> Self {
        self.experiments.push(experiment);
        self
    }
    /// How to integrate (default: DOPRI5, rtol 1e-8, atol 1e-10).
    pub fn integrator(mut self, integrator: Integrator) -> Self {
        self.integrator = integrator;
        self
    }
    /// Relative accuracy of the quadratures of a continuous record (default 1e-10).
    pub fn quadrature_rtol(mut self, rtol: f64) -> Self {
        self.quadrature_rtol = rtol;
        self
    }

    /// Checks everything and builds the problem.
    pub fn build(self) -> Result<Problem<S>, ProblemError> {
        self.integrator.validate().map_err(ProblemError::Integrator)?;
        if !(self.quadrature_rtol > 0.0 && self.quadrature_rtol < 1.0) {
            return Err(ProblemError::InvalidValue {
                what: "quadrature rtol".into(),
                value: self.quadrature_rtol,
            });
        }
        let (integrator, quadrature_rtol) = (self.integrator, self.quadrature_rtol);
        let mut experiments = self.experiments;
        if experiments.is_empty() {
            experiments.push(single(
                self.system,
                self.t0,
                &self.values,
                &self.unknowns,
                self.data,
            )?);
        } else if self.data.is_some() || !self.values.is_empty() {
            return Err(ProblemError::Experiments(
                "known values and data belong to the experiments when there are experiments".into(),
            ));
        }
        let declared = self.unknowns;
        if declared.is_empty() {
            return Err(ProblemError::NoUnknowns);
        }
        for (i, u) in declared.iter().enumerate() {
            u.validate().map_err(|message| ProblemError::InvalidUnknown {
                name: u.name.clone(),
                message,
            })?;
            if declared[..i].iter().any(|v| v.name == u.name) {
                return Err(ProblemError::SpecifiedTwice {
                    name: u.name.clone(),
                    first: "unknown",
                    second: "unknown",
                });
            }
        }
        let mut experiments = resolve_experiments(&declared, experiments)?;
        for e in &mut experiments {
            e.integrate_with(&integrator);
        }
        let (free, scales) = roles(&declared, &experiments)?;
        for &j in &scales {
            if declared[j].prior.is_some() {
                return Err(ProblemError::InvalidUnknown {
                    name: declared[j].name.clone(),
                    message:
                        "a prior on a noise scale, which is set in closed form, is not supported"
                            .into(),
                });
            }
        }
        if declared.iter().any(|u| u.prior.is_some())
            && experiments.iter().any(|e| e.data.record != crate::Record::Discrete)
        {
            return Err(ProblemError::Experiments("priors need discrete data".into()));
        }
        let held = declared.iter().map(|u| u.guess).collect();
        let problem = Problem {
            unknowns: Unknowns::new(Vec::new()),
            declared,
            free,
            held,
            scales,
            experiments,
            integrator,
            quadrature_rtol,
        };
        problem.replan()
    }
}

/// The one experiment of a problem built without experiments: every state and parameter
/// known or unknown by name.
fn single<S: System>(
    system: S,
    t0: f64,
    values: &[(String, f64)],
    unknowns: &[Unknown],
    data: Option<Data>,
) -> Result<Experiment<S>, ProblemError> {
    let sig = system.signature();
    if !t0.is_finite() {
        return Err(ProblemError::InvalidValue { what: "t0".into(), value: t0 });
    }
    let (n, np) = (sig.n_states(), sig.n_parameters());
    let mut settings: Vec<Option<(Setting, &'static str)>> = vec![None; n + np];
    let slot = |name: &str| -> Result<usize, ProblemError> {
        sig.state(name).or_else(|| sig.parameter(name).map(|k| n + k)).ok_or_else(|| {
            ProblemError::UnknownName {
                name: name.into(),
                states: sig.states().join(", "),
                parameters: sig.parameters().join(", "),
            }
        })
    };
    let given = values.iter().map(|(name, v)| (name, Setting::Value(*v), "known"));
    // An unknown of the data's noise models (a σ scale's s, an unknown a noise function
    // uses) that is no state or parameter has no slot: the noise model resolves it.
    let of_noise = |i: usize, name: &str| {
        data.iter().flat_map(|d| &d.series).any(|s| match &s.noise {
            Some(Noise::Scale { unknown, .. }) => unknown == name,
            Some(Noise::Function(f)) => f.uses().contains(&i),
            _ => false,
        })
    };
    let unknown = unknowns
        .iter()
        .enumerate()
        .filter(|(i, u)| slot(&u.name).is_ok() || !of_noise(*i, &u.name))
        .map(|(_, u)| (&u.name, Setting::Unknown(u.name.clone()), "unknown"));
    for (name, setting, how) in given.chain(unknown) {
        let i = slot(name)?;
        if let Some((_, first)) = &settings[i] {
            return Err(ProblemError::SpecifiedTwice { name: name.clone(), first, second: how });
        }
        if let Setting::Value(v) = setting
            && !v.is_finite()
        {
            return Err(ProblemError::InvalidValue { what: format!("known `{name}`"), value: v });
        }
        settings[i] = Some((setting, how));
    }
    if let Some(i) = settings.iter().position(Option::is_none) {
        let (kind, name) = if i < n {
            ("state", &sig.states()[i])
        } else {
            ("parameter", &sig.parameters()[i - n])
        };
        return Err(ProblemError::NotSpecified { kind, name: name.clone() });
    }
    let mut initial: Vec<Setting> = settings.into_iter().map(|s| s.expect("checked").0).collect();
    let parameters = initial.split_off(n);
    Ok(Experiment {
        name: SINGLE_EXPERIMENT.into(),
        also: Vec::new(),
        system,
        t0,
        initial,
        parameters,
        data: data.ok_or(ProblemError::NoData)?,
    })
}

/// The experiments with their settings resolved against the unknowns, each checked.
fn resolve_experiments<S: System>(
    declared: &[Unknown],
    experiments: Vec<Experiment<S>>,
) -> Result<Vec<Planned<S>>, ProblemError> {
    let mut out: Vec<Planned<S>> = Vec::with_capacity(experiments.len());
    for e in experiments {
        let names = std::iter::once(&e.name).chain(&e.also);
        for (k, name) in names.clone().enumerate() {
            if out.iter().any(|o| o.answers_to(name))
                || names.clone().skip(k + 1).any(|n| n == name)
            {
                return Err(ProblemError::Experiments(format!(
                    "two experiments are called `{name}`"
                )));
            }
        }
        let fail = |message: String| {
            ProblemError::Experiments(format!("experiment `{}`: {message}", e.name))
        };
        if !e.t0.is_finite() {
            return Err(fail(format!("t0 is {}", e.t0)));
        }
        let sig = e.system.signature();
        if e.initial.len() != sig.n_states() || e.parameters.len() != sig.n_parameters() {
            return Err(fail(format!(
                "{} initial values and {} parameters for a system of {} states and {} parameters",
                e.initial.len(),
                e.parameters.len(),
                sig.n_states(),
                sig.n_parameters()
            )));
        }
        let resolve = |s: &Setting, what: &str| -> Result<Resolved, ProblemError> {
            Ok(match s {
                Setting::Value(v) if v.is_finite() => Resolved::Value(*v),
                Setting::Value(v) => return Err(fail(format!("{what} is {v}"))),
                Setting::Unknown(name) => {
                    Resolved::Unknown(declared.iter().position(|u| &u.name == name).ok_or_else(
                        || fail(format!("{what} is set to `{name}`, which is not an unknown")),
                    )?)
                }
                Setting::Function(f) => {
                    if let Some(&j) = f.uses().iter().find(|&&j| j >= declared.len()) {
                        return Err(fail(format!(
                            "{what}: `{}` uses unknown {j} of {}",
                            f.describe(),
                            declared.len()
                        )));
                    }
                    Resolved::Function(f.clone())
                }
            })
        };
        let initial = e
            .initial
            .iter()
            .zip(sig.states())
            .map(|(s, name)| resolve(s, &format!("the initial value of `{name}`")))
            .collect::<Result<Vec<_>, _>>()?;
        let parameters = e
            .parameters
            .iter()
            .zip(sig.parameters())
            .map(|(s, name)| resolve(s, &format!("parameter `{name}`")))
            .collect::<Result<Vec<_>, _>>()?;
        let find = |name: &str| declared.iter().position(|u| u.name == name);
        let plan = plan(&e.system, &e.data, &find).map_err(|err| in_experiment(&e.name, err))?;
        out.push(Planned {
            name: e.name,
            also: e.also,
            system: std::sync::Arc::new(e.system),
            t0: e.t0,
            initial,
            parameters,
            data: e.data,
            plan,
            slots: Vec::new(),
            adjoint_cheaper: Default::default(),
        });
    }
    Ok(out)
}

/// Which unknowns the methods move (free) and which are noise scales set in closed form; an
/// unknown that nothing uses is refused.
fn roles<S: System>(
    declared: &[Unknown],
    experiments: &[Planned<S>],
) -> Result<(Vec<usize>, Vec<usize>), ProblemError> {
    let k = declared.len();
    let (mut model, mut scale) = (vec![false; k], vec![false; k]);
    for e in experiments {
        for s in e.initial.iter().chain(&e.parameters) {
            match s {
                Resolved::Unknown(j) => model[*j] = true,
                Resolved::Function(f) => f.uses().iter().for_each(|&j| model[j] = true),
                Resolved::Value(_) => {}
            }
        }
        for series in &e.sampled().series {
            match &series.noise {
                PlannedNoise::Scale { unknown, .. } => scale[*unknown] = true,
                PlannedNoise::Function(f) => f.uses().iter().for_each(|&j| model[j] = true),
                _ => {}
            }
        }
    }
    if let Some(j) = (0..k).find(|&j| model[j] && scale[j]) {
        return Err(ProblemError::Experiments(format!(
            "`{}` is a noise scale and also used by the model or a setting: a scale set in closed form must be nothing else",
            declared[j].name
        )));
    }
    if let Some(j) = (0..k).find(|&j| !model[j] && !scale[j]) {
        return Err(ProblemError::Experiments(format!(
            "the unknown `{}` is used nowhere (no initial value, parameter, setting or σ)",
            declared[j].name
        )));
    }
    Ok(((0..k).filter(|&j| model[j]).collect(), (0..k).filter(|&j| scale[j]).collect()))
}

/// "below its min 1e-5" or "above its max 2" where `value` lies outside `u`'s bounds by more
/// than `slack` of the bound (relative), else None.
fn outside_bounds(u: &Unknown, value: f64, slack: f64) -> Option<String> {
    let beyond = |b: f64| slack * b.abs();
    let below = u.min.filter(|&lo| value < lo - beyond(lo));
    let above = u.max.filter(|&hi| value > hi + beyond(hi));
    match (below, above) {
        (Some(lo), _) => Some(format!("below its min {}", crate::format::shortest(lo))),
        (_, Some(hi)) => Some(format!("above its max {}", crate::format::shortest(hi))),
        _ => None,
    }
}
