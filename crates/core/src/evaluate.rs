//! The evaluation kernels of a [`Problem`]: one integration of each experiment at the
//! unknowns' coordinates z, turned into the least-squares quantities every method needs (ε,
//! U, A, the weighted residuals and their Jacobian, predictions, the measured quantities with
//! bands), stacked over the experiments (integrated in parallel when there are several).
//!
//! A residual row is R = (T(h) − T(b))/σ on the series' scale T. A row whose σ is a function
//! of the unknowns gets a second row √(2 ln σ + c) (c = [`NOISE_ROW_SHIFT`]), so that
//! ε = Σ R² + Σ (2 ln σ + c) is twice the negative log-likelihood up to a constant and still a
//! sum of squares; the normal matrix A is then the Fisher information
//! Σ ∇T(h)∇T(h)ᵀ/σ² + 2 ∇ln σ ∇ln σᵀ, which the Gauss–Newton product JᵀJ of those rows
//! underestimates.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use sysid_ode::{Counts, Integrator, Ivp, Observable, ObservableGradient, OdeError, System};

use crate::confidence::band_half_width;
use crate::experiment::Planned;
use crate::format::shortest;
use crate::noise::{NOISE_ROW_SHIFT, NoiseArgs, NoiseDistribution, NoiseGradient, Transform};
use crate::plan::{Plan, PlannedNoise, Sampled};
use crate::problem::Problem;

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

/// Residuals and Jacobian, each row scaled by 1/σ (the square root of its weight) so that
/// ε = ‖r‖², U = Jᵀr and (without noise functions) A = JᵀJ. For a continuous record the rows
/// are the record at Gauss–Legendre nodes (see [`Problem::residuals_and_jacobian`]).
#[derive(Clone, Debug, PartialEq)]
pub struct WeightedResiduals {
    /// (T(h_o(y(t_m))) − T(b_{o,m}))/σ, series after series, in time order within a series,
    /// experiment after experiment (each followed by its noise rows).
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
    /// A (eq. 15, continuous eq. 24): the Gauss–Newton normal matrix, the Fisher
    /// information (in units of ε/2) where σ is a function of the unknowns.
    pub normal: DMatrix<f64>,
    /// The weighted residuals and their Jacobian (discrete data only).
    pub residuals: Option<WeightedResiduals>,
    /// ‖r‖ as the certificate measures it: the data rows, and each noise row at 1 (its
    /// shifted size depends on an arbitrary constant).
    pub norm: f64,
    /// ε of each experiment's rows.
    pub experiment_costs: Vec<f64>,
    /// Work done.
    pub counts: Counts,
}

impl Linearization {
    /// The decrease of ε the Gauss–Newton model predicts for the step δ from here:
    /// ε − m₀(δ) = −(2Uᵀδ + δᵀAδ).
    pub fn predicted_decrease(&self, delta: &DVector<f64>) -> f64 {
        -(2.0 * self.gradient.dot(delta) + delta.dot(&(&self.normal * delta)))
    }
}

/// One experiment's rows at a point.
pub(crate) struct Rows {
    pub(crate) r: Vec<f64>,
    /// k entries per row of `r`, when asked for.
    pub(crate) jacobian: Vec<f64>,
    /// Fisher rows (k entries each) that replace the function-σ rows in A.
    fisher: Vec<f64>,
    /// Whether each row of `r` enters A directly.
    in_normal: Vec<bool>,
    /// Σ over data rows of R², and the number of noise rows.
    data_cost: f64,
    noise_rows: usize,
    /// The sample (index into the experiment's times) of each row of `r`.
    pub(crate) samples: Vec<usize>,
    pub(crate) counts: Counts,
}

impl<S: System> Planned<S> {
    /// The number of noise rows (samples whose σ is a function of the unknowns).
    pub(crate) fn noise_rows(&self) -> usize {
        self.sampled()
            .series
            .iter()
            .filter(|s| matches!(s.noise, PlannedNoise::Function(_)))
            .map(|s| s.samples.len())
            .sum()
    }

    /// The number of residual rows: a row per sample and a noise row per function-σ sample.
    pub fn n_rows(&self) -> usize {
        self.sampled().series.iter().map(|s| s.samples.len()).sum::<usize>() + self.noise_rows()
    }

    /// The part of the negative log-likelihood that is not ½ ε: ½ ln 2π, ln σ of every
    /// sample whose σ does not vary, and the log scale's ln b or ln(b ln 10) terms; less
    /// c/2 per noise row. None for a continuous record.
    pub fn nll_offset(&self) -> Option<f64> {
        let Plan::Discrete(sampled) = &self.plan else { return None };
        let mut offset = 0.0;
        for s in &sampled.series {
            for m in &s.samples {
                offset += s.distribution.constant() + s.transform.jacobian_term(m.measured);
                offset += match s.noise {
                    PlannedNoise::Function(_) => -0.5 * NOISE_ROW_SHIFT,
                    _ => -m.sqrt_weight.ln(),
                };
            }
        }
        Some(offset)
    }
}

/// What one experiment's evaluation needs from the problem at a point.
pub(crate) struct At<'a> {
    /// The declared unknowns' values.
    pub(crate) v: &'a [f64],
    pub(crate) free_index: &'a [Option<usize>],
    /// d value / d z of the free unknowns.
    pub(crate) chain: &'a [f64],
    pub(crate) integrator: &'a Integrator,
    pub(crate) jacobian: bool,
}

impl<S: System> Problem<S> {
    /// Integrates every experiment with its sensitivities at z and forms ε, U and A: sums over
    /// the samples of discrete data (Goodman's eq. 12, 15), integrals over a continuous record
    /// accumulated during the integration (eq. 22, 24).
    pub fn linearize(&self, z: &[f64]) -> Result<Linearization, OdeError> {
        self.linearize_with(z, &self.integrator)
    }

    /// [`linearize`](Self::linearize) with the experiments integrated by `integrator` (a
    /// [paced](crate::evaluations) step limit); settings computed by integration keep theirs.
    pub(crate) fn linearize_with(
        &self,
        z: &[f64],
        integrator: &Integrator,
    ) -> Result<Linearization, OdeError> {
        if !self.is_continuous() {
            return self.linearize_sampled(z, integrator);
        }
        let k = self.unknowns.len();
        let (v, free_index, chain) = (self.values_at(z), self.free_index(), self.chain(z));
        let mut total = Linearization {
            z: z.to_vec(),
            cost: 0.0,
            gradient: DVector::zeros(k),
            normal: DMatrix::zeros(k, k),
            residuals: None,
            norm: 0.0,
            experiment_costs: Vec::new(),
            counts: Counts::default(),
        };
        for e in &self.experiments {
            let (cost, gradient, normal, counts) = match &e.plan {
                Plan::Continuous { span, outputs, .. } => {
                    let (y0, p) = e.start(&v)?;
                    let sizes = e.sizes(&y0);
                    let q =
                        Ivp::new(e.system(), e.t0, &y0, &p).sized(&sizes).least_squares_integrals(
                            integrator,
                            &e.slots,
                            outputs,
                            *span,
                            self.quadrature_rtol,
                        )?;
                    let dz = slot_matrix(e, &v, &free_index, &chain, k);
                    (q.cost, dz.tr_mul(&q.gradient), dz.tr_mul(&(&q.normal * &dz)), q.counts)
                }
                Plan::Discrete(_) => {
                    let at = At {
                        v: &v,
                        free_index: &free_index,
                        chain: &chain,
                        integrator,
                        jacobian: true,
                    };
                    let rows = experiment_rows(e, &at, k)?;
                    let (u, a) = rows.normal_equations(k);
                    (rows.r.iter().map(|x| x * x).sum(), u, a, rows.counts)
                }
            };
            total.cost += cost;
            total.gradient += gradient;
            total.normal += normal;
            total.experiment_costs.push(cost);
            total.counts += counts;
        }
        total.norm = total.cost.sqrt();
        let span = self.span();
        if !total.cost.is_finite()
            || total.normal.iter().chain(total.gradient.iter()).any(|v| !v.is_finite())
        {
            return Err(OdeError::NonFinite {
                t: span.0,
                what: "the least-squares integrals".into(),
            });
        }
        Ok(total)
    }

    /// The weighted residuals and their Jacobian at z, from one integration with
    /// sensitivities of each experiment: what a general least-squares solver works with.
    /// Discrete data give one row per sample (and a noise row per sample whose σ is a
    /// function of the unknowns). A continuous record gives one row per node of a composite
    /// Gauss–Legendre rule (4 nodes per panel; panels between the samples of a sampled
    /// record, 256 panels over the span for a record
    /// given as a function), so that ‖r‖² is the quadrature of ε.
    pub fn residuals_and_jacobian(&self, z: &[f64]) -> Result<Linearization, OdeError> {
        self.linearize_sampled(z, &self.integrator)
    }

    /// The data of the first experiment in residual form.
    pub fn sampled(&self) -> &Sampled {
        self.experiments[0].sampled()
    }

    fn evaluate_rows(
        &self,
        z: &[f64],
        integrator: &Integrator,
        jacobian: bool,
    ) -> Result<Vec<Rows>, OdeError> {
        let k = self.unknowns.len();
        let (v, free_index, chain) = (self.values_at(z), self.free_index(), self.chain(z));
        let at = At { v: &v, free_index: &free_index, chain: &chain, integrator, jacobian };
        let mut rows = self.each_experiment(|e| experiment_rows(e, &at, k))?;
        rows.extend(self.prior_rows(&at, k));
        Ok(rows)
    }

    /// `f` of every experiment, in order; in parallel where there are several.
    pub(crate) fn each_experiment<T: Send>(
        &self,
        f: impl Fn(&Planned<S>) -> Result<T, OdeError> + Sync,
    ) -> Result<Vec<T>, OdeError> {
        match self.experiments.len() {
            1 => Ok(vec![f(&self.experiments[0])?]),
            _ => self.experiments.par_iter().map(&f).collect(),
        }
    }

    /// The priors' rows (T(θ) − mean)/sd at the point `at`, after the experiments' rows;
    /// none without priors.
    fn prior_rows(&self, at: &At<'_>, k: usize) -> Option<Rows> {
        let mut r = Vec::new();
        let mut jacobian = Vec::new();
        for (j, u) in self.declared.iter().enumerate() {
            // On a Laplace prior's kink the row is 0 with slope 0 (the test the step box and
            // the certificate make).
            let Some((residual, slope)) = u.prior_residual(at.v[j]) else { continue };
            r.push(residual);
            if at.jacobian {
                let mut row = vec![0.0; k];
                if let Some(f) = at.free_index[j] {
                    row[f] = slope * at.chain[f];
                }
                jacobian.extend(row);
            }
        }
        (!r.is_empty()).then(|| Rows {
            data_cost: r.iter().map(|x| x * x).sum(),
            in_normal: vec![true; r.len()],
            r,
            jacobian,
            fisher: Vec::new(),
            noise_rows: 0,
            samples: Vec::new(),
            counts: Counts::default(),
        })
    }

    /// The number of unknowns with a prior (each a residual row after the experiments').
    pub fn n_priors(&self) -> usize {
        self.declared.iter().filter(|u| u.prior.is_some()).count()
    }

    /// The negative log-prior at a linearization's point, ½ Σ r² + Σ ln(sd·√(2π)) over the
    /// priors; None without priors. [`nll`](Self::nll) is the likelihood alone.
    pub fn prior_nll(&self, lin: &Linearization) -> Option<f64> {
        if self.n_priors() == 0 || lin.experiment_costs.len() <= self.experiments.len() {
            return None;
        }
        let offsets: f64 =
            self.declared.iter().filter_map(|u| u.prior.as_ref()).map(|p| p.offset()).sum();
        lin.experiment_costs.last().map(|c| 0.5 * c + offsets)
    }

    /// The negative log-prior at the free unknowns' coordinates z, as
    /// [`prior_nll`](Self::prior_nll) gives it from a linearization; None without priors.
    pub fn prior_nll_at(&self, z: &[f64]) -> Option<f64> {
        let values = self.values_at(z);
        let terms = self.declared.iter().zip(&values).filter_map(|(u, &v)| {
            let (r, _) = u.prior_residual(v)?;
            Some(0.5 * r * r + u.prior.as_ref()?.offset())
        });
        (self.n_priors() > 0).then(|| terms.sum())
    }

    /// The gradient of the priors' term at the free unknowns' coordinates z, with respect to
    /// them: what [`objective_gradient`](Self::objective_gradient) adds to the NLL's. Zeros
    /// without priors.
    pub fn prior_gradient_at(&self, z: &[f64]) -> Vec<f64> {
        let (v, free_index, chain) = (self.values_at(z), self.free_index(), self.chain(z));
        let at = At {
            v: &v,
            free_index: &free_index,
            chain: &chain,
            integrator: &self.integrator,
            jacobian: true,
        };
        // U = Jᵀr of the priors' own rows, as the linearization forms them.
        self.prior_rows(&at, z.len()).map_or_else(|| vec![0.0; z.len()], |r| r.gradient(z.len()))
    }

    /// The gradient of the NLL (`priors` false) or of the objective, the NLL plus the
    /// priors' term, at a linearization's point: with respect to the coordinates z of the
    /// free unknowns, then to those of the noise scales (ln s for a scale on a log scale;
    /// a scale s of σ = s·f enters each of its rows as ln σ + ½ r², r ∝ 1/s, so
    /// ∂/∂s = Σ (1 − r²)/s): the order of [`parameters`](Self::parameters).
    pub fn objective_gradient(&self, lin: &Linearization, priors: bool) -> Vec<f64> {
        let Some(rows) = &lin.residuals else {
            return lin.gradient.iter().copied().collect();
        };
        // The linearization's U = Jᵀr is the objective's gradient; the NLL's leaves out the
        // priors' rows, the last ones.
        let mut g: Vec<f64> = match priors || self.n_priors() == 0 {
            true => lin.gradient.iter().copied().collect(),
            false => {
                let n = rows.r.len() - self.n_priors();
                rows.jacobian.rows(0, n).tr_mul(&rows.r.rows(0, n)).iter().copied().collect()
            }
        };
        g.extend(self.scale_gradient(rows.r.iter().copied()));
        g
    }

    /// The NLL's gradient with respect to the noise scales' coordinates (ln s for a scale on
    /// a log scale), from the residual rows `r` in their order: a scale s of σ = s·f enters
    /// each of its rows as ln σ + ½ r², r ∝ 1/s, so ∂/∂s = Σ (1 − r²)/s. Empty without
    /// scales.
    pub(crate) fn scale_gradient(&self, r: impl Iterator<Item = f64>) -> Vec<f64> {
        if self.scales.is_empty() {
            return Vec::new();
        }
        let sigma = self.scale_values();
        let mut dscale = vec![0.0; sigma.len()];
        for (r, s) in r.zip(self.scale_rows()) {
            if let Some(s) = s {
                dscale[s] += (1.0 - r * r) / sigma[s];
            }
        }
        dscale
            .iter()
            .zip(&self.scales)
            .zip(&sigma)
            .map(|((d, &j), s)| {
                let u = &self.declared[j];
                d * u.scale(u.coordinate(*s))
            })
            .collect()
    }

    /// [`residuals_and_jacobian`](Self::residuals_and_jacobian) with the experiments
    /// integrated by `integrator`.
    pub(crate) fn linearize_sampled(
        &self,
        z: &[f64],
        integrator: &Integrator,
    ) -> Result<Linearization, OdeError> {
        let k = self.unknowns.len();
        let all = self.evaluate_rows(z, integrator, true)?;
        let rows: usize = all.iter().map(|e| e.r.len()).sum();
        let (mut r, mut jacobian) = (Vec::with_capacity(rows), Vec::with_capacity(rows * k));
        let mut counts = Counts::default();
        let (mut data_cost, mut noise_rows) = (0.0, 0);
        for e in &all {
            r.extend_from_slice(&e.r);
            jacobian.extend_from_slice(&e.jacobian);
            counts += e.counts;
            data_cost += e.data_cost;
            noise_rows += e.noise_rows;
        }
        let r = DVector::from_vec(r);
        let jac = DMatrix::from_row_slice(rows, k, &jacobian);
        // JᵀJ, unless rows whose σ is a function of the unknowns call for the Fisher
        // information instead.
        let plain = all.iter().all(|e| e.fisher.is_empty() && e.in_normal.iter().all(|x| *x));
        let normal = match plain {
            true => jac.tr_mul(&jac),
            false => all.iter().map(|e| e.normal_equations(k).1).sum(),
        };
        let experiment_costs = all.iter().map(|e| e.r.iter().map(|x| x * x).sum()).collect();
        Ok(Linearization {
            z: z.to_vec(),
            cost: r.norm_squared(),
            gradient: jac.tr_mul(&r),
            normal,
            residuals: Some(WeightedResiduals { r, jacobian: jac }),
            norm: (data_cost + noise_rows as f64).sqrt(),
            experiment_costs,
            counts,
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
        if !self.is_continuous() {
            let (r, counts) = self.residuals_with(&self.cost_integrator(), z)?;
            return Ok((r.norm_squared(), counts));
        }
        let v = self.values_at(z);
        let (mut cost, mut counts) = (0.0, Counts::default());
        for e in &self.experiments {
            match &e.plan {
                Plan::Continuous { span, outputs, .. } => {
                    let (y0, p) = e.start(&v)?;
                    let sizes = e.sizes(&y0);
                    let q =
                        Ivp::new(e.system(), e.t0, &y0, &p).sized(&sizes).least_squares_integrals(
                            &self.cost_integrator(),
                            &[],
                            outputs,
                            *span,
                            self.quadrature_rtol,
                        )?;
                    cost += q.cost;
                    counts += q.counts;
                }
                Plan::Discrete(_) => {
                    let at = At {
                        v: &v,
                        free_index: &self.free_index(),
                        chain: &self.chain(z),
                        integrator: &self.cost_integrator(),
                        jacobian: false,
                    };
                    let rows = experiment_rows(e, &at, self.unknowns.len())?;
                    cost += rows.r.iter().map(|x| x * x).sum::<f64>();
                    counts += rows.counts;
                }
            }
        }
        if !cost.is_finite() {
            return Err(OdeError::NonFinite { t: self.span().0, what: "the cost".into() });
        }
        Ok((cost, counts))
    }

    /// Number of rows of [`residuals`](Self::residuals): the experiments' and the priors'.
    pub fn n_residuals(&self) -> usize {
        self.experiments.iter().map(|e| e.n_rows()).sum::<usize>() + self.n_priors()
    }

    /// The negative log-likelihood at a linearization's point: ½ ε plus every experiment's
    /// [`nll_offset`](Planned::nll_offset). None for a continuous record.
    pub fn nll(&self, lin: &Linearization) -> Option<f64> {
        self.experiment_nlls(lin).map(|list| list.iter().sum())
    }

    /// The negative log-likelihood at z from a plain integration of the model (no
    /// sensitivities), as [`nll`](Self::nll) gives it from a linearization: for a point
    /// where the sensitivities cannot be integrated but the model can.
    pub fn nll_at(&self, z: &[f64]) -> Result<Option<f64>, OdeError> {
        Ok(self.nll_and_counts(z)?.map(|(nll, _)| nll))
    }

    /// [`nll_at`](Self::nll_at) with the work its integrations did.
    pub fn nll_and_counts(&self, z: &[f64]) -> Result<Option<(f64, Counts)>, OdeError> {
        let rows = self.evaluate_rows(z, &self.integrator, false)?;
        let costs = rows.iter().map(|rows| rows.r.iter().map(|x| x * x).sum::<f64>());
        let mut counts = Counts::default();
        for e in &rows {
            counts += e.counts;
        }
        Ok(self.nlls(costs).map(|list| (list.iter().sum(), counts)))
    }

    /// The negative log-likelihood of each experiment at a linearization's point.
    pub fn experiment_nlls(&self, lin: &Linearization) -> Option<Vec<f64>> {
        self.nlls(lin.experiment_costs.iter().copied())
    }

    /// Each experiment's NLL from its ε (the experiments' costs in order; what follows them,
    /// the priors' rows, is left out).
    pub(crate) fn nlls(&self, costs: impl Iterator<Item = f64>) -> Option<Vec<f64>> {
        self.experiments
            .iter()
            .zip(costs)
            .map(|(e, c)| e.nll_offset().map(|o| 0.5 * c + o))
            .collect()
    }

    /// ∂slot/∂z of experiment `experiment` at z: one row per slot, one column per free
    /// unknown (the chain rule of the settings and of log scales applied).
    pub fn slot_matrix(&self, experiment: usize, z: &[f64]) -> DMatrix<f64> {
        let e = &self.experiments[experiment];
        slot_matrix(e, &self.values_at(z), &self.free_index(), &self.chain(z), self.unknowns.len())
    }

    /// The number of samples whose σ is each noise scale, in the order of
    /// [`scales`](Self::scales).
    pub fn scale_samples(&self) -> Vec<usize> {
        self.scales
            .iter()
            .map(|&j| {
                self.experiments
                    .iter()
                    .flat_map(|e| &e.sampled().series)
                    .filter(
                        |s| matches!(s.noise, PlannedNoise::Scale { unknown, .. } if unknown == j),
                    )
                    .map(|s| s.samples.len())
                    .sum()
            })
            .collect()
    }

    /// The noise scale of each row of [`residuals`](Self::residuals): its index in
    /// [`scales`](Self::scales) for a sample whose σ is s·f with s a noise scale, None for any
    /// other row (other samples, noise rows, priors).
    pub fn scale_rows(&self) -> Vec<Option<usize>> {
        let mut rows = Vec::with_capacity(self.n_residuals());
        for e in &self.experiments {
            for s in &e.sampled().series {
                let g = match s.noise {
                    PlannedNoise::Scale { unknown, .. } => {
                        self.scales.iter().position(|&j| j == unknown)
                    }
                    _ => None,
                };
                rows.extend(std::iter::repeat_n(g, s.samples.len()));
            }
            rows.extend(std::iter::repeat_n(None, e.noise_rows()));
        }
        rows.extend(std::iter::repeat_n(None, self.n_priors()));
        rows
    }

    /// Each noise scale's value given the free unknowns at `values`: ŝ² = mean over its
    /// samples of ((T(h) − T(b))/f)², clamped to the scale's bounds. None where the model
    /// cannot be evaluated.
    pub fn optimal_scales(&self, values: &[f64]) -> Option<Vec<f64>> {
        let z = self.unknowns.coordinates(values);
        let (r, _) = self.residuals(&z).ok()?;
        self.closed_form(&r)
    }

    /// [`optimal_scales`](Self::optimal_scales) at a linearization's point, from its
    /// residuals (weighted at this problem's scales), without an integration. None without
    /// residual rows.
    pub fn scales_at(&self, lin: &Linearization) -> Option<Vec<f64>> {
        self.closed_form(&lin.residuals.as_ref()?.r)
    }

    /// The scales' closed form from the residual rows `r`, weighted at the held scales.
    fn closed_form(&self, r: &DVector<f64>) -> Option<Vec<f64>> {
        self.closed_form_of(&self.scale_sums(r))
    }

    /// Per noise scale, over its rows of `r` (weighted at the held scale s): Σ (r s)², the
    /// squared scaled residuals (r = (T(h) − T(b))/(s f)), and the number of rows.
    fn scale_sums(&self, r: &DVector<f64>) -> Vec<(f64, usize)> {
        let mut sums = vec![(0.0, 0usize); self.scales.len()];
        for (r, g) in r.iter().zip(self.scale_rows()) {
            if let Some(g) = g {
                sums[g].0 += (r * self.held[self.scales[g]]).powi(2);
                sums[g].1 += 1;
            }
        }
        sums
    }

    /// The closed form from [`scale_sums`](Self::scale_sums): ŝ² = Σ (r s)²/n, clamped to
    /// the scale's bounds.
    fn closed_form_of(&self, sums: &[(f64, usize)]) -> Option<Vec<f64>> {
        let out: Vec<f64> = sums
            .iter()
            .zip(&self.scales)
            .map(|(&(sum, n), &j)| {
                let u = &self.declared[j];
                let lo = u.min.unwrap_or(0.0).max(f64::MIN_POSITIVE);
                (sum / n as f64).sqrt().clamp(lo, u.max.unwrap_or(f64::INFINITY))
            })
            .collect();
        out.iter().all(|v| v.is_finite() && *v > 0.0).then_some(out)
    }

    /// `lin`, made at this problem's scales, as it is at the scales `sigma` (one per
    /// [`scales`](Self::scales)), without an integration: each row of scale g is
    /// (T(h) − T(b))/(s_g f), so it and its Jacobian row are multiplied by c = s_g/σ_g; ε, U
    /// and the experiments' ε are summed again from the rows, and A and ‖r‖ change by
    /// (c² − 1) times each such row's terms (A may hold Fisher rows of other samples, which
    /// the scales do not touch). `lin` unchanged where it has no residual rows.
    pub fn reweighed(&self, lin: &Linearization, sigma: &[f64]) -> Linearization {
        let mut out = lin.clone();
        let Some(res) = out.residuals.as_mut() else { return out };
        let factor: Vec<f64> =
            self.scales.iter().zip(sigma).map(|(&j, s)| self.held[j] / s).collect();
        let mut norm2 = lin.norm * lin.norm;
        for (i, g) in self.scale_rows().into_iter().enumerate() {
            let Some(c) = g.map(|g| factor[g]) else { continue };
            let r = res.r[i];
            let row = res.jacobian.row(i).transpose();
            norm2 += (c * c - 1.0) * r * r;
            out.normal.ger(c * c - 1.0, &row, &row, 1.0);
            res.r[i] *= c;
            res.jacobian.row_mut(i).scale_mut(c);
        }
        // Each experiment's rows (its samples and noise rows), then the priors' (last).
        let mut from = 0;
        let rows = self.experiments.iter().map(|e| e.n_rows()).chain([res.r.len()]);
        for (cost, n) in out.experiment_costs.iter_mut().zip(rows) {
            let to = (from + n).min(res.r.len());
            *cost = res.r.as_slice()[from..to].iter().map(|x| x * x).sum();
            from = to;
        }
        out.cost = res.r.norm_squared();
        out.gradient = res.jacobian.tr_mul(&res.r);
        out.norm = norm2.max(0.0).sqrt();
        out
    }

    /// Under hierarchical optimisation (the scales at their closed form ŝ(z) at every
    /// point), what the scales take from A in the profile's Gauss–Newton model: with ε_g the
    /// ε of scale g's rows and U_g their part of U, ε_g = n_g at ŝ, and
    /// n_g ln(ε_g(z + δ)/n_g) = 2U_gᵀδ + δᵀ(A_g − 2U_gU_gᵀ/n_g)δ + O(δ³), so the profile's
    /// model is A − Σ_g 2U_gU_gᵀ/n_g (indefinite along the rows' own residuals: scaling them
    /// all costs the profile nothing). Returns that sum over the scales whose closed form at
    /// `lin` is inside their bounds (a scale held on a bound is not profiled); None when
    /// there is none, or no residual rows.
    pub fn profile_curvature(&self, lin: &Linearization) -> Option<DMatrix<f64>> {
        let res = lin.residuals.as_ref()?;
        let k = res.jacobian.ncols();
        let mut u = vec![DVector::zeros(k); self.scales.len()];
        for (i, g) in self.scale_rows().into_iter().enumerate() {
            if let Some(g) = g {
                u[g].axpy(res.r[i], &res.jacobian.row(i).transpose(), 1.0);
            }
        }
        let mut out: Option<DMatrix<f64>> = None;
        for ((&(sum, n), u), &j) in self.scale_sums(&res.r).iter().zip(&u).zip(&self.scales) {
            // ε_g = Σ (r s)²/s²: n at the closed form, unless the scale is held on a bound.
            let (cost, n) = (sum / self.held[j].powi(2), n as f64);
            if n == 0.0 || (cost - n).abs() > 1e-6 * n {
                continue;
            }
            out.get_or_insert_with(|| DMatrix::zeros(k, k)).ger(2.0 / n, u, u, 1.0);
        }
        out
    }

    /// What moving the scales from this problem's s to their closed form σ at the trial
    /// point `lin` (evaluated at s) lowers ε by, in ε's units (twice the NLL): with ε_g the
    /// ε of scale g's rows there, Σ_g ε_g (1 − (s_g/σ_g)²) − 2 n_g ln(σ_g/s_g) ≥ 0 (σ_g
    /// minimises it; clamped to its bounds it still lowers it). 0 without scales.
    pub fn profile_gain(&self, lin: &Linearization) -> f64 {
        lin.residuals.as_ref().map_or(0.0, |res| self.profile_gain_of(&res.r))
    }

    /// [`profile_gain`](Self::profile_gain) from the weighted residuals `r` at the trial
    /// point (evaluated at s), as [`residuals`](Self::residuals) gives them.
    pub fn profile_gain_of(&self, r: &DVector<f64>) -> f64 {
        self.gain_terms(r).iter().map(|&(gain, _)| gain).sum::<f64>().max(0.0)
    }

    /// [`profile_gain`](Self::profile_gain) at `lin` in two parts: from the scales whose
    /// closed form there is below the held value (the data fitted more closely than the held
    /// scales say: the weights would grow), and from the others (0 without residual rows).
    pub fn split_gain(&self, lin: &Linearization) -> (f64, f64) {
        let Some(res) = lin.residuals.as_ref() else { return (0.0, 0.0) };
        let terms = self.gain_terms(&res.r);
        let part = |tightens: bool| {
            terms.iter().filter(|t| t.1 == tightens).map(|t| t.0).sum::<f64>().max(0.0)
        };
        (part(true), part(false))
    }

    /// Per scale g, in order: what moving it from s_g to its closed form σ_g lowers ε by,
    /// ε_g (1 − (s_g/σ_g)²) − 2 n_g ln(σ_g/s_g) (≥ 0 up to rounding), and whether σ_g < s_g.
    /// Empty where the closed form cannot be formed.
    fn gain_terms(&self, r: &DVector<f64>) -> Vec<(f64, bool)> {
        let sums = self.scale_sums(r);
        let Some(sigma) = self.closed_form_of(&sums) else { return Vec::new() };
        sums.iter()
            .zip(&sigma)
            .zip(&self.scales)
            .map(|((&(sum, n), &sigma), &j)| {
                let (s, ratio) = (self.held[j], self.held[j] / sigma);
                (sum / (s * s) * (1.0 - ratio * ratio) + 2.0 * n as f64 * ratio.ln(), sigma < s)
            })
            .collect()
    }

    /// The weighted residual vector at z, without sensitivities: the rows of
    /// [`residuals_and_jacobian`](Self::residuals_and_jacobian).
    pub fn residuals(&self, z: &[f64]) -> Result<(DVector<f64>, Counts), OdeError> {
        self.residuals_with(&self.integrator, z)
    }

    /// [`residuals`](Self::residuals) with the experiments integrated by `integrator`.
    pub(crate) fn residuals_with(
        &self,
        integrator: &Integrator,
        z: &[f64],
    ) -> Result<(DVector<f64>, Counts), OdeError> {
        let all = self.evaluate_rows(z, integrator, false)?;
        let mut counts = Counts::default();
        let mut r = Vec::with_capacity(self.n_residuals());
        for e in all {
            r.extend(e.r);
            counts += e.counts;
        }
        Ok((DVector::from_vec(r), counts))
    }

    /// The model's values h_o(t_m) of every measured quantity at z (untransformed), one per
    /// sample in the order of the residual rows (without the noise rows), from a plain
    /// integration 10 times tighter than the fits use: what noise-free data at z would be.
    pub fn predictions(&self, z: &[f64]) -> Result<Vec<f64>, OdeError> {
        self.model_values(z).map(|(h, _)| h)
    }

    /// The noise's σ of every sample at z, in the order of [`predictions`](Self::predictions):
    /// 1/√w for relative weights, the known σ, the noise scale times its factor, or the noise
    /// function evaluated at the model's states and value there.
    pub fn sigmas(&self, z: &[f64]) -> Result<Vec<f64>, OdeError> {
        self.model_values(z).map(|(_, sigma)| sigma)
    }

    /// [`predictions`](Self::predictions) and [`sigmas`](Self::sigmas) from one integration.
    fn model_values(&self, z: &[f64]) -> Result<(Vec<f64>, Vec<f64>), OdeError> {
        let v = self.values_at(z);
        let (mut h, mut sigma) = (Vec::new(), Vec::new());
        for e in &self.experiments {
            let (y0, p) = e.start(&v)?;
            let sampled = e.sampled();
            let sizes = e.sizes(&y0);
            let sol = Ivp::new(e.system(), e.t0, &y0, &p)
                .sized(&sizes)
                .solve(&self.cost_integrator(), &sampled.times)?;
            let mut og = ObservableGradient::new(e.system(), &p, &[]);
            let (n, np) = (y0.len(), p.len());
            for s in &sampled.series {
                for sample in &s.samples {
                    let (t, y) = (sampled.times[sample.index], sol.state(sample.index));
                    let value = og.eval(t, y, &[], s.observable, &mut []);
                    h.push(value);
                    sigma.push(match &s.noise {
                        PlannedNoise::Function(f) => {
                            let (mut dy, mut dp, mut dv) =
                                (vec![0.0; n], vec![0.0; np], vec![0.0; v.len()]);
                            let mut g =
                                NoiseGradient { y: &mut dy, h: 0.0, p: &mut dp, v: &mut dv };
                            f.eval(NoiseArgs { t, y, h: value, p: &p, v: &v }, &mut g)
                        }
                        _ => 1.0 / sample.sqrt_weight,
                    });
                }
            }
        }
        if let Some(i) = h.iter().position(|v| !v.is_finite()) {
            return Err(OdeError::NonFinite { t: self.span().0, what: format!("prediction {i}") });
        }
        Ok((h, sigma))
    }

    /// Every measured quantity of the first experiment at `values` of the unknowns, at
    /// `times` (sorted; on either side of t0), with the half-width of its 95 % band from
    /// `band`, the covariance of the values and the t quantile of the fit's degrees of
    /// freedom ([`Estimate::band`](crate::Estimate::band)): t √(g Cov gᵀ), g = ∂h/∂(values)
    /// from the sensitivities. What a fit predicts for the measurements, with its
    /// uncertainty. Values that are not one per unknown, or a covariance that is not k × k
    /// (k unknowns), are an error ([`OdeError::Dimension`]).
    pub fn observed(
        &self,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
    ) -> Result<Vec<Observed>, OdeError> {
        self.observed_in(0, values, band, times)
    }

    /// [`observed`](Self::observed) for experiment `experiment`.
    ///
    /// # Panics
    ///
    /// Where `experiment` is not an index of [`experiments`](Self::experiments).
    pub fn observed_in(
        &self,
        experiment: usize,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
    ) -> Result<Vec<Observed>, OdeError> {
        let e = &self.experiments[experiment];
        let signature = e.system().signature();
        let quantities: Vec<(String, Observable)> = e
            .sampled()
            .series
            .iter()
            .map(|series| {
                let name = match series.observable {
                    Observable::State(i) => signature.states()[i].clone(),
                    Observable::Output(i) => signature.outputs()[i].clone(),
                };
                (name, series.observable)
            })
            .collect();
        self.along(experiment, values, band, times, &quantities)
    }

    /// Every state of experiment `experiment` at `values` of the unknowns, at `times`, with
    /// the half-width of its 95 % band, as [`observed`](Self::observed) gives the measured
    /// quantities: the trajectory a fit predicts.
    ///
    /// # Panics
    ///
    /// Where `experiment` is not an index of [`experiments`](Self::experiments).
    pub fn trajectory(
        &self,
        experiment: usize,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
    ) -> Result<Vec<Observed>, OdeError> {
        let states = self.experiments[experiment].system.signature().states();
        let quantities: Vec<(String, Observable)> =
            states.iter().enumerate().map(|(i, n)| (n.clone(), Observable::State(i))).collect();
        self.along(experiment, values, band, times, &quantities)
    }

    fn along(
        &self,
        experiment: usize,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
        quantities: &[(String, Observable)],
    ) -> Result<Vec<Observed>, OdeError> {
        let e = &self.experiments[experiment];
        let k = self.unknowns.len();
        let dimension = |what, actual| Err(OdeError::Dimension { what, actual, expected: k });
        if values.len() != k {
            return dimension("the values of the unknowns", values.len());
        }
        if let Some((cov, _)) = band {
            for (what, actual) in
                [("the covariance (rows)", cov.nrows()), ("the covariance (columns)", cov.ncols())]
            {
                if actual != k {
                    return dimension(what, actual);
                }
            }
        }
        let z = self.unknowns.coordinates(values);
        let v = self.values_at(&z);
        let (y0, p) = e.start(&v)?;
        let sizes = e.sizes(&y0);
        let sol = Ivp::new(e.system(), e.t0, &y0, &p).sized(&sizes).solve_sensitivities(
            &self.integrator,
            &e.slots,
            times,
        )?;
        // ∂slot/∂value of the free unknowns (the band is in values, not coordinates).
        let dv = slot_matrix(e, &v, &self.free_index(), &vec![1.0; k], k);
        let mut og = ObservableGradient::new(e.system(), &p, &e.slots);
        let mut grad_slots = vec![0.0; e.slots.len()];
        let mut out = Vec::new();
        for (name, observable) in quantities {
            let mut observed = Observed {
                name: name.clone(),
                values: Vec::with_capacity(times.len()),
                half_width: band.map(|_| Vec::with_capacity(times.len())),
            };
            for (m, &t) in times.iter().enumerate() {
                let s = sol.sensitivity_slice(m);
                let h = og.eval(t, sol.state(m), s, *observable, &mut grad_slots);
                observed.values.push(h);
                if let (Some((cov, q)), Some(w)) = (band, observed.half_width.as_mut()) {
                    let g = dv.tr_mul(&DVector::from_column_slice(&grad_slots));
                    w.push(band_half_width(q, &g, cov));
                }
            }
            out.push(observed);
        }
        Ok(out)
    }
}

/// ∂slot/∂z of experiment `e` as a dense slots × k matrix: the slot Jacobian times the chain
/// of each free unknown.
/// Per slot (row of ∂slot/∂z), the most any free coordinate moves it, max_j |∂slot/∂z_j|:
/// the factor of its sensitivity column in the Jacobian the fit uses (a log-scale unknown's
/// value, 1 on a linear scale), which the integration's error control measures it in.
fn coordinate_weights(dz: &DMatrix<f64>) -> Vec<f64> {
    dz.row_iter().map(|row| row.iter().fold(0.0_f64, |m, x| m.max(x.abs()))).collect()
}

pub(crate) fn slot_matrix<S: System>(
    e: &Planned<S>,
    v: &[f64],
    free_index: &[Option<usize>],
    chain: &[f64],
    k: usize,
) -> DMatrix<f64> {
    let sparse = e.slot_jacobian(v, free_index);
    let mut d = DMatrix::zeros(sparse.len(), k);
    for (s, row) in sparse.iter().enumerate() {
        for &(f, x) in row {
            d[(s, f)] += x * chain[f];
        }
    }
    d
}

impl Rows {
    /// Drops the rows' derivatives (J's and the Fisher rows), keeping the residuals, their
    /// samples and the work: what a gradient's caller reads once U is formed.
    pub(crate) fn forget_derivatives(&mut self) {
        self.jacobian = Vec::new();
        self.fisher = Vec::new();
    }

    /// U = Jᵀr over these rows (k columns).
    pub(crate) fn gradient(&self, k: usize) -> Vec<f64> {
        let mut u = vec![0.0; k];
        for (r, row) in self.r.iter().zip(self.jacobian.chunks(k)) {
            u.iter_mut().zip(row).for_each(|(u, j)| *u += r * j);
        }
        u
    }

    /// U = Jᵀr and A: JᵀJ over the rows that enter it directly, plus the Fisher rows.
    fn normal_equations(&self, k: usize) -> (DVector<f64>, DMatrix<f64>) {
        let u = DVector::from_vec(self.gradient(k));
        let mut a = DMatrix::zeros(k, k);
        let add = |row: &[f64], a: &mut DMatrix<f64>| {
            for i in 0..k {
                if row[i] == 0.0 {
                    continue;
                }
                for j in 0..k {
                    a[(i, j)] += row[i] * row[j];
                }
            }
        };
        for (row, _) in self.jacobian.chunks(k).zip(&self.in_normal).filter(|(_, direct)| **direct)
        {
            add(row, &mut a);
        }
        for row in self.fisher.chunks(k) {
            add(row, &mut a);
        }
        (u, a)
    }
}

/// An experiment's integration: the states, with their sensitivities when asked for.
enum Solved {
    States(sysid_ode::Trajectory),
    Sensitivities(sysid_ode::SensitivityTrajectory),
}

/// The rows of one experiment at a point: a row per sample (data rows, series after series)
/// and then a noise row per function-σ sample; with their Jacobian in the free unknowns'
/// coordinates when asked for.
pub(crate) fn experiment_rows<S: System>(
    e: &Planned<S>,
    at: &At<'_>,
    k: usize,
) -> Result<Rows, OdeError> {
    let (y0, p) = e.start(at.v)?;
    let times = &e.sampled().times;
    let sizes = e.sizes(&y0);
    let ivp = Ivp::new(e.system(), e.t0, &y0, &p).sized(&sizes);
    let slots: &[sysid_ode::Wrt] = if at.jacobian { &e.slots } else { &[] };
    // ∂slot/∂z; the identity (slot j is free unknown j) leaves the gradients as they are.
    let dz = at.jacobian.then(|| slot_matrix(e, at.v, at.free_index, at.chain, k));
    // The states and (when asked) their sensitivities to the slots at every sample time,
    // each column's error controlled in the fit's coordinates.
    let solved = match &dz {
        Some(d) => {
            let weights = coordinate_weights(d);
            let sol = ivp.weighted(&weights).solve_sensitivities(at.integrator, slots, times)?;
            Solved::Sensitivities(sol)
        }
        None => Solved::States(ivp.solve(at.integrator, times)?),
    };
    let counts = match &solved {
        Solved::Sensitivities(sol) => sol.counts(),
        Solved::States(sol) => sol.counts(),
    };
    let point = |m: usize| match &solved {
        Solved::Sensitivities(sol) => (sol.state(m), sol.sensitivity_slice(m)),
        Solved::States(sol) => (sol.state(m), &[][..]),
    };
    let mut rows = sample_rows(e, at, (&p, slots, dz.as_ref()), point)?;
    rows.counts = counts;
    Ok(rows)
}

/// The error of a sample's residual r that is not finite, or whose square (its term of the
/// NLL) overflows, at time `t`: named by its observable and experiment, how it is weighed
/// (`weighed`), the model's value and the datum. The model integrated: not an integration's
/// failure.
fn unrepresentable(
    t: f64,
    (observable, experiment): (&str, &str),
    r: f64,
    weighed: &str,
    (model, datum): (f64, f64),
) -> OdeError {
    let residual =
        format!("the residual of the observable `{observable}` of experiment `{experiment}`");
    let (model, datum) = (shortest(model), shortest(datum));
    let what = match r.is_finite() {
        true => format!(
            "the square of {residual} ({}: {weighed}; the model gives {model}, the datum is {datum}) overflows",
            shortest(r)
        ),
        false => format!(
            "{residual} ({weighed}; the model gives {model}, the datum is {datum}) is not finite"
        ),
    };
    OdeError::Unrepresentable { t, what }
}

/// The rows of experiment `e` from its states and sensitivities at the sample times
/// (`point(m)`: y(t_m) and S(t_m), n × `slots.len()` row by row, or empty without a
/// Jacobian), with parameters `p` and the slots' Jacobian `dz` (slots × columns): a row's
/// Jacobian entry j is ∂R/∂(column j), through the slots and directly through the unknowns'
/// values (the noise functions' ∂σ/∂v, in the first `at.chain.len()` columns).
pub(crate) fn sample_rows<'s, S: System>(
    e: &Planned<S>,
    at: &At<'_>,
    (p, slots, dz): (&[f64], &[sysid_ode::Wrt], Option<&DMatrix<f64>>),
    point: impl Fn(usize) -> (&'s [f64], &'s [f64]),
) -> Result<Rows, OdeError> {
    let sampled = e.sampled();
    let times = &sampled.times;
    let n = e.system().signature().n_states();
    let ns = slots.len();
    let k = dz.map_or(0, |d| d.ncols());
    let jacobian = dz.is_some();
    let identity = dz.is_some_and(|d| {
        d.nrows() == k
            && (0..k).all(|i| (0..k).all(|j| if i == j { true } else { d[(i, j)] == 0.0 }))
    });
    let mut og = ObservableGradient::new(e.system(), p, slots);
    let mut grad_slots = vec![0.0; ns];
    let mut grad = vec![0.0; k];
    let total: usize = sampled.series.iter().map(|s| s.samples.len()).sum();
    let mut out = Rows {
        r: Vec::with_capacity(total),
        jacobian: Vec::with_capacity(if jacobian { total * k } else { 0 }),
        fisher: Vec::new(),
        in_normal: Vec::with_capacity(total),
        data_cost: 0.0,
        noise_rows: 0,
        samples: Vec::with_capacity(total),
        counts: Counts::default(),
    };
    let mut noise: Vec<(usize, f64, Vec<f64>)> = Vec::new();
    let np = p.len();
    let (mut dy, mut dp, mut dv) = (vec![0.0; n], vec![0.0; np], vec![0.0; at.v.len()]);
    let mut ds_slot = vec![0.0; ns];
    for s in &sampled.series {
        for sample in &s.samples {
            let m = sample.index;
            let (y, sm) = point(m);
            let h = og.eval(times[m], y, sm, s.observable, &mut grad_slots);
            // ∂h/∂z.
            if let Some(d) = dz {
                if identity {
                    for j in 0..k {
                        grad[j] = grad_slots[j] * d[(j, j)];
                    }
                } else {
                    for (j, g) in grad.iter_mut().enumerate() {
                        *g = (0..ns).map(|q| grad_slots[q] * d[(q, j)]).sum();
                    }
                }
            }
            let (th, slope) = (s.transform.apply(h), s.transform.derivative(h));
            if !th.is_finite() {
                // Named here: the end's check can only count rows.
                let mut what = format!(
                    "the observable `{}` of experiment `{}`",
                    s.observable_name(e.system()),
                    e.name
                );
                if s.transform != Transform::Lin {
                    what +=
                        &format!(" on its {} scale (the model gives {h:e})", s.transform.name());
                }
                return Err(OdeError::NonFinite { t: times[m], what });
            }
            let laplace = s.distribution == NoiseDistribution::Laplace;
            let PlannedNoise::Function(f) = &s.noise else {
                // Normal: R = √w·d. Laplace: R = sign(d)·√(2|d|/b), and A takes the Fisher
                // information ∇T(h)/b in place of the row, whose entries grow without bound
                // as d goes to 0.
                let w = sample.sqrt_weight;
                let (r, dr) = s.distribution.residual(th - sample.value, w);
                if !(r * r).is_finite() {
                    // A noise scale of 0 or ∞ (a weight of ∞ or 0), or near 0 so that the
                    // residual's square, the NLL's term, overflows.
                    let weighed = format!("the square root of its weight {}", shortest(w));
                    let name = s.observable_name(e.system());
                    let observable = (name.as_str(), e.name.as_str());
                    return Err(unrepresentable(
                        times[m],
                        observable,
                        r,
                        &weighed,
                        (th, sample.value),
                    ));
                }
                out.r.push(r);
                out.samples.push(m);
                out.data_cost += r * r;
                out.in_normal.push(!laplace);
                if jacobian {
                    out.jacobian.extend(grad.iter().map(|g| dr * slope * g));
                    if laplace {
                        out.fisher.extend(grad.iter().map(|g| w * slope * g));
                    }
                }
                continue;
            };
            dy.iter_mut().for_each(|x| *x = 0.0);
            dp.iter_mut().for_each(|x| *x = 0.0);
            dv.iter_mut().for_each(|x| *x = 0.0);
            let mut gradient = NoiseGradient { y: &mut dy, h: 0.0, p: &mut dp, v: &mut dv };
            let args = NoiseArgs { t: times[m], y, h, p, v: at.v };
            let sigma = f.eval(args, &mut gradient);
            let dh = gradient.h;
            if !(sigma > 0.0 && sigma.is_finite()) {
                return Err(OdeError::NonFinite {
                    t: times[m],
                    what: format!(
                        "σ = {} of `{}` is {sigma}",
                        f.describe(),
                        s.observable_name(e.system())
                    ),
                });
            }
            let diff = th - sample.value;
            // Normal: R = d/σ. Laplace (σ the scale b): R = sign(d)·√(2|d|/b), ∂R/∂d =
            // 1/√(2|d|b), so that ∂R/∂z = ∂R/∂d·(∂T(h)/∂z − d ∂b/∂z / b) in both.
            let (r, dr) = match laplace {
                true => s.distribution.residual(diff, 1.0 / sigma),
                false => (diff / sigma, 1.0 / sigma),
            };
            if !(r * r).is_finite() {
                let weighed = format!("σ = {}", shortest(sigma));
                let name = s.observable_name(e.system());
                let observable = (name.as_str(), e.name.as_str());
                return Err(unrepresentable(times[m], observable, r, &weighed, (th, sample.value)));
            }
            out.r.push(r);
            out.samples.push(m);
            out.data_cost += r * r;
            out.in_normal.push(false);
            let b2 = 2.0 * sigma.ln() + NOISE_ROW_SHIFT;
            if b2.is_nan() || b2 <= 0.0 {
                // Not an integration's failure: the model integrated.
                return Err(OdeError::Unrepresentable {
                    t: times[m],
                    what: format!(
                        "σ = {sigma:e} of `{}` lies below {}",
                        s.observable_name(e.system()),
                        crate::noise::least_sigma().1
                    ),
                });
            }
            let b = b2.sqrt();
            let mut dsigma = vec![0.0; k];
            if let Some(d) = dz {
                // ∂σ/∂z through the states, the value, the parameters and the unknowns: first
                // ∂σ/∂slot directly and through the states, then through the slots to z.
                for (q, w) in slots.iter().enumerate() {
                    ds_slot[q] = match *w {
                        sysid_ode::Wrt::InitialValue(_) => 0.0,
                        sysid_ode::Wrt::Parameter(kp) => dp[kp],
                    } + (0..n).map(|i| dy[i] * sm[i * ns + q]).sum::<f64>();
                }
                for (j, ds) in dsigma.iter_mut().enumerate() {
                    *ds = dh * grad[j]
                        + ds_slot.iter().enumerate().map(|(q, s)| s * d[(q, j)]).sum::<f64>();
                }
                let free: Vec<(usize, usize)> = at
                    .free_index
                    .iter()
                    .enumerate()
                    .filter_map(|(decl, f)| f.map(|f| (decl, f)))
                    .collect();
                for (decl, f) in free {
                    dsigma[f] += dv[decl] * at.chain[f];
                }
                if laplace {
                    out.jacobian
                        .extend((0..k).map(|j| dr * (slope * grad[j] - diff * dsigma[j] / sigma)));
                } else {
                    out.jacobian.extend((0..k).map(|j| (slope * grad[j] - r * dsigma[j]) / sigma));
                }
                // Fisher rows: ∇T(h)/σ, and √2 ∇ln σ (normal) or ∇ln b (Laplace).
                let ln_scale = if laplace { 1.0 } else { std::f64::consts::SQRT_2 };
                out.fisher.extend((0..k).map(|j| slope * grad[j] / sigma));
                out.fisher.extend((0..k).map(|j| ln_scale * dsigma[j] / sigma));
            }
            noise.push((m, b, dsigma.iter().map(|d| d / (sigma * b)).collect()));
        }
    }
    out.noise_rows = noise.len();
    for (m, b, row) in noise {
        out.r.push(b);
        out.samples.push(m);
        out.in_normal.push(false);
        if jacobian {
            out.jacobian.extend(row);
        }
    }
    if let Some(i) = out.r.iter().position(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite {
            t: times.first().copied().unwrap_or(e.t0),
            what: format!("residual {i}"),
        });
    }
    if out.jacobian.iter().any(|v| !v.is_finite()) {
        return Err(OdeError::NonFinite {
            t: times.first().copied().unwrap_or(e.t0),
            what: "the residual Jacobian".into(),
        });
    }
    Ok(out)
}
