//! A model file as an identification problem: one experiment for `[data]`, or one per
//! `[[experiments]]`, each with its data, inputs, t0 and settings; the outputs' noise models;
//! and the settings, initial values and σ that are expressions, as functions of the unknowns
//! differentiated with dual numbers.

use std::path::Path;
use std::sync::Arc;

use num_dual::Dual64;
use sysid_core::{
    Experiment, Noise, NoiseDistribution, Problem, ProblemError, Setting,
    plan::{NoiseArgs, NoiseFunction, NoiseGradient, SettingFunction},
};
use sysid_ode::{Ivp, Observable, ObservableGradient, Scalar};

use crate::data::{self, Start};
use crate::error::ModelError;
use crate::expr::Program;
use crate::file::{Expression, NoiseSpec, SetValue};
use crate::steady::SteadyState;
use crate::{Model, ModelSystem};

/// Where a parameter's value comes from in one experiment.
#[derive(Clone, Debug)]
enum Source {
    /// A number.
    Known(f64),
    /// The unknown of this declared index.
    Unknown(usize),
    /// An expression of the parameters given outside the experiments and the extras.
    Expression(Program),
    /// Nothing outside the experiments (set by each of them).
    Unset,
}

/// How one experiment gives its parameters and the extra unknowns their values: what its
/// setting, initial-value and σ expressions are evaluated with.
#[derive(Debug)]
struct Context {
    /// Per parameter, outside the experiments.
    base: Vec<Source>,
    /// Per parameter, in this experiment.
    effective: Vec<Source>,
    /// The declared index of each extra unknown.
    extras: Vec<usize>,
}

impl Context {
    /// [parameters..., extras...] at the unknowns' values `v`: as this experiment gives the
    /// parameters (`effective`), or as they are outside the experiments.
    fn vector<T: Scalar>(&self, effective: bool, v: &[T]) -> Vec<T> {
        let value = |s: &Source, base: &[T]| match s {
            Source::Known(x) => T::from(*x),
            Source::Unknown(j) => v[*j],
            Source::Expression(program) => program.eval(0.0, &[], base, &[]),
            Source::Unset => T::from(f64::NAN),
        };
        let mut base: Vec<T> = self.base.iter().map(|s| value(s, &[])).collect();
        base.extend(self.extras.iter().map(|&j| v[j]));
        if !effective {
            return base;
        }
        let mut out: Vec<T> = self.effective.iter().map(|s| value(s, &base)).collect();
        out.extend(self.extras.iter().map(|&j| v[j]));
        out
    }

    /// The unknowns (declared indices) the value of `name` depends on.
    fn uses_of(&self, names: &[String], scope: &Names<'_>, effective: bool) -> Vec<usize> {
        let mut out = Vec::new();
        let mut add = |j: usize| {
            if !out.contains(&j) {
                out.push(j);
            }
        };
        for name in names {
            if let Some(x) = scope.extras.iter().position(|e| e == name) {
                add(self.extras[x]);
            } else if let Some(q) = scope.parameters.iter().position(|p| p == name) {
                let source = if effective { &self.effective[q] } else { &self.base[q] };
                match source {
                    Source::Unknown(j) => add(*j),
                    Source::Expression(_) => {
                        if let Some(uses) = scope.set_uses.iter().find(|(p, _)| *p == q) {
                            uses.1.iter().for_each(|&j| add(j));
                        }
                    }
                    Source::Known(_) | Source::Unset => {}
                }
            }
        }
        out
    }
}

/// Names the model's expressions refer to.
struct Names<'a> {
    parameters: &'a [String],
    extras: &'a [String],
    /// For the parameters an experiment sets by an expression: their unknowns.
    set_uses: Vec<(usize, Vec<usize>)>,
}

/// A setting or an initial value given by an expression, in one experiment.
#[derive(Debug)]
struct ExpressionSetting {
    program: Program,
    context: Arc<Context>,
    /// Evaluated with the experiment's parameters (an initial value) or those outside the
    /// experiments (a parameter the experiment sets).
    effective: bool,
    uses: Vec<usize>,
    text: String,
}

impl SettingFunction for ExpressionSetting {
    fn eval(&self, v: &[f64], gradient: &mut [f64]) -> f64 {
        let value = self.program.eval(0.0, &[], &self.context.vector(self.effective, v), &[]);
        for &j in &self.uses {
            let seeded: Vec<Dual64> = v
                .iter()
                .enumerate()
                .map(|(i, &x)| if i == j { Dual64::new(x, 1.0) } else { Dual64::from(x) })
                .collect();
            let d = self.program.eval(0.0, &[], &self.context.vector(self.effective, &seeded), &[]);
            gradient[j] = d.eps;
        }
        value
    }
    fn uses(&self) -> &[usize] {
        &self.uses
    }
    fn describe(&self) -> String {
        self.text.clone()
    }
}

/// An output's σ given by an expression of t, the states, the parameters, the extras and
/// the output's own value.
#[derive(Debug)]
struct ExpressionNoise {
    program: Program,
    /// The declared index of each extra.
    extras: Vec<usize>,
    /// Which states, parameters, extras and whether the value it uses (to seed only those).
    states: Vec<usize>,
    parameters: Vec<usize>,
    uses: Vec<usize>,
    own: bool,
    text: String,
}

impl ExpressionNoise {
    fn at<T: Scalar>(&self, args: &NoiseArgs<'_>, y: &[T], p: &[T], v: &[T], h: T) -> T {
        let mut ext: Vec<T> = p.to_vec();
        ext.extend(self.extras.iter().map(|&j| v[j]));
        ext.push(h);
        self.program.eval(args.t, y, &ext, &[])
    }
}

impl NoiseFunction for ExpressionNoise {
    fn eval(&self, args: NoiseArgs<'_>, gradient: &mut NoiseGradient<'_>) -> f64 {
        let lift = |x: &[f64]| x.iter().map(|&a| Dual64::from(a)).collect::<Vec<_>>();
        let (y, p, v) = (lift(args.y), lift(args.p), lift(args.v));
        let h = Dual64::from(args.h);
        let seeded = |list: &[Dual64], i: usize| {
            let mut s = list.to_vec();
            s[i] = Dual64::new(s[i].re, 1.0);
            s
        };
        for &i in &self.states {
            gradient.y[i] = self.at(&args, &seeded(&y, i), &p, &v, h).eps;
        }
        for &q in &self.parameters {
            gradient.p[q] = self.at(&args, &y, &seeded(&p, q), &v, h).eps;
        }
        for &j in &self.uses {
            gradient.v[j] = self.at(&args, &y, &p, &seeded(&v, j), h).eps;
        }
        if self.own {
            gradient.h = self.at(&args, &y, &p, &v, Dual64::new(args.h, 1.0)).eps;
        }
        self.at::<f64>(&args, args.y, args.p, args.v, args.h)
    }
    fn uses(&self) -> &[usize] {
        &self.uses
    }
    fn describe(&self) -> String {
        self.text.clone()
    }
}

/// A name and the value an experiment gives it (`set`, `preequilibrate`, `initial`).
type Assignment<'a> = (String, &'a SetValue);

/// Whether two lists of assignments set the same names to the same values, in the same order
/// (a number to the same bits, an expression to the same text).
fn same_settings(a: &[Assignment<'_>], b: &[Assignment<'_>]) -> bool {
    let same = |x: &SetValue, y: &SetValue| match (x, y) {
        (SetValue::Number(x), SetValue::Number(y)) => x.to_bits() == y.to_bits(),
        (SetValue::Expression(x), SetValue::Expression(y)) => x.text == y.text,
        _ => false,
    };
    a.len() == b.len() && a.iter().zip(b).all(|((m, x), (n, y))| m == n && same(x, y))
}

/// An experiment to build: its name, data file, t0 and where t0 is written, and what it sets.
struct Plan<'a> {
    name: String,
    file: &'a Path,
    start: Start<'a>,
    set: Vec<Assignment<'a>>,
    preequilibrate: Option<Vec<Assignment<'a>>>,
    steady: bool,
    initial: Vec<Assignment<'a>>,
    also: Vec<String>,
}

impl Model {
    /// The identification problem of the model file: its `[data]` (or `data` instead) as one
    /// experiment, or each of its `[[experiments]]`. An error in an imported problem is
    /// located where the user wrote its subject ([`ModelFile::origins`](crate::ModelFile)).
    pub fn problem(&self, data: Option<&Path>) -> Result<Problem<ModelSystem>, ModelError> {
        let f = &self.file;
        let model = f.path.display();
        let named: Vec<String> = match data {
            Some(_) => vec!["given by --data (in Python, data=)".into()],
            None if f.experiments.is_empty() => {
                vec![format!("that `[data] file` in {model} names")]
            }
            None => f
                .experiments
                .iter()
                .map(|e| format!("that experiment `{}`'s `file` in {model} names", e.name))
                .collect(),
        };
        let plans: Vec<Plan<'_>> = if f.experiments.is_empty() {
            let file = match data {
                Some(p) => p,
                None => self.data_path()?,
            };
            let start =
                Start { t0: f.data.t0, at: f.data.t0_at, table: "[data]", named_by: &named[0] };
            vec![Plan {
                name: sysid_core::plan::SINGLE_EXPERIMENT.into(),
                file,
                start,
                set: Vec::new(),
                preequilibrate: None,
                steady: false,
                initial: Vec::new(),
                also: Vec::new(),
            }]
        } else {
            if data.is_some() {
                return Err(self.located(
                    "--data (in Python, data=) replaces the [data] file, and this model has [[experiments]], each with its own file".into(),
                ));
            }
            f.experiments
                .iter()
                .zip(&named)
                .map(|(e, named_by)| Plan {
                    name: e.name.clone(),
                    file: &e.file,
                    start: Start { t0: e.t0, at: e.t0_at, table: "[[experiments]]", named_by },
                    set: e.set.iter().map(|(p, v, _)| (p.clone(), v)).collect(),
                    preequilibrate: e
                        .preequilibrate
                        .as_ref()
                        .map(|list| list.iter().map(|(p, v, _)| (p.clone(), v)).collect()),
                    steady: e.steady,
                    initial: e.initial.iter().map(|(x, v, _)| (x.clone(), v)).collect(),
                    also: e.also.clone(),
                })
                .collect()
        };
        let declared = &f.unknowns;
        let index = |name: &str| declared.iter().position(|u| u.name == name);
        let extras: Vec<usize> =
            f.extras.iter().map(|x| index(x).expect("an extra is an unknown")).collect();
        let base: Vec<Source> = f
            .parameters
            .iter()
            .map(|name| match (f.known.iter().find(|k| &k.0 == name), index(name)) {
                (Some((_, v)), _) => Source::Known(*v),
                (None, Some(j)) => Source::Unknown(j),
                (None, None) => Source::Unset,
            })
            .collect();
        let scales = self.scale_unknowns();
        // One system, derived and compiled once; each experiment drives it with its inputs.
        let system = self.system(Default::default());
        let mut builder = Problem::builder(system.clone()).integrator(f.integrator);
        for u in declared {
            builder = builder.unknown_with(u.clone());
        }
        let mut preequilibrations: Vec<(&Vec<Assignment<'_>>, Arc<SteadyState>)> = Vec::new();
        for plan in &plans {
            let read = data::read_from(f, plan.file, plan.start)
                .map_err(|e| self.in_experiment(&plan.name, e))?;
            let (parameters, mut initial) =
                self.settings((&plan.set, &plan.initial), &base, &extras, &plan.name)?;
            let own = initial.clone();
            if let Some(pre) = &plan.preequilibrate {
                // Experiments whose preequilibrations set the same values share one steady
                // state, solved once per point: Isensee's 109 conditions have one.
                let steady = match preequilibrations.iter().find(|(p, _)| same_settings(p, pre)) {
                    Some((_, steady)) => Arc::clone(steady),
                    None => {
                        let (pre_parameters, pre_initial) =
                            self.settings((pre, &[]), &base, &extras, &plan.name)?;
                        let steady = Arc::new(SteadyState::new(
                            system.clone(),
                            f.integrator,
                            (pre_parameters, pre_initial),
                            declared,
                        ));
                        preequilibrations.push((pre, Arc::clone(&steady)));
                        steady
                    }
                };
                initial = steady.initial_values(&f.states, &plan.name);
            }
            // The experiment's own initial values replace the preequilibration's steady state
            // (PEtab's re-initialisation after a preequilibration).
            for (state, _) in &plan.initial {
                let i = f.states.iter().position(|x| x == state).expect("checked when read");
                initial[i] = own[i].clone();
            }
            if plan.steady {
                // From there (or from [initial]) to the steady state under its own settings.
                let steady = Arc::new(SteadyState::new(
                    system.clone(),
                    f.integrator,
                    (parameters.clone(), initial),
                    declared,
                ));
                initial = steady.initial_values(&f.states, &plan.name);
            }
            let mut data = read.data;
            for &(series, output) in &read.modelled {
                let NoiseSpec::Expression(e) = &f.outputs[output].noise else { continue };
                let noise = match e.bare.as_deref().filter(|b| scales.contains(b)) {
                    Some(scale) => {
                        let n = match &data.series[series].samples {
                            sysid_core::Samples::Points { values, .. } => values.len(),
                            sysid_core::Samples::Function(_) => 0,
                        };
                        Noise::Scale { unknown: scale.to_string(), factors: vec![1.0; n] }
                    }
                    None => Noise::Function(Arc::new(self.noise_function(
                        e,
                        &f.outputs[output].name,
                        &extras,
                    ))),
                };
                data.series[series].noise = Some(noise);
            }
            let t0 = plan.start.t0;
            builder = builder.experiment(Experiment {
                name: plan.name.clone(),
                also: plan.also.clone(),
                system: system.with_inputs(read.inputs),
                t0,
                initial,
                parameters,
                data,
            });
        }
        let problem = builder.build().map_err(|e| self.problem_error(e, &plans))?;
        self.check_sigma_at_start(&problem)?;
        Ok(problem)
    }

    /// The parameters and the initial values of an experiment under the settings `set` (its
    /// own, or its preequilibration's) applied to the parameters outside the experiments,
    /// `base`; the states in `starts` (its `initial`) start from those values instead of
    /// `[initial]`'s, evaluated with its parameters.
    fn settings(
        &self,
        (set, starts): (&[Assignment<'_>], &[Assignment<'_>]),
        base: &[Source],
        extras: &[usize],
        experiment: &str,
    ) -> Result<(Vec<Setting>, Vec<Setting>), ModelError> {
        let f = &self.file;
        let declared = &f.unknowns;
        let index = |name: &str| declared.iter().position(|u| u.name == name);
        let mut effective = base.to_vec();
        let mut set_uses = Vec::new();
        for (name, value) in set {
            let q = f.parameters.iter().position(|p| p == name).expect("checked when read");
            effective[q] = match value {
                SetValue::Number(x) => Source::Known(*x),
                SetValue::Expression(e) => match e.bare.as_deref().and_then(index) {
                    Some(j) => Source::Unknown(j),
                    None => {
                        self.check_base(e, base, experiment)?;
                        let probe = Context {
                            base: base.to_vec(),
                            effective: Vec::new(),
                            extras: extras.to_vec(),
                        };
                        let names = Names {
                            parameters: &f.parameters,
                            extras: &f.extras,
                            set_uses: Vec::new(),
                        };
                        set_uses.push((q, probe.uses_of(&e.uses, &names, false)));
                        Source::Expression(e.program.clone())
                    }
                },
            };
        }
        let context = Arc::new(Context { base: base.to_vec(), effective, extras: extras.to_vec() });
        let names = Names { parameters: &f.parameters, extras: &f.extras, set_uses };
        let setting = |e: &Expression, effective: bool| -> Setting {
            Setting::Function(Arc::new(ExpressionSetting {
                program: e.program.clone(),
                context: context.clone(),
                effective,
                uses: context.uses_of(&e.uses, &names, effective),
                text: e.text.clone(),
            }))
        };
        let parameters: Vec<Setting> = f
            .parameters
            .iter()
            .enumerate()
            .map(|(q, name)| match &context.effective[q] {
                Source::Known(x) => Setting::Value(*x),
                Source::Unknown(j) => Setting::Unknown(declared[*j].name.clone()),
                Source::Expression(_) => {
                    let (_, value) = set.iter().find(|(p, _)| p == name).expect("set");
                    let SetValue::Expression(e) = value else { unreachable!("an expression") };
                    setting(e, false)
                }
                Source::Unset => Setting::Value(f64::NAN),
            })
            .collect();
        let initial: Vec<Setting> = f
            .states
            .iter()
            .map(|name| {
                if let Some((_, start)) = starts.iter().find(|s| &s.0 == name) {
                    match start {
                        SetValue::Number(x) => Setting::Value(*x),
                        SetValue::Expression(e) => setting(e, true),
                    }
                } else if let Some((_, v)) = f.known.iter().find(|k| &k.0 == name) {
                    Setting::Value(*v)
                } else if let Some((_, e)) = f.initial.iter().find(|k| &k.0 == name) {
                    setting(e, true)
                } else {
                    Setting::Unknown(name.clone())
                }
            })
            .collect();
        Ok((parameters, initial))
    }

    /// The extras whose only use is to be the whole σ of outputs: noise scales, set in closed
    /// form.
    fn scale_unknowns(&self) -> Vec<&str> {
        let f = &self.file;
        let mut other: Vec<&str> = Vec::new();
        let mut bare: Vec<&str> = Vec::new();
        for o in &f.outputs {
            if let NoiseSpec::Expression(e) = &o.noise {
                // A Laplace scale has no closed form here (the normal σ's is the root mean
                // square): it is fitted as a function.
                match (&e.bare, o.distribution) {
                    (Some(name), NoiseDistribution::Normal) => bare.push(name),
                    _ => other.extend(e.uses.iter().map(String::as_str)),
                }
            }
        }
        for (_, e) in &f.initial {
            other.extend(e.uses.iter().map(String::as_str));
        }
        for x in &f.experiments {
            for (_, v, _) in x.set.iter().chain(&x.initial).chain(x.preequilibrate.iter().flatten())
            {
                if let SetValue::Expression(e) = v {
                    other.extend(e.uses.iter().map(String::as_str));
                }
            }
        }
        bare.into_iter().filter(|b| f.extras.iter().any(|x| x == b) && !other.contains(b)).collect()
    }

    /// σ of `output` as a function for the likelihood.
    fn noise_function(&self, e: &Expression, output: &str, extras: &[usize]) -> ExpressionNoise {
        let f = &self.file;
        let position = |list: &[String], n: &String| list.iter().position(|x| x == n);
        let declared: Vec<usize> =
            e.uses.iter().filter_map(|n| position(&f.extras, n).map(|x| extras[x])).collect();
        ExpressionNoise {
            program: e.program.clone(),
            extras: extras.to_vec(),
            states: e.uses.iter().filter_map(|n| position(&f.states, n)).collect(),
            parameters: e.uses.iter().filter_map(|n| position(&f.parameters, n)).collect(),
            uses: declared,
            own: e.uses.iter().any(|n| n == output),
            text: e.text.clone(),
        }
    }

    /// Refuses a set expression that uses a parameter with no value outside the
    /// experiments.
    fn check_base(
        &self,
        e: &Expression,
        base: &[Source],
        experiment: &str,
    ) -> Result<(), ModelError> {
        let f = &self.file;
        for name in &e.uses {
            if let Some(q) = f.parameters.iter().position(|p| p == name)
                && matches!(base[q], Source::Unset)
            {
                return Err(f.err(
                    e.at,
                    format!(
                        "experiment `{experiment}`: `{}` uses `{name}`, which has no value outside the experiments: use an unknown or a [known] parameter",
                        e.text
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Refuses a σ that is not finite and at least the likelihood's least σ at the start,
    /// naming the output, the experiment and the time.
    fn check_sigma_at_start(&self, problem: &Problem<ModelSystem>) -> Result<(), ModelError> {
        let (floor, why) = sysid_core::plan::least_sigma();
        let v = problem.values_at(&problem.unknowns().coordinates(&problem.guesses()));
        for e in problem.experiments() {
            let functions: Vec<_> = e
                .sampled()
                .series
                .iter()
                .filter_map(|s| match &s.noise {
                    sysid_core::plan::PlannedNoise::Function(n) => Some((s, n.clone())),
                    _ => None,
                })
                .collect();
            if functions.is_empty() {
                continue;
            }
            let sampled = e.sampled();
            // The trajectory, unless every σ here is a function of t, the parameters and the
            // unknowns alone (a PEtab noise formula of noise parameters): then σ needs no
            // integration, nor the initial values (a steady state to solve, with Isensee's
            // 123 conditions most of the import's time), which it does not read.
            let model_free = functions.iter().all(|(s, _)| self.sigma_is_model_free(s.observable));
            let (y0, p) = match model_free {
                true => (
                    vec![0.0; sysid_ode::System::signature(e.system()).n_states()],
                    e.parameters_at(&v),
                ),
                false => e.point(&v),
            };
            let sol = match model_free {
                true => None,
                false => match Ivp::new(e.system(), e.t0(), &y0, &p)
                    .sized(&e.sizes(&y0))
                    .solve(problem.integrator(), &sampled.times)
                {
                    Ok(sol) => Some(sol),
                    Err(_) => continue,
                },
            };
            let mut og = ObservableGradient::new(e.system(), &p, &[]);
            let (n, np) = (y0.len(), p.len());
            for (series, noise) in functions {
                for sample in &series.samples {
                    let t = sampled.times[sample.index];
                    let (y, h) = match &sol {
                        Some(sol) => {
                            let y = sol.state(sample.index);
                            (y, og.eval(t, y, &[], series.observable, &mut []))
                        }
                        None => (y0.as_slice(), f64::NAN),
                    };
                    let (mut dy, mut dp, mut dv) =
                        (vec![0.0; n], vec![0.0; np], vec![0.0; v.len()]);
                    let mut g = NoiseGradient { y: &mut dy, h: 0.0, p: &mut dp, v: &mut dv };
                    let sigma = noise.eval(NoiseArgs { t, y, h, p: &p, v: &v }, &mut g);
                    if !(sigma >= floor && sigma.is_finite()) {
                        let name = match series.observable {
                            Observable::State(i) => &self.file.states[i],
                            Observable::Output(o) => &self.file.outputs[o].name,
                        };
                        // At the σ expression, where it is one.
                        let at =
                            self.file.outputs.iter().find(|o| &o.name == name).map_or(0, |o| {
                                match &o.noise {
                                    crate::NoiseSpec::Expression(e) => e.at,
                                    _ => o.at,
                                }
                            });
                        let must = match sigma > 0.0 {
                            true => format!("σ must be at least {why}"),
                            false => "σ must be positive".to_string(),
                        };
                        return Err(self.file.err(
                            at,
                            format!(
                                "the σ of `{name}`, {}, is {} at t = {} in experiment `{}` at the start: {must}",
                                noise.describe(),
                                sysid_core::format::shortest(sigma),
                                sysid_core::format::shortest(t),
                                e.name()
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Whether the σ of an observable uses neither the states nor the output's own value.
    fn sigma_is_model_free(&self, observable: Observable) -> bool {
        let f = &self.file;
        let Observable::Output(o) = observable else { return false };
        let output = &f.outputs[o];
        match &output.noise {
            NoiseSpec::Expression(e) => {
                !e.uses.iter().any(|n| n == &output.name || f.states.contains(n))
            }
            _ => false,
        }
    }

    fn in_experiment(&self, name: &str, e: ModelError) -> ModelError {
        if name == sysid_core::plan::SINGLE_EXPERIMENT {
            return e;
        }
        ModelError { message: format!("experiment `{name}`: {}", e.message), ..e }
    }

    fn problem_error(&self, e: ProblemError, plans: &[Plan<'_>]) -> ModelError {
        let file = match plans {
            [one] => one.file.display().to_string(),
            _ => self.file.path.display().to_string(),
        };
        match e {
            // At the unknown's key, where it is one of the file's.
            ProblemError::InvalidUnknown { ref name, .. } => {
                let f = &self.file;
                match f.unknowns.iter().position(|u| &u.name == name) {
                    Some(i) if i < f.unknowns_at.len() => f.err(f.unknowns_at[i], e.to_string()),
                    _ => self.located(e.to_string()),
                }
            }
            ProblemError::NoUnknowns => self.located(e.to_string()),
            other => ModelError::file(&file, other.to_string()),
        }
    }
}
