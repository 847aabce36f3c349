//! What a study repeats: a problem whose data are the model at the truth plus noise of known
//! standard deviation, sample by sample.

use nalgebra::DMatrix;
use rand::Rng;
use rand_distr::StandardNormal;
use sysid_core::{Data, Problem, Samples, Series, Transform, method::NormalFactor};
use sysid_ode::{OdeError, System};
use sysid_systems::{Case, DataSource};

use crate::error::StudyError;

/// A problem template (model, knowns, unknowns with their bounds and scales, integrator, the
/// measurement times and weights), the true values of the unknowns, the noise-free data and
/// the standard deviation of the noise on every sample.
#[derive(Clone, Debug)]
pub struct Scenario<S> {
    base: Problem<S>,
    truth: Vec<f64>,
    /// Noise-free values, one per sample, series after series in data order.
    clean: Vec<f64>,
    /// σ of each sample, in the same order.
    sigma: Vec<f64>,
}

impl<S: System + Clone> Scenario<S> {
    /// A scenario from its parts. `sigma` has one entry per measured value, series after
    /// series in the order of `base`'s data; the noise-free data are the model at `truth`
    /// (values of the unknowns), integrated 10 times tighter than the fits.
    pub fn new(base: Problem<S>, truth: Vec<f64>, sigma: Vec<f64>) -> Result<Self, StudyError> {
        let clean = predictions(&base, &truth)?;
        Self::build(base, truth, clean, sigma)
    }

    fn build(
        base: Problem<S>,
        truth: Vec<f64>,
        clean: Vec<f64>,
        sigma: Vec<f64>,
    ) -> Result<Self, StudyError> {
        if sigma.len() != clean.len() {
            return Err(StudyError::Setup(format!(
                "{} noise levels for {} measured values",
                sigma.len(),
                clean.len()
            )));
        }
        if let Some(i) = sigma.iter().position(|s| !(*s >= 0.0 && s.is_finite())) {
            return Err(StudyError::Setup(format!("noise level {i} is {}", sigma[i])));
        }
        Ok(Self { base, truth, clean, sigma })
    }

    /// A catalogue case. Synthetic data keep their noise model (σ, or σ·|y| for relative
    /// noise); fixed data (a published table) get the noise their reference fit leaves,
    /// σ_m = s / √w_m with s² = ε / (N − k), around the reference answer.
    pub fn from_case(case: &Case<S>) -> Result<Self, StudyError> {
        let problem = case.problem(1).map_err(|e| StudyError::Setup(e.to_string()))?;
        let truth = case.expected_values().ok_or_else(|| {
            StudyError::Setup(format!("{}: no true values or reference answer", case.name))
        })?;
        match &case.data {
            DataSource::Synthetic { noise, .. } => {
                // The data's series follow the noise list; relative σ refers to the truth.
                let truth_problem = problem.clone().with_integrator(case.truth_integrator())?;
                let clean = predictions(&truth_problem, &truth)?;
                let mut sigma = Vec::with_capacity(clean.len());
                let mut at = 0;
                for (series, n) in problem.data().series.iter().zip(noise) {
                    let count = sample_count(series);
                    for y in &clean[at..at + count] {
                        sigma.push(if n.relative { n.sigma * y.abs() } else { n.sigma });
                    }
                    at += count;
                }
                Self::build(problem, truth, clean, sigma)
            }
            DataSource::Fixed(_) => Self::from_residuals(problem, truth),
        }
    }

    /// Noise as the data of `problem` show it around `truth` (for example a fit of a model
    /// file): with a noise model, each sample's σ from it at the truth (noise scales at the
    /// values `problem` holds them at); with relative weights σ_m = s / √w_m,
    /// s² = ε(truth) / (N − k), so that the weights keep their meaning of relative precisions.
    pub fn from_residuals(problem: Problem<S>, truth: Vec<f64>) -> Result<Self, StudyError> {
        if problem.has_noise_model() {
            let z = problem.unknowns().coordinates(&truth);
            let sigma = problem.sigmas(&z).map_err(|e| {
                StudyError::Setup(format!("the noise model cannot be evaluated at the truth: {e}"))
            })?;
            return Self::new(problem, truth, sigma);
        }
        let k = problem.unknowns().len();
        let n = problem.n_residuals();
        if n <= k {
            return Err(StudyError::Setup(format!(
                "{n} measured values for {k} unknowns: no residual variance to take the noise level from"
            )));
        }
        let z = problem.unknowns().coordinates(&truth);
        let (cost, _) = problem.cost(&z).map_err(at_truth)?;
        let s = (cost / (n - k) as f64).sqrt();
        if s == 0.0 {
            return Err(StudyError::Setup(
                "the model fits the data exactly: no noise level to simulate".into(),
            ));
        }
        let sigma: Vec<f64> = problem
            .experiments()
            .iter()
            .flat_map(|e| &e.sampled().series)
            .flat_map(|series| series.samples.iter().map(|m| s / m.sqrt_weight))
            .collect();
        Self::new(problem, truth, sigma)
    }
}

impl<S: System + Clone> Scenario<S> {
    /// The same scenario with unknowns held at values (`--fix`): the data stay the model at
    /// the full truth; the fits estimate the other unknowns only.
    pub fn with_fixed(self, fixed: &[(String, f64)]) -> Result<Self, StudyError> {
        if fixed.is_empty() {
            return Ok(self);
        }
        let names = self.base.names();
        let base = self.base.with_fixed(fixed)?;
        let kept = base.names();
        let truth =
            names.iter().zip(&self.truth).filter(|(n, _)| kept.contains(n)).map(|p| *p.1).collect();
        Ok(Self { base, truth, ..self })
    }

    /// The problem template.
    pub fn problem(&self) -> &Problem<S> {
        &self.base
    }

    /// True values of the unknowns.
    pub fn truth(&self) -> &[f64] {
        &self.truth
    }

    /// σ of every measured value.
    pub fn sigma(&self) -> &[f64] {
        &self.sigma
    }

    /// The noise-free data.
    pub fn clean(&self) -> &[f64] {
        &self.clean
    }

    /// Every experiment's data with noise `noise`·σ_m drawn from `rng` (standard normal,
    /// sample after sample, experiment after experiment), on each series' scale: a log-scale
    /// measurement is the model's value times a log-normal factor.
    pub fn noisy_data(&self, noise: f64, rng: &mut impl Rng) -> Vec<Data> {
        self.data_from(|clean, sigma, transform| {
            let shift = noise * sigma * rng.sample::<f64, _>(StandardNormal);
            match transform {
                Transform::Lin => clean + shift,
                Transform::Log => clean * shift.exp(),
                Transform::Log10 => clean * 10f64.powf(shift),
            }
        })
    }

    /// Every experiment's data, each sample's value `value(clean, σ, scale)`, sample after
    /// sample in the template's order.
    fn data_from(&self, mut value: impl FnMut(f64, f64, Transform) -> f64) -> Vec<Data> {
        let mut at = 0;
        self.base
            .experiments()
            .iter()
            .map(|e| {
                let mut data = e.data().clone();
                for series in &mut data.series {
                    let transform = series.transform;
                    if let Samples::Points { values, .. } = &mut series.samples {
                        for v in values.iter_mut() {
                            *v = value(self.clean[at], self.sigma[at], transform);
                            at += 1;
                        }
                    }
                }
                data
            })
            .collect()
    }

    /// The problem on `data`, one per experiment (same times and noise as the template).
    pub fn with_data(&self, data: Vec<Data>) -> Result<Problem<S>, StudyError> {
        Ok(self.base.clone().with_experiment_data(data)?)
    }

    /// The Cramér–Rao bound at the truth for noise `noise`·σ: the inverse Fisher information
    /// F = Σ_m ∇h_m ∇h_mᵀ / (noise σ_m)², as a covariance of the values of the unknowns (the
    /// smallest covariance any unbiased estimator can have, to first order). With priors on
    /// the unknowns, their information is added (Σ ∇r_p ∇r_pᵀ of their standardised rows, not
    /// scaled by the noise): van Trees' bound for an estimate that uses them.
    pub fn cramer_rao(&self, noise: f64) -> Result<DMatrix<f64>, StudyError> {
        let problem = self.with_data(self.clean_data())?;
        let z = problem.unknowns().coordinates(&self.truth);
        let lin = problem.residuals_and_jacobian(&z).map_err(at_truth)?;
        let fisher = if problem.has_noise_model() {
            // The noise model's own Fisher information, for noise `noise` times its σ; the
            // priors' rows, in it too, are not scaled by the noise (as below).
            let prior = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
                z.len(),
                problem.unknowns().list().iter().zip(&z).map(|(u, &zi)| {
                    let slope = u.prior.as_ref().map_or(0.0, |p| p.residual(u.value(zi)).1);
                    (slope * u.scale(zi)).powi(2)
                }),
            ));
            (&lin.normal - &prior) / (noise * noise) + prior
        } else {
            let jac = &lin.residuals.as_ref().expect("discrete data give residuals").jacobian;
            // Row m of the weighted Jacobian is √w_m ∇h_m (in coordinates z).
            let sqrt_w: Vec<f64> = problem
                .experiments()
                .iter()
                .flat_map(|e| &e.sampled().series)
                .flat_map(|s| s.samples.iter().map(|m| m.sqrt_weight))
                .collect();
            // The priors' rows, after the data's, are standardised already, (T(θ) − mean)/sd,
            // and the noise does not scale them: F adds the prior's information (the van
            // Trees bound of an estimate that uses the prior, as the fits do).
            let mut g = jac.clone();
            for (m, mut row) in g.row_iter_mut().enumerate().take(sqrt_w.len()) {
                row /= sqrt_w[m] * noise * self.sigma[m];
            }
            g.tr_mul(&g)
        };
        let factor = NormalFactor::new(&fisher, 1e14).map_err(|s| {
            let names = problem.names();
            let which: Vec<&str> = s.unknowns.iter().map(|&i| names[i].as_str()).collect();
            StudyError::Setup(format!(
                "the Fisher information is singular at the truth: the data cannot identify {}",
                which.join(", ")
            ))
        })?;
        let inverse = factor.inverse();
        let scale: Vec<f64> =
            problem.unknowns().list().iter().zip(&z).map(|(u, &zi)| u.scale(zi)).collect();
        let k = scale.len();
        Ok(DMatrix::from_fn(k, k, |i, j| inverse[(i, j)] * scale[i] * scale[j]))
    }

    /// Every experiment's data without noise.
    pub fn clean_data(&self) -> Vec<Data> {
        self.data_from(|clean, _, _| clean)
    }
}

/// The model's values at the truth: noise-free data (discrete data only).
fn predictions<S: System>(problem: &Problem<S>, truth: &[f64]) -> Result<Vec<f64>, StudyError> {
    if problem.is_continuous() {
        return Err(StudyError::Setup(
            "a study needs discrete data (a continuous record has no sample noise)".into(),
        ));
    }
    let k = problem.unknowns().len();
    if truth.len() != k {
        return Err(StudyError::Setup(format!("{} true values for {k} unknowns", truth.len())));
    }
    let z = problem.unknowns().coordinates(truth);
    problem.predictions(&z).map_err(at_truth)
}

/// What stops a study at the truth: the model cannot be integrated there, or it integrates
/// and a value there cannot be represented (a residual whose square overflows).
fn at_truth(e: OdeError) -> StudyError {
    StudyError::Setup(match e {
        OdeError::Unrepresentable { .. } => format!("the model integrates at the truth, but {e}"),
        e => format!("the model cannot be integrated at the truth: {e}"),
    })
}

fn sample_count(series: &Series) -> usize {
    match &series.samples {
        Samples::Points { values, .. } => values.len(),
        Samples::Function(_) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A failure at the truth is called an integration failure only where it is one.
    #[test]
    fn a_value_that_overflows_at_the_truth_is_not_called_an_integration_failure() {
        let overflow = OdeError::Unrepresentable { t: 2.0, what: "ε overflows".into() };
        let message = at_truth(overflow).to_string();
        assert!(
            message.contains("the model integrates at the truth, but ε overflows"),
            "{message}"
        );
        let failed = OdeError::TooManySteps { t: 1.0, t_end: 2.0, steps: 10 };
        let message = at_truth(failed).to_string();
        assert!(message.contains("cannot be integrated at the truth: too many steps"), "{message}");
    }
}
