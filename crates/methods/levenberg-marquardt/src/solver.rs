//! Levenberg–Marquardt as a [`Step`] of the shared driver.
//!
//! At the iterate z, with ε, U = JᵀWr and A = JᵀWJ (the Gauss–Newton quantities every method
//! shares, Goodman's eq. 12 and 15), the trial step δ(λ) minimises
//!
//!   m_λ(δ) = ε + 2Uᵀδ + δᵀAδ + λ‖Dδ‖²   over the box lo − z ≤ δ ≤ hi − z,
//!
//! with D = diag(d), d_i the largest √A_ii seen so far (Moré's scaling: the iteration does not
//! depend on the units of the unknowns). λ = 0, the Gauss–Newton step, when that step lies in
//! the trust region ‖Dδ‖ ≤ Δ (within Moré's 10 %); otherwise λ > 0 is found with ‖Dδ(λ)‖
//! within 10 % of Δ, by bisection in log λ from the last λ (‖Dδ(λ)‖ falls as λ grows). The
//! ratio of the actual to the predicted decrease,
//!
//!   ρ = (ε(z) − ε(z + δ)) / (ε(z) − m₀(δ)),
//!
//! decides, with MINPACK's constants: ρ ≥ 1e-4 accepts the step; ρ < ¼ shrinks the radius to
//! ½·min(Δ, 10‖Dδ‖); ρ ≥ ¾, or λ = 0 with ρ ≥ ¼, sets it to 2‖Dδ‖. A rejected step is
//! recomputed in the smaller region from the same point. Near the minimum, where the model
//! predicts a decrease below ε's accuracy (rtol·ε), the difference of two integrated costs is
//! noise: the actual decrease is then measured from the gradients at both ends (the
//! trapezoidal rule along the step, exact for a quadratic), which the sensitivities give as
//! accurately as the certificate needs. (Accepting any step whose cost stays within the noise
//! floor let the iteration cycle between two points on Boehm's problem, forever 3e-6 from
//! certified.)

use nalgebra::DVector;
use sysid_core::{
    Advance, Estimate, Evaluations, Failure, FitError, Iterate, Linearization, Method, Problem,
    Proposal, Quadratic, Rule, Singular, Step, drive, minimise_in_box,
};
use sysid_ode::System;

use crate::options::LevenbergMarquardtOptions;

/// Levenberg–Marquardt with its options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LevenbergMarquardt {
    /// The options.
    pub options: LevenbergMarquardtOptions,
}

impl LevenbergMarquardt {
    /// The method with these options.
    pub fn new(options: LevenbergMarquardtOptions) -> Self {
        Self { options }
    }
}

impl<S: System> Method<S> for LevenbergMarquardt {
    fn name(&self) -> &str {
        "levenberg-marquardt"
    }

    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.options.validate()?;
        let mut step = TrustRegion {
            options: &self.options,
            scale: Vec::new(),
            radius: 0.0,
            lambda: 0.0,
            proposed: None,
        };
        drive(problem, "levenberg-marquardt", &self.options.driver, &mut step, start)
    }
}

/// The state of the iteration: the scaling D, the radius Δ, the last λ, and the step of the
/// last proposal (which the advance evaluates first).
struct TrustRegion<'o> {
    options: &'o LevenbergMarquardtOptions,
    scale: Vec<f64>,
    radius: f64,
    lambda: f64,
    proposed: Option<Trial>,
}

/// A trial step with what the decision needs.
struct Trial {
    delta: DVector<f64>,
    /// ‖Dδ‖.
    scaled_norm: f64,
    /// ε − m₀(δ) = −(2Uᵀδ + δᵀAδ).
    predicted: f64,
    lambda: f64,
    condition: f64,
}

impl TrustRegion<'_> {
    /// d_i ← max(d_i, √A_ii); a zero column keeps scale 1.
    fn rescale(&mut self, lin: &Linearization) {
        let k = lin.gradient.len();
        self.scale.resize(k, 0.0);
        for (i, d) in self.scale.iter_mut().enumerate() {
            let largest = d.max(lin.normal[(i, i)].max(0.0).sqrt());
            *d = if largest == 0.0 { 1.0 } else { largest };
        }
    }

    /// The minimiser of m_λ in the box, with ‖Dδ‖ and the predicted decrease.
    fn solve(
        &self,
        lin: &Linearization,
        (lo, hi): (&[f64], &[f64]),
        lambda: f64,
    ) -> Result<Trial, Singular> {
        let k = lin.gradient.len();
        let mut h = lin.normal.clone();
        for i in 0..k {
            h[(i, i)] += lambda * self.scale[i] * self.scale[i];
        }
        let model = Quadratic { h: &h, c: &lin.gradient };
        let max_condition = self.options.driver.max_condition;
        let solution = minimise_in_box(&model, (lo, hi), &vec![0.0; k], max_condition)?;
        let delta = DVector::from_vec(solution.x);
        let scaled_norm = delta.iter().zip(&self.scale).map(|(d, s)| (d * s).powi(2)).sum::<f64>();
        let predicted = -(2.0 * lin.gradient.dot(&delta) + delta.dot(&(&lin.normal * &delta)));
        Ok(Trial {
            delta,
            scaled_norm: scaled_norm.sqrt(),
            predicted,
            lambda,
            condition: solution.condition,
        })
    }

    /// The trial step for the current radius from the iterate `lin`.
    fn step<S: System>(
        &mut self,
        problem: &Problem<S>,
        lin: &Linearization,
    ) -> Result<Trial, Failure> {
        let (lo, hi) = problem.unknowns().step_box(&lin.z);
        let bounds = (lo.as_slice(), hi.as_slice());
        let radius = self.radius;
        let gauss_newton = self.solve(lin, bounds, 0.0);
        if let Ok(trial) = &gauss_newton
            && trial.scaled_norm <= 1.1 * radius
        {
            self.lambda = 0.0;
            return gauss_newton.map_err(|s| Failure::singular(&s, &problem.names()));
        }
        // ‖D⁻¹U‖/Δ: the λ at which the steepest-descent limit of δ(λ) has length Δ.
        let scaled_gradient =
            lin.gradient.iter().zip(&self.scale).map(|(g, d)| (g / d).powi(2)).sum::<f64>();
        let mut lambda =
            if self.lambda > 0.0 { self.lambda } else { scaled_gradient.sqrt() / radius };
        if !(lambda > 0.0 && lambda.is_finite()) {
            lambda = 1e-3;
        }
        let (mut low, mut high) = (0.0_f64, f64::INFINITY);
        let (mut inside, mut damped): (Option<Trial>, Option<Trial>) = (None, None);
        let mut singular = gauss_newton.err();
        for _ in 0..60 {
            match self.solve(lin, bounds, lambda) {
                Ok(trial) if (trial.scaled_norm - radius).abs() <= 0.1 * radius => {
                    self.lambda = lambda;
                    return Ok(trial);
                }
                Ok(trial) if trial.scaled_norm > radius => {
                    low = lambda;
                    damped = Some(trial);
                }
                Ok(trial) => {
                    high = lambda;
                    inside = Some(trial);
                }
                Err(s) => {
                    low = lambda;
                    singular = Some(s);
                }
            }
            lambda = match (low > 0.0, high.is_finite()) {
                (_, false) => lambda * 10.0,
                (false, true) => high / 10.0,
                (true, true) => (low * high).sqrt(),
            };
        }
        // Not within 10 % of the radius after 60 tries: the step with the least λ inside the
        // region, else the most damped one (the advance judges it like any other); when no
        // λ gave a step, the singular system.
        match (inside.or(damped), singular) {
            (Some(trial), _) => {
                self.lambda = trial.lambda;
                Ok(trial)
            }
            (None, singular) => {
                let k = lin.gradient.len();
                let s = singular.unwrap_or_else(|| Singular {
                    unknowns: (0..k).collect(),
                    condition: f64::INFINITY,
                    direction: vec![1.0; k],
                });
                Err(Failure::singular(&s, &problem.names()))
            }
        }
    }
}

impl<S: System> Step<S> for TrustRegion<'_> {
    /// Linearizes at the start; D from its A, Δ = factor·‖D z₀‖ (factor when that is 0).
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        let lin = ev.linearize(&z)?;
        self.rescale(&lin);
        let scaled = z.iter().zip(&self.scale).map(|(z, d)| (z * d).powi(2)).sum::<f64>().sqrt();
        let factor = self.options.factor;
        self.radius = if scaled > 0.0 { factor * scaled } else { factor };
        Ok(Iterate::linearized(lin))
    }

    /// The same point at the refined integration; the radius and the scaling stay.
    fn restart(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Iterate, Failure> {
        ev.linearize(&current.z).map(Iterate::linearized)
    }

    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        let lin = current.linearization.as_ref().expect("the iterates are linearized");
        self.rescale(lin);
        let trial = self.step(ev.problem(), lin)?;
        let z = ev.problem().unknowns().moved(&current.z, trial.delta.as_slice(), 1.0);
        let condition = Some(trial.condition);
        self.proposed = Some(trial);
        Ok(Proposal { z, condition, gradient_norm: None, stop: None })
    }

    fn advance(
        &mut self,
        ev: &Evaluations<'_, S>,
        current: &Iterate,
        proposal: Proposal,
    ) -> Result<Advance, Failure> {
        let problem = ev.problem();
        let lin = current.linearization.as_ref().expect("the iterates are linearized");
        let resolution = problem.integrator().rtol * lin.cost;
        let step_tolerance = problem.resolvable_step(self.options.driver.step_tolerance);
        let z_norm = current.z.iter().map(|v| v * v).sum::<f64>().sqrt();
        let negligible = step_tolerance * (z_norm + step_tolerance);
        let mut trial = match self.proposed.take() {
            Some(trial) => trial,
            None => self.step(problem, lin)?,
        };
        let mut z = proposal.z;
        for _ in 0..=self.options.max_rejections {
            let evaluated = match ev.linearize(&z) {
                Ok(l) => Some(l),
                Err(budget @ Failure::Budget { .. }) => return Err(budget),
                // An integration that fails at the trial point: a step too long.
                Err(_) => None,
            };
            let decrease = match &evaluated {
                // Below ε's accuracy the difference of two integrated costs is noise; the
                // gradients, from the sensitivities, are still accurate, and the trapezoidal
                // rule along the step is exact for a quadratic:
                // ε(z) − ε(z⁺) = −½(∇ε(z) + ∇ε(z⁺))ᵀ(z⁺ − z), with ∇ε = 2U.
                Some(l) if trial.predicted <= resolution => -(0..l.z.len())
                    .map(|i| (lin.gradient[i] + l.gradient[i]) * (l.z[i] - lin.z[i]))
                    .sum::<f64>(),
                Some(l) => lin.cost - l.cost,
                None => f64::NEG_INFINITY,
            };
            let rho =
                if trial.predicted > 0.0 { decrease / trial.predicted } else { f64::NEG_INFINITY };
            if rho < 0.25 {
                self.radius = 0.5 * self.radius.min(10.0 * trial.scaled_norm);
            } else if rho >= 0.75 || trial.lambda == 0.0 {
                self.radius = 2.0 * trial.scaled_norm;
            }
            if let Some(l) = evaluated.filter(|_| rho >= 1e-4) {
                return Ok(Advance::Moved(Iterate::linearized(l)));
            }
            if trial.delta.norm() <= negligible || !(self.radius > 0.0 && self.radius.is_finite()) {
                return Ok(Advance::Stop(Rule::Step));
            }
            trial = self.step(problem, lin)?;
            z = problem.unknowns().moved(&current.z, trial.delta.as_slice(), 1.0);
        }
        Ok(Advance::Stop(Rule::NoDescent))
    }
}
