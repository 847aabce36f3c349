//! The identification problem: a model, what is known, what is unknown, and the data. It
//! knows nothing of methods; it evaluates the least-squares quantities every method needs.

use sysid_ode::{Integrator, Observable, System, Wrt};

use crate::data::Data;
use crate::error::ProblemError;
use crate::plan::{Plan, plan};
use crate::unknowns::{Unknown, Unknowns};

/// Default relative accuracy of the quadratures of a continuous record.
pub const QUADRATURE_RTOL: f64 = 1e-10;

/// A system, its known initial values and parameters, the unknowns with their starting
/// guesses, the measurements, and how to integrate.
///
/// Build one with [`Problem::builder`]; every state needs its initial value either known or
/// unknown, and every parameter likewise.
#[derive(Clone, Debug)]
pub struct Problem<S> {
    pub(crate) system: S,
    pub(crate) t0: f64,
    pub(crate) initial: Vec<f64>,
    pub(crate) parameters: Vec<f64>,
    pub(crate) unknowns: Unknowns,
    pub(crate) data: Data,
    pub(crate) plan: Plan,
    pub(crate) integrator: Integrator,
    pub(crate) quadrature_rtol: f64,
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
            integrator: Integrator::default(),
            quadrature_rtol: QUADRATURE_RTOL,
        }
    }

    /// The model.
    pub fn system(&self) -> &S {
        &self.system
    }
    /// Time of the initial values.
    pub fn t0(&self) -> f64 {
        self.t0
    }
    /// The unknowns.
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }
    /// Names of the unknowns.
    pub fn names(&self) -> Vec<String> {
        self.unknowns.names()
    }
    /// The starting guesses (values).
    pub fn guesses(&self) -> Vec<f64> {
        self.unknowns.guesses()
    }
    /// The measurements.
    pub fn data(&self) -> &Data {
        &self.data
    }
    /// Whether the data are a continuous record.
    pub fn is_continuous(&self) -> bool {
        matches!(self.plan, Plan::Continuous { .. })
    }
    /// The integrator.
    pub fn integrator(&self) -> &Integrator {
        &self.integrator
    }
    /// The time span a fit integrates over: the data (the record's span for continuous
    /// data) together with t0.
    pub fn span(&self) -> (f64, f64) {
        let (lo, hi) = match &self.plan {
            Plan::Discrete(s) => (s.times[0], s.times[s.times.len() - 1]),
            Plan::Continuous { span, .. } => *span,
        };
        (lo.min(self.t0), hi.max(self.t0))
    }

    /// A step tolerance as the methods apply it: not below the integrator's relative
    /// tolerance. The model is integrated to about rtol, so changes of the unknowns below
    /// it are indistinguishable from integration error; iterating on them costs
    /// integrations and changes nothing the integration can resolve.
    pub fn resolvable_step(&self, step_tolerance: f64) -> f64 {
        step_tolerance.max(self.integrator.rtol)
    }

    /// Number of measured values (None for a record given as a function).
    pub fn n_observations(&self) -> Option<usize> {
        self.data.n_observations()
    }

    /// Degrees of freedom N − k of the residual variance (None for a record given as a
    /// function).
    pub fn dof(&self) -> Option<usize> {
        self.n_observations().map(|n| n.saturating_sub(self.unknowns.len()))
    }

    /// ‖W^½ b‖: the weighted data's norm (the record's for continuous data, by the
    /// quadrature of its residual form), the scale an exact fit is measured against.
    pub fn data_norm(&self) -> f64 {
        self.sampled()
            .series
            .iter()
            .flat_map(|s| &s.samples)
            .map(|m| (m.sqrt_weight * m.value).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Row `row` of the residual vector in words: "`B` at t = 3 (sample 14 of `B`)".
    pub fn describe_row(&self, row: usize) -> String {
        let sampled = self.sampled();
        let signature = self.system.signature();
        let mut at = row;
        for s in &sampled.series {
            if at < s.samples.len() {
                let name = match s.observable {
                    Observable::State(i) => &signature.states()[i],
                    Observable::Output(i) => &signature.outputs()[i],
                };
                let t = sampled.times[s.samples[at].index];
                return format!("`{name}` at t = {t} (sample {} of `{name}`)", at + 1);
            }
            at -= s.samples.len();
        }
        format!("row {row}")
    }

    /// The same problem with the unknowns named in `fixed` held at the given values: they
    /// become known, and the degrees of freedom and every method count them so.
    pub fn with_fixed(mut self, fixed: &[(String, f64)]) -> Result<Self, ProblemError> {
        if fixed.is_empty() {
            return Ok(self);
        }
        let mut list = self.unknowns.list().to_vec();
        let mut wrt = self.unknowns.wrt().to_vec();
        for (name, value) in fixed {
            let Some(i) = list.iter().position(|u| &u.name == name) else {
                return Err(ProblemError::NotAnUnknown {
                    name: name.clone(),
                    unknowns: self.unknowns.names().join(", "),
                });
            };
            if !value.is_finite() {
                return Err(ProblemError::InvalidValue {
                    what: format!("fixed `{name}`"),
                    value: *value,
                });
            }
            match wrt[i] {
                Wrt::InitialValue(j) => self.initial[j] = *value,
                Wrt::Parameter(j) => self.parameters[j] = *value,
            }
            list.remove(i);
            wrt.remove(i);
        }
        if list.is_empty() {
            return Err(ProblemError::NoUnknowns);
        }
        self.plan = plan(&self.system, &self.data, list.len())?;
        self.unknowns = Unknowns::new(list, wrt);
        Ok(self)
    }

    /// The same problem with another integrator.
    pub fn with_integrator(mut self, integrator: Integrator) -> Result<Self, ProblemError> {
        integrator.validate().map_err(ProblemError::Integrator)?;
        self.integrator = integrator;
        Ok(self)
    }

    /// The same problem with other measurements (of the same kind of quantities).
    pub fn with_data(mut self, data: Data) -> Result<Self, ProblemError> {
        self.plan = plan(&self.system, &data, self.unknowns.len())?;
        self.data = data;
        Ok(self)
    }

    /// y(t0) and α at coordinates z.
    pub fn point(&self, z: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (mut y0, mut p) = (self.initial.clone(), self.parameters.clone());
        for ((u, w), &zi) in self.unknowns.list().iter().zip(self.unknowns.wrt()).zip(z) {
            match *w {
                Wrt::InitialValue(i) => y0[i] = u.value(zi),
                Wrt::Parameter(k) => p[k] = u.value(zi),
            }
        }
        (y0, p)
    }

    /// d value / d z for each unknown at z: the chain rule of log-scale unknowns.
    pub(crate) fn chain(&self, z: &[f64]) -> Vec<f64> {
        self.unknowns.list().iter().zip(z).map(|(u, &zi)| u.scale(zi)).collect()
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
    integrator: Integrator,
    quadrature_rtol: f64,
}

impl<S: System> ProblemBuilder<S> {
    /// Time of the initial values (default 0). Data may lie on both sides.
    pub fn t0(mut self, t0: f64) -> Self {
        self.t0 = t0;
        self
    }
    /// A known initial value (state name) or parameter value.
    pub fn known(mut self, name: &str, value: f64) -> Self {
        self.values.push((name.into(), value));
        self
    }
    /// Known values for several names.
    pub fn knowns(mut self, values: &[(&str, f64)]) -> Self {
        self.values.extend(values.iter().map(|(n, v)| (n.to_string(), *v)));
        self
    }
    /// An unknown initial value (state name) or parameter, with its starting guess.
    pub fn unknown(self, name: &str, guess: f64) -> Self {
        self.unknown_with(Unknown::new(name, guess))
    }
    /// An unknown with bounds or a log scale.
    pub fn unknown_with(mut self, unknown: Unknown) -> Self {
        self.unknowns.push(unknown);
        self
    }
    /// The measurements.
    pub fn data(mut self, data: Data) -> Self {
        self.data = Some(data);
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
        let sig = self.system.signature();
        if !self.t0.is_finite() {
            return Err(ProblemError::InvalidValue { what: "t0".into(), value: self.t0 });
        }
        self.integrator.validate().map_err(ProblemError::Integrator)?;
        if !(self.quadrature_rtol > 0.0 && self.quadrature_rtol < 1.0) {
            return Err(ProblemError::InvalidValue {
                what: "quadrature rtol".into(),
                value: self.quadrature_rtol,
            });
        }
        let (n, np) = (sig.n_states(), sig.n_parameters());
        let mut initial = vec![f64::NAN; n];
        let mut parameters = vec![f64::NAN; np];
        let mut given: Vec<Option<&'static str>> = vec![None; n + np];
        let resolve = |name: &str| -> Result<Wrt, ProblemError> {
            sig.state(name)
                .map(Wrt::InitialValue)
                .or_else(|| sig.parameter(name).map(Wrt::Parameter))
                .ok_or_else(|| ProblemError::UnknownName {
                    name: name.into(),
                    states: sig.states().join(", "),
                    parameters: sig.parameters().join(", "),
                })
        };
        let slot = |w: Wrt| match w {
            Wrt::InitialValue(i) => i,
            Wrt::Parameter(k) => n + k,
        };
        let mark = |given: &mut Vec<Option<&'static str>>,
                    name: &str,
                    w: Wrt,
                    how: &'static str| {
            if let Some(first) = given[slot(w)] {
                return Err(ProblemError::SpecifiedTwice { name: name.into(), first, second: how });
            }
            given[slot(w)] = Some(how);
            Ok(())
        };
        for (name, value) in &self.values {
            let w = resolve(name)?;
            mark(&mut given, name, w, "known")?;
            if !value.is_finite() {
                return Err(ProblemError::InvalidValue {
                    what: format!("known `{name}`"),
                    value: *value,
                });
            }
            match w {
                Wrt::InitialValue(i) => initial[i] = *value,
                Wrt::Parameter(k) => parameters[k] = *value,
            }
        }
        let mut wrt = Vec::with_capacity(self.unknowns.len());
        for u in &self.unknowns {
            let w = resolve(&u.name)?;
            mark(&mut given, &u.name, w, "unknown")?;
            u.validate().map_err(|message| ProblemError::InvalidUnknown {
                name: u.name.clone(),
                message,
            })?;
            match w {
                Wrt::InitialValue(i) => initial[i] = u.guess,
                Wrt::Parameter(k) => parameters[k] = u.guess,
            }
            wrt.push(w);
        }
        for (i, g) in given.iter().enumerate() {
            if g.is_none() {
                let (kind, name) = if i < n {
                    ("state", &sig.states()[i])
                } else {
                    ("parameter", &sig.parameters()[i - n])
                };
                return Err(ProblemError::NotSpecified { kind, name: name.clone() });
            }
        }
        if self.unknowns.is_empty() {
            return Err(ProblemError::NoUnknowns);
        }
        let data = self.data.ok_or(ProblemError::NoData)?;
        let plan = plan(&self.system, &data, self.unknowns.len())?;
        Ok(Problem {
            t0: self.t0,
            initial,
            parameters,
            unknowns: Unknowns::new(self.unknowns, wrt),
            data,
            plan,
            integrator: self.integrator,
            quadrature_rtol: self.quadrature_rtol,
            system: self.system,
        })
    }
}
