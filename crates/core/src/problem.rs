//! The identification problem: a model, what is known, what is unknown, and the data. It
//! knows nothing of methods; it evaluates the least-squares quantities every method needs.

use nalgebra::{DMatrix, DVector};
use sysid_ode::{
    Counts, Integrator, Interpolation, Ivp, Observable, ObservableGradient, OdeError, Record,
    RecordedOutput, Signal, System, Wrt,
};

use crate::confidence::t95;
use crate::data::{Data, Record as Kind, Samples};
use crate::error::ProblemError;
use crate::linalg::NormalFactor;
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
    system: S,
    t0: f64,
    initial: Vec<f64>,
    parameters: Vec<f64>,
    unknowns: Unknowns,
    data: Data,
    plan: Plan,
    integrator: Integrator,
    quadrature_rtol: f64,
}

/// The measurements resolved against the system.
#[derive(Clone, Debug)]
enum Plan {
    Discrete(Sampled),
    Continuous {
        span: (f64, f64),
        outputs: Vec<RecordedOutput>,
        /// The record discretised for least-squares solvers that need a residual vector.
        nodes: Sampled,
    },
}

/// A measured quantity as the model predicts it: see [`Problem::observed`].
#[derive(Clone, Debug, PartialEq)]
pub struct Observed {
    /// The state or output.
    pub name: String,
    /// Its values at the times asked for.
    pub values: Vec<f64>,
    /// Half-width of the 95 % band at each time, t_{0.975, N−k} √(g Cov gᵀ) (when a covariance
    /// was given and N > k).
    pub half_width: Option<Vec<f64>>,
}

/// The data in residual form: measured values at discrete times, each with the square root
/// of its weight. Discrete data as given (weight w_o); a continuous record at the nodes of a
/// composite Gauss–Legendre rule (weight w_o times the node's weight), so that
/// Σ (√w (h − b))² is the quadrature of ε.
#[derive(Clone, Debug)]
pub struct Sampled {
    /// All times, sorted, without repeats.
    pub times: Vec<f64>,
    /// One entry per measured quantity.
    pub series: Vec<PlannedSeries>,
}

/// The samples of one measured quantity in residual form.
#[derive(Clone, Debug)]
pub struct PlannedSeries {
    /// What is measured.
    pub observable: Observable,
    /// Its samples.
    pub samples: Vec<Sample>,
}

/// One measured value: row √w (h(t) − b) of the residual vector.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    /// Index into [`Sampled::times`].
    pub index: usize,
    /// The measured value b.
    pub value: f64,
    /// √w.
    pub sqrt_weight: f64,
}

/// Panels per record span of a record given as a function, in its residual form.
pub const RESIDUAL_PANELS: usize = 256;

// Gauss–Legendre, 4 points on [−1, 1].
const GL4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
];

/// Residuals and Jacobian, each row scaled by the square root of its weight so that
/// ε = ‖r‖², U = Jᵀr and A = JᵀJ. For a continuous record the rows are the record at
/// Gauss–Legendre nodes (see [`Problem::residuals_and_jacobian`]).
#[derive(Clone, Debug, PartialEq)]
pub struct WeightedResiduals {
    /// √w_o (h_o(y(t_m)) − b_{o,m}), series after series, in time order within a series.
    pub r: DVector<f64>,
    /// ∂r/∂z.
    pub jacobian: DMatrix<f64>,
}

/// Everything one integration with sensitivities tells about the unknowns z.
#[derive(Clone, Debug, PartialEq)]
pub struct Linearization {
    /// Where it was evaluated (coordinates).
    pub z: Vec<f64>,
    /// ε.
    pub cost: f64,
    /// U (Goodman eq. 12, continuous eq. 22): half the gradient of ε.
    pub gradient: DVector<f64>,
    /// A (eq. 15, continuous eq. 24): the Gauss–Newton normal matrix.
    pub normal: DMatrix<f64>,
    /// The weighted residuals and their Jacobian (discrete data only).
    pub residuals: Option<WeightedResiduals>,
    /// Work done.
    pub counts: Counts,
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

    /// The half-width of a 95 % band in standard deviations: Student's t quantile for the
    /// problem's N − k degrees of freedom (None without residual degrees of freedom).
    pub fn band_quantile(&self) -> Option<f64> {
        self.dof().and_then(t95)
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
    fn chain(&self, z: &[f64]) -> Vec<f64> {
        self.unknowns.list().iter().zip(z).map(|(u, &zi)| u.scale(zi)).collect()
    }

    /// Integrates the model and its sensitivities at z and forms ε, U and A: sums over the
    /// samples of discrete data (Goodman's eq. 12, 15), integrals over a continuous record
    /// accumulated during the integration (eq. 22, 24).
    pub fn linearize(&self, z: &[f64]) -> Result<Linearization, OdeError> {
        let (span, outputs) = match &self.plan {
            Plan::Discrete(sampled) => return self.linearize_sampled(sampled, z),
            Plan::Continuous { span, outputs, .. } => (*span, outputs),
        };
        let (y0, p) = self.point(z);
        let wrt = self.unknowns.wrt();
        let k = wrt.len();
        let q = Ivp::new(&self.system, self.t0, &y0, &p).least_squares_integrals(
            &self.integrator,
            wrt,
            outputs,
            span,
            self.quadrature_rtol,
        )?;
        let scale = self.chain(z);
        let gradient = DVector::from_fn(k, |i, _| q.gradient[i] * scale[i]);
        let normal = DMatrix::from_fn(k, k, |i, j| q.normal[(i, j)] * scale[i] * scale[j]);
        if !q.cost.is_finite() || normal.iter().chain(gradient.iter()).any(|v| !v.is_finite()) {
            return Err(OdeError::NonFinite {
                t: span.0,
                what: "the least-squares integrals".into(),
            });
        }
        Ok(Linearization {
            z: z.to_vec(),
            cost: q.cost,
            gradient,
            normal,
            residuals: None,
            counts: q.counts,
        })
    }

    /// The weighted residuals and their Jacobian at z, from one integration with
    /// sensitivities: what a general least-squares solver works with. Discrete data give
    /// one row per sample. A continuous record gives one row per node of a composite
    /// Gauss–Legendre rule (4 nodes per panel; panels between the samples of a sampled
    /// record, [`RESIDUAL_PANELS`] panels over the span for a record given as a function), so
    /// that ‖r‖² is the quadrature of ε.
    pub fn residuals_and_jacobian(&self, z: &[f64]) -> Result<Linearization, OdeError> {
        self.linearize_sampled(self.sampled(), z)
    }

    /// The data in residual form (the rows of [`residuals`](Self::residuals)).
    pub fn sampled(&self) -> &Sampled {
        match &self.plan {
            Plan::Discrete(sampled) => sampled,
            Plan::Continuous { nodes, .. } => nodes,
        }
    }

    fn linearize_sampled(&self, plan: &Sampled, z: &[f64]) -> Result<Linearization, OdeError> {
        let (y0, p) = self.point(z);
        let wrt = self.unknowns.wrt();
        let k = wrt.len();
        let scale = self.chain(z);
        let times = &plan.times;
        let sol = Ivp::new(&self.system, self.t0, &y0, &p).solve_sensitivities(
            &self.integrator,
            wrt,
            times,
        )?;
        let rows: usize = plan.series.iter().map(|s| s.samples.len()).sum();
        let mut r = DVector::zeros(rows);
        let mut jac = DMatrix::zeros(rows, k);
        let mut og = ObservableGradient::new(&self.system, &p, wrt);
        let mut grad = vec![0.0; k];
        let mut row = 0;
        for s in &plan.series {
            for sample in &s.samples {
                let m = sample.index;
                let h = og.eval(
                    times[m],
                    sol.state(m),
                    sol.sensitivity_slice(m),
                    s.observable,
                    &mut grad,
                );
                r[row] = sample.sqrt_weight * (h - sample.value);
                for j in 0..k {
                    jac[(row, j)] = sample.sqrt_weight * grad[j] * scale[j];
                }
                row += 1;
            }
        }
        check_finite(&r, &jac, times)?;
        Ok(Linearization {
            z: z.to_vec(),
            cost: r.norm_squared(),
            gradient: jac.tr_mul(&r),
            normal: jac.tr_mul(&jac),
            residuals: Some(WeightedResiduals { r, jacobian: jac }),
            counts: sol.counts(),
        })
    }

    /// The integrator of [`cost`](Self::cost): the problem's, 10 times tighter (rtol not
    /// below 1e-13). A plain integration controls the error of the states only and so takes
    /// longer steps than one with sensitivities; tightening it keeps ε as accurate as the
    /// fits' own evaluations (on van der Pol at rtol 1e-8: 1.6e-8 relative error untightened,
    /// about 2e-9 tightened).
    fn cost_integrator(&self) -> Integrator {
        let rtol = (self.integrator.rtol / 10.0).max(1e-13);
        Integrator { rtol, atol: self.integrator.atol / 10.0, ..self.integrator }
    }

    /// ε at z by a plain integration of the model, with tolerances 10 times tighter than the
    /// fits use, so that every method's iterates are compared on one accurate measure (the
    /// integral itself for a continuous record).
    pub fn cost(&self, z: &[f64]) -> Result<(f64, Counts), OdeError> {
        let (span, outputs) = match &self.plan {
            Plan::Discrete(_) => {
                let (r, counts) = self.residuals_with(&self.cost_integrator(), z)?;
                return Ok((r.norm_squared(), counts));
            }
            Plan::Continuous { span, outputs, .. } => (*span, outputs),
        };
        let (y0, p) = self.point(z);
        let q = Ivp::new(&self.system, self.t0, &y0, &p).least_squares_integrals(
            &self.cost_integrator(),
            &[],
            outputs,
            span,
            self.quadrature_rtol,
        )?;
        if !q.cost.is_finite() {
            return Err(OdeError::NonFinite { t: span.0, what: "the cost".into() });
        }
        Ok((q.cost, q.counts))
    }

    /// Number of rows of [`residuals`](Self::residuals).
    pub fn n_residuals(&self) -> usize {
        self.sampled().series.iter().map(|s| s.samples.len()).sum()
    }

    /// The weighted residual vector at z, without sensitivities: the rows of
    /// [`residuals_and_jacobian`](Self::residuals_and_jacobian).
    pub fn residuals(&self, z: &[f64]) -> Result<(DVector<f64>, Counts), OdeError> {
        self.residuals_with(&self.integrator, z)
    }

    fn residuals_with(
        &self,
        integrator: &Integrator,
        z: &[f64],
    ) -> Result<(DVector<f64>, Counts), OdeError> {
        let (h, counts) = self.predictions_with(integrator, z)?;
        let samples = self.sampled().series.iter().flat_map(|s| &s.samples);
        let r = DVector::from_iterator(
            h.len(),
            h.iter().zip(samples).map(|(h, s)| s.sqrt_weight * (h - s.value)),
        );
        if let Some(i) = r.iter().position(|v| !v.is_finite()) {
            let t = self.sampled().times[0];
            return Err(OdeError::NonFinite { t, what: format!("residual {i}") });
        }
        Ok((r, counts))
    }

    /// The model's values h_o(t_m) of every measured quantity at z, row by row as the
    /// residuals (series after series, samples in time order; for a continuous record, at
    /// the nodes of its residual form), from a plain integration 10 times tighter than the
    /// fits use: what noise-free data at z would be.
    pub fn predictions(&self, z: &[f64]) -> Result<Vec<f64>, OdeError> {
        let (h, _) = self.predictions_with(&self.cost_integrator(), z)?;
        if let Some(i) = h.iter().position(|v| !v.is_finite()) {
            let t = self.sampled().times[0];
            return Err(OdeError::NonFinite { t, what: format!("prediction {i}") });
        }
        Ok(h)
    }

    fn predictions_with(
        &self,
        integrator: &Integrator,
        z: &[f64],
    ) -> Result<(Vec<f64>, Counts), OdeError> {
        let plan = self.sampled();
        let (y0, p) = self.point(z);
        let times = &plan.times;
        let sol = Ivp::new(&self.system, self.t0, &y0, &p).solve(integrator, times)?;
        let mut og = ObservableGradient::new(&self.system, &p, &[]);
        let mut h = Vec::with_capacity(self.n_residuals());
        for s in &plan.series {
            for sample in &s.samples {
                let m = sample.index;
                h.push(og.eval(times[m], sol.state(m), &[], s.observable, &mut []));
            }
        }
        Ok((h, sol.counts()))
    }

    /// Every measured quantity of the model at `values` of the unknowns, at `times` (sorted;
    /// on either side of t0), with the half-width of its 95 % band from `covariance` (of the
    /// values): t_{0.975, N−k} √(g Cov gᵀ), g = ∂h/∂(values) from the sensitivities. What a fit
    /// predicts for the measurements, with its uncertainty.
    pub fn observed(
        &self,
        values: &[f64],
        covariance: Option<&DMatrix<f64>>,
        times: &[f64],
    ) -> Result<Vec<Observed>, OdeError> {
        let z = self.unknowns.coordinates(values);
        let (y0, p) = self.point(&z);
        let wrt = self.unknowns.wrt();
        let sol = Ivp::new(&self.system, self.t0, &y0, &p).solve_sensitivities(
            &self.integrator,
            wrt,
            times,
        )?;
        let signature = self.system.signature();
        let mut og = ObservableGradient::new(&self.system, &p, wrt);
        let mut grad = vec![0.0; wrt.len()];
        let mut out = Vec::new();
        let quantile = self.band_quantile();
        for series in &self.sampled().series {
            let name = match series.observable {
                Observable::State(i) => signature.states()[i].clone(),
                Observable::Output(i) => signature.outputs()[i].clone(),
            };
            let mut observed = Observed {
                name,
                values: Vec::with_capacity(times.len()),
                half_width: quantile.and(covariance).map(|_| Vec::with_capacity(times.len())),
            };
            for (m, &t) in times.iter().enumerate() {
                let s = sol.sensitivity_slice(m);
                let h = og.eval(t, sol.state(m), s, series.observable, &mut grad);
                observed.values.push(h);
                if let (Some(cov), Some(w)) = (covariance, observed.half_width.as_mut()) {
                    let g = DVector::from_column_slice(&grad);
                    let var = g.dot(&(cov * &g));
                    w.push(quantile.unwrap_or(f64::NAN) * var.max(0.0).sqrt());
                }
            }
            out.push(observed);
        }
        Ok(out)
    }

    /// Covariance of the estimates (as values) from the normal matrix at the estimate, scaled
    /// by the residual variance s² = ε / (N − k):  Cov = s² A⁻¹, transformed to values by the
    /// delta method. Unknowns `held` on a bound are not estimated there: the covariance is
    /// that of the free ones, s² (A_FF)⁻¹ with s² = ε / (N − k_free), and the held ones' rows
    /// and columns are 0. `None` when there are no more data than free unknowns (no residual
    /// variance), for a record given as a function (no count N), or when A_FF is singular.
    pub fn covariance(&self, lin: &Linearization, held: &[bool]) -> Option<DMatrix<f64>> {
        let k = self.unknowns.len();
        let free: Vec<usize> = (0..k).filter(|&i| !held.get(i).copied().unwrap_or(false)).collect();
        let n = self.n_observations()?;
        if n <= free.len() || free.is_empty() {
            return None;
        }
        let s2 = lin.cost / (n - free.len()) as f64;
        let block = lin.normal.select_rows(&free).select_columns(&free);
        let inverse = NormalFactor::new(&block, f64::INFINITY).ok()?.inverse();
        let scale: Vec<f64> =
            self.unknowns.list().iter().zip(&lin.z).map(|(u, &z)| u.scale(z)).collect();
        let mut cov = DMatrix::zeros(k, k);
        for (a, &i) in free.iter().enumerate() {
            for (b, &j) in free.iter().enumerate() {
                cov[(i, j)] = s2 * inverse[(a, b)] * scale[i] * scale[j];
            }
        }
        Some(cov)
    }
}

fn check_finite(r: &DVector<f64>, jac: &DMatrix<f64>, times: &[f64]) -> Result<(), OdeError> {
    if let Some(i) = r.iter().position(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite {
            t: times.first().copied().unwrap_or(0.0),
            what: format!("residual {i}"),
        });
    }
    if jac.iter().any(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite {
            t: times.first().copied().unwrap_or(0.0),
            what: "the residual Jacobian".into(),
        });
    }
    Ok(())
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

/// Resolves and checks the measurements.
fn plan<S: System>(system: &S, data: &Data, k: usize) -> Result<Plan, ProblemError> {
    let sig = system.signature();
    if data.series.is_empty() {
        return Err(ProblemError::NoData);
    }
    let mut seen = std::collections::HashSet::new();
    let mut resolved = Vec::with_capacity(data.series.len());
    for s in &data.series {
        let invalid =
            |message: String| ProblemError::InvalidSeries { name: s.name.clone(), message };
        let observable = sig.observable(&s.name).ok_or_else(|| ProblemError::UnknownSeries {
            name: s.name.clone(),
            observable: sig
                .states()
                .iter()
                .chain(sig.outputs())
                .cloned()
                .collect::<Vec<_>>()
                .join(", "),
        })?;
        if !seen.insert(&s.name) {
            return Err(invalid("given twice".into()));
        }
        if !(s.weight > 0.0 && s.weight.is_finite()) {
            return Err(invalid(format!(
                "the weight must be positive and finite, got {}",
                s.weight
            )));
        }
        if let Samples::Points { times, values } = &s.samples {
            if times.len() != values.len() {
                return Err(invalid(format!("{} times but {} values", times.len(), values.len())));
            }
            if times.is_empty() {
                return Err(invalid("no samples".into()));
            }
            if let Some(i) = times.iter().position(|t| !t.is_finite()) {
                return Err(invalid(format!("time {i} is {}", times[i])));
            }
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(invalid(format!("value at t = {} is {}", times[i], values[i])));
            }
            if let Some(i) = times.windows(2).position(|w| w[1] <= w[0]) {
                return Err(invalid(format!(
                    "times must increase: {} follows {}",
                    times[i + 1],
                    times[i]
                )));
            }
        }
        if let Some(weights) = &s.sample_weights {
            let count = match &s.samples {
                Samples::Points { values, .. } => values.len(),
                Samples::Function(_) => 0,
            };
            if weights.len() != count {
                return Err(invalid(format!(
                    "{} sample weights for {count} samples",
                    weights.len()
                )));
            }
            if let Some(i) = weights.iter().position(|w| !(*w > 0.0 && w.is_finite())) {
                return Err(invalid(format!(
                    "sample weight {i} must be positive and finite, got {}",
                    weights[i]
                )));
            }
            if data.record != Kind::Discrete {
                return Err(invalid("per-sample weights need discrete data".into()));
            }
        }
        resolved.push(observable);
    }
    match data.record {
        Kind::Discrete => {
            let mut points = Vec::with_capacity(data.series.len());
            for s in &data.series {
                match &s.samples {
                    Samples::Points { times, values } => {
                        let sqrt_weight = |m: usize| match &s.sample_weights {
                            Some(w) => (s.weight * w[m]).sqrt(),
                            None => s.weight.sqrt(),
                        };
                        points.push(
                            times
                                .iter()
                                .zip(values)
                                .enumerate()
                                .map(|(m, (&t, &v))| (t, v, sqrt_weight(m)))
                                .collect(),
                        );
                    }
                    Samples::Function(_) => {
                        return Err(ProblemError::InvalidSeries {
                            name: s.name.clone(),
                            message: "a record given as a function needs continuous data".into(),
                        });
                    }
                }
            }
            let observations = data.n_observations().unwrap_or(0);
            if observations < k {
                return Err(ProblemError::TooFewData { observations, unknowns: k });
            }
            Ok(Plan::Discrete(gather(&resolved, points)))
        }
        Kind::Continuous { t_lo, t_hi } => {
            if !(t_lo.is_finite() && t_hi.is_finite() && t_lo < t_hi) {
                return Err(ProblemError::InvalidValue {
                    what: format!("record span [{t_lo}, {t_hi}]"),
                    value: t_hi - t_lo,
                });
            }
            let outputs = data
                .series
                .iter()
                .zip(&resolved)
                .map(|(s, &observable)| {
                    let record = match &s.samples {
                        Samples::Points { times, values } => Record::Samples(
                            Signal::new(times.clone(), values.clone(), Interpolation::Linear)
                                .map_err(|e| ProblemError::InvalidSeries {
                                    name: s.name.clone(),
                                    message: e.to_string(),
                                })?,
                        ),
                        Samples::Function(f) => Record::Function(f.clone()),
                    };
                    Ok(RecordedOutput { observable, weight: s.weight, record })
                })
                .collect::<Result<Vec<_>, ProblemError>>()?;
            if let Some(observations) = data.n_observations()
                && observations < k
            {
                return Err(ProblemError::TooFewData { observations, unknowns: k });
            }
            let points = outputs.iter().map(|o| record_nodes(o, (t_lo, t_hi))).collect();
            let nodes = gather(&resolved, points);
            Ok(Plan::Continuous { span: (t_lo, t_hi), outputs, nodes })
        }
    }
}

/// Gathers per-series (time, value, √weight) points on one sorted time grid.
fn gather(observables: &[Observable], points: Vec<Vec<(f64, f64, f64)>>) -> Sampled {
    let mut times: Vec<f64> = points.iter().flatten().map(|p| p.0).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let series = observables
        .iter()
        .zip(points)
        .map(|(&observable, pts)| PlannedSeries {
            observable,
            samples: pts
                .into_iter()
                .map(|(t, value, sqrt_weight)| Sample {
                    index: times.partition_point(|x| *x < t),
                    value,
                    sqrt_weight,
                })
                .collect(),
        })
        .collect();
    Sampled { times, series }
}

/// A record as residual rows: b at the nodes of a composite 4-point Gauss–Legendre rule,
/// each with the square root of w_o times its quadrature weight.
fn record_nodes(output: &RecordedOutput, (t_lo, t_hi): (f64, f64)) -> Vec<(f64, f64, f64)> {
    let mut breaks = vec![t_lo];
    match &output.record {
        Record::Samples(s) => breaks.extend(s.times().iter().filter(|&&t| t > t_lo && t < t_hi)),
        Record::Function(_) => {
            let h = (t_hi - t_lo) / RESIDUAL_PANELS as f64;
            breaks.extend((1..RESIDUAL_PANELS).map(|i| t_lo + h * i as f64));
        }
    }
    breaks.push(t_hi);
    let mut nodes = Vec::with_capacity(4 * breaks.len());
    for panel in breaks.windows(2) {
        let (c, r) = (0.5 * (panel[0] + panel[1]), 0.5 * (panel[1] - panel[0]));
        for (x, w) in GL4 {
            let t = c + r * x;
            nodes.push((t, output.record.value(t), (output.weight * w * r).sqrt()));
        }
    }
    nodes
}
