//! The evaluation kernels of a [`Problem`]: one integration of the model at the unknowns'
//! coordinates z, turned into the least-squares quantities every method needs (ε, U, A, the
//! weighted residuals and their Jacobian, predictions, the measured quantities with bands).

use nalgebra::{DMatrix, DVector};
use sysid_ode::{Counts, Integrator, Ivp, Observable, ObservableGradient, OdeError, System};

use crate::confidence::band_half_width;
use crate::plan::{Plan, Sampled};
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
    /// on either side of t0), with the half-width of its 95 % band from `band`, the
    /// covariance of the values and the t quantile of the fit's degrees of freedom
    /// ([`Estimate::band`](crate::Estimate::band)): t √(g Cov gᵀ), g = ∂h/∂(values) from the
    /// sensitivities. What a fit predicts for the measurements, with its uncertainty.
    pub fn observed(
        &self,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
    ) -> Result<Vec<Observed>, OdeError> {
        let signature = self.system.signature();
        let quantities: Vec<(String, Observable)> = self
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
        self.along(values, band, times, &quantities)
    }

    /// Every state of the model at `values` of the unknowns, at `times`, with the
    /// half-width of its 95 % band, as [`observed`](Self::observed) gives the measured
    /// quantities: the trajectory a fit predicts.
    pub fn trajectory(
        &self,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
    ) -> Result<Vec<Observed>, OdeError> {
        let states = self.system.signature().states();
        let quantities: Vec<(String, Observable)> =
            states.iter().enumerate().map(|(i, n)| (n.clone(), Observable::State(i))).collect();
        self.along(values, band, times, &quantities)
    }

    fn along(
        &self,
        values: &[f64],
        band: Option<(&DMatrix<f64>, f64)>,
        times: &[f64],
        quantities: &[(String, Observable)],
    ) -> Result<Vec<Observed>, OdeError> {
        let z = self.unknowns.coordinates(values);
        let (y0, p) = self.point(&z);
        let wrt = self.unknowns.wrt();
        let sol = Ivp::new(&self.system, self.t0, &y0, &p).solve_sensitivities(
            &self.integrator,
            wrt,
            times,
        )?;
        let mut og = ObservableGradient::new(&self.system, &p, wrt);
        let mut grad = vec![0.0; wrt.len()];
        let mut out = Vec::new();
        for (name, observable) in quantities {
            let mut observed = Observed {
                name: name.clone(),
                values: Vec::with_capacity(times.len()),
                half_width: band.map(|_| Vec::with_capacity(times.len())),
            };
            for (m, &t) in times.iter().enumerate() {
                let s = sol.sensitivity_slice(m);
                let h = og.eval(t, sol.state(m), s, *observable, &mut grad);
                observed.values.push(h);
                if let (Some((cov, q)), Some(w)) = (band, observed.half_width.as_mut()) {
                    w.push(band_half_width(q, &DVector::from_column_slice(&grad), cov));
                }
            }
            out.push(observed);
        }
        Ok(out)
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
