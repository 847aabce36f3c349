//! Levenberg–Marquardt as a [`Step`] of the shared driver.
//!
//! At the iterate z, with ε, U = JᵀWr and A = JᵀWJ (the Gauss–Newton quantities every method
//! shares, Goodman's eq. 12 and 15), the trial step δ(λ) minimises
//!
//!   m_λ(δ) = ε + 2Uᵀδ + δᵀAδ + λ‖Dδ‖²   over the box lo − z ≤ δ ≤ hi − z,
//!
//! with D = diag(d), d_i ← max(√A_ii, 0.9·d_i) at each iterate (Moré's scaling, with a memory
//! that fades: [`sysid_core::method::SCALE_MEMORY`]; the iteration does not depend on the units of the
//! unknowns). λ = 0, the Gauss–Newton step, when that step lies in
//! the trust region ‖Dδ‖ ≤ Δ (within Moré's 10 %); otherwise λ > 0 is found with ‖Dδ(λ)‖
//! within 10 % of Δ, by bisection in log λ from the last λ (‖Dδ(λ)‖ falls as λ grows). The
//! ratio of the actual to the predicted decrease,
//!
//!   ρ = (ε(z) − ε(z + δ)) / (ε(z) − m₀(δ)),
//!
//! decides: ρ ≥ [`ACCEPT`] (¼) accepts the step; ρ < ¼ shrinks the radius to ½·min(Δ, 10‖Dδ‖);
//! ρ ≥ ¾, or λ = 0 with ρ ≥ ¼, sets it to 2‖Dδ‖ (MINPACK's constants). A rejected step is
//! recomputed in the smaller region from the same point; while that gives the same step (the
//! Gauss–Newton step, still inside the region), the radius halves again without integrating
//! it twice. Near the minimum, where the model
//! predicts a decrease below ε's accuracy (rtol·(|ε| + 2‖r‖·‖W^½ b‖),
//! [`Problem::cost_resolution`]), the difference of two integrated costs is
//! noise: the actual decrease is then measured from the gradients at both ends (the
//! trapezoidal rule along the step, exact for a quadratic), which the sensitivities give as
//! accurately as the certificate needs. (Accepting any step whose cost stays within the noise
//! floor let the iteration cycle between two points on Boehm's problem, forever 3e-6 from
//! certified.)
//!
//! Each trial costs an integration with sensitivities, F, where the cost alone would decide
//! a rejection. While at least [`SCREEN_FROM`] of the recent trials were rejected, a trial
//! whose predicted decrease is above ε's resolution is screened: integrated plain first (P),
//! rejected on that cost where ρ < ¼, and integrated with sensitivities only otherwise. The
//! points visited are the same (ρ from the plain cost and from the sensitivities' differ by
//! the integration's error); a fit costs less where more than P/F of the trials are rejected.
//!
//! With noise scales that the driver sets to their closed form at every iterate
//! ([`Evaluations::profiling`](sysid_core::method::Evaluations::profiling), hierarchical
//! optimisation after the first round), the objective is the profile NLL(z, ŝ(z)): the model's
//! matrix is A less what the scales take (`Problem::profile_curvature`), and a trial's
//! decrease is ε's at the iterate's scales plus what moving them to the trial's closed form
//! gains (`Problem::profile_gain`). A model kept for an iterate (the hybrid's Hessian) is
//! matched by z and ε, since the driver may re-weight the iterate in place.

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    DriverOptions, Estimate, Failure, FitError, Linearization, Method, Problem, Rule, Termination,
    method::{
        Accelerated, Advance, Curve, CurveStep, Evaluations, Geodesic, Iterate, Proposal, Step,
        actual_decrease, differenced_hessian, drive,
    },
    observer::{self, TrialReport},
};
use sysid_ode::System;

use crate::options::{Hessian, LevenbergMarquardtOptions};

/// Fletcher and Xu's switch: a step that lowered ε by at least this fraction of itself
/// keeps the hybrid on Gauss–Newton's model (their ε = 0.2). Below it the residuals are
/// not falling towards zero, Σ rᵢ∇²rᵢ matters, and the full Hessian pays for its k
/// linearizations.
pub const FAST_FALL: f64 = 0.2;

/// The least ratio ρ of the actual to the predicted decrease at which a step is taken.
///
/// MINPACK takes any step with ρ ≥ 1e-4 and only shrinks the radius below ¼. On a sloppy
/// problem that takes steps the model knew nothing about: Fiedler's problem from nominal + 0.1
/// (its first radius 3.2e4) took a Gauss–Newton step that predicted a fall of 256 in ε = 3508
/// and got 0.04 (ρ = 2e-4); it put k3, k5 and k11 on their upper bounds, three decades away,
/// and the fit stalled there at NLL −48.80, where fides reaches −58.584. A step is taken here
/// only where the model predicted at least a quarter of what happened (the threshold at
/// which MINPACK already judges the model poor); otherwise it is recomputed in a smaller
/// region. Measured with the default method on the PEtab problems from nominal and from
/// nominal + 0.1 (docs/methods.md): every fit that certified still certifies the same NLL,
/// Fiedler's shifted fit certifies −58.58395, Elowitz's take 190 and 207 iterations instead
/// of 310, and the others within a tenth of their former count (Crauste from nominal 55
/// instead of 50, Fiedler 103 instead of 100).
pub const ACCEPT: f64 = 0.25;

/// The share of recent trials rejected from which a trial is screened: integrated plain
/// first (the cost alone, P), and with sensitivities (F) only where the plain cost does not
/// reject it. With a share r of trials rejected, a step then costs F + P/(1 − r) instead of
/// F/(1 − r): screening pays where r > P/F. P/F, measured with one thread
/// (`sysid evaluate --repeat 20` with and without `--gradient`): Fiedler 0.12, Bachmann 0.16,
/// Elowitz 0.33, Boehm 0.36, Bruno 0.39; nl2sol rejects about half of its trials there.
pub const SCREEN_FROM: f64 = 0.4;

/// The largest difference, in rtol·ε, between a screened trial's plain cost and its
/// sensitivities' that keeps a run screened ([`SCREEN_FROM`]).
const SCREEN_AGREEMENT: f64 = 1.0;

/// How much of the share of rejected trials each new trial makes ([`SCREEN_FROM`]).
const SCREEN_MEMORY: f64 = 0.25;

/// The iterations over which a crawl is judged ([`CRAWL_FALL`]).
pub const CRAWL_WINDOW: usize = 50;

/// A fit crawls where its cost fell by less than this share of ε over the last
/// [`CRAWL_WINDOW`] iterations (under hierarchical optimisation ε at the iterate's scales:
/// the profile cost has an arbitrary constant): a narrow curved valley, where the straight
/// step leaves the floor within a short distance and the trust region creeps along it
/// (Crauste from nominal + 0.1: ε falling by 2e-6 of itself an iteration for 800
/// iterations). While it
/// does, a rejected trial is corrected by a chord step with the iterate's Jacobian, which
/// brings it back towards the floor ([`LevenbergMarquardtOptions::correct`]). The share is
/// ten times what the crawl of Crauste's shifted fit lowers ε by over the window, and below
/// what a fit converging at any useful rate does (docs/methods.md); a larger one, 1e-2,
/// changed fits that were still descending, and Giordano's from nominal + 0.1 ended higher.
pub const CRAWL_FALL: f64 = 1e-3;

/// Most halvings of the radius that give the step just rejected again: from MINPACK's first
/// radius, 100‖D z₀‖, to any Gauss–Newton step it is tens.
const MAX_SAME: usize = 200;

/// The name of the method `options` make ([`Method::name`]).
fn method_name(options: &LevenbergMarquardtOptions) -> &'static str {
    match options.hessian {
        Hessian::GaussNewton if options.geodesic => "geodesic-lm",
        Hessian::GaussNewton => "levenberg-marquardt",
        Hessian::Hybrid => "hybrid-newton",
        Hessian::Adaptive => "nl2sol",
    }
}

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

    /// Fletcher and Xu's hybrid in the same trust region: Gauss–Newton while ε falls fast,
    /// Newton on the full Hessian of ε (by differences) once it slows.
    pub fn hybrid(options: LevenbergMarquardtOptions) -> Self {
        Self { options: LevenbergMarquardtOptions { hessian: Hessian::Hybrid, ..options } }
    }

    /// Transtrum and Sethna's geodesic Levenberg–Marquardt: Gauss–Newton's model, each step
    /// bent along the valley by its second-order term ([`sysid_core::method::Geodesic`]).
    pub fn geodesic(options: LevenbergMarquardtOptions) -> Self {
        Self {
            options: LevenbergMarquardtOptions {
                hessian: Hessian::GaussNewton,
                geodesic: true,
                ..options
            },
        }
    }

    /// NL2SOL's adaptive model in the same trust region: Gauss–Newton's, or Gauss–Newton's
    /// plus a structured secant approximation of the rest of the Hessian, whichever predicted
    /// the last step better.
    /// While it crawls, a rejected trial is corrected along the valley
    /// ([`LevenbergMarquardtOptions::correct`]).
    pub fn adaptive(options: LevenbergMarquardtOptions) -> Self {
        Self {
            options: LevenbergMarquardtOptions {
                hessian: Hessian::Adaptive,
                correct: true,
                ..options
            },
        }
    }
}

impl<S: System> Method<S> for LevenbergMarquardt {
    fn name(&self) -> &str {
        method_name(&self.options)
    }

    /// A run from `start`; where it stalls on flat ground (a plateau, or unknowns the model
    /// does not respond to), a second, cautious run from the same start, whose first radius
    /// is one own scale of the unknowns (‖D s‖) instead of MINPACK's 100·‖D z₀‖
    /// ([`Estimate::retried`]; docs/methods.md, "The cautious retry").
    /// The budgets (`max_iterations`, `max_integrations`, `max_seconds`) are the fit's: the
    /// second run has what the first left, and there is none where nothing is left.
    fn fit_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        let first = self.run(problem, start, &self.options, false)?;
        let flat = matches!(&first.termination,
            Termination::Stalled { plateau, undetermined, .. } if *plateau || !undetermined.is_empty());
        if !flat {
            return Ok(first);
        }
        let driver = &self.options.driver;
        let left = DriverOptions {
            max_iterations: driver.max_iterations.saturating_sub(first.iterations),
            max_integrations: Some(
                driver
                    .integration_budget(problem.unknowns().len(), problem.experiments().len())
                    .saturating_sub(first.counts.integrations),
            ),
            max_seconds: driver.max_seconds.map(|s| s - first.elapsed.as_secs_f64()),
            ..*driver
        };
        let spent = left.max_iterations == 0
            || left.max_integrations == Some(0)
            || left.max_seconds.is_some_and(|s| s <= 0.0);
        if spent {
            return Ok(first);
        }
        let options = LevenbergMarquardtOptions { driver: left, ..self.options.clone() };
        Ok(Estimate::retried(first, self.run(problem, start, &options, true)?))
    }

    fn fit_once_from(&self, problem: &Problem<S>, start: &[f64]) -> Result<Estimate, FitError> {
        self.run(problem, start, &self.options, false)
    }
}

impl LevenbergMarquardt {
    /// One run from `start` with `options`: its first radius MINPACK's, or with `cautious` one
    /// own scale of the unknowns.
    fn run<S: System>(
        &self,
        problem: &Problem<S>,
        start: &[f64],
        options: &LevenbergMarquardtOptions,
        cautious: bool,
    ) -> Result<Estimate, FitError> {
        options.validate()?;
        let mut step = TrustRegion {
            options,
            cautious,
            curve: Curve::default(),
            radius: 0.0,
            proposed: None,
            newton: None,
            fall: None,
            secant: Secant::default(),
            geodesic: Geodesic::default(),
            profile: None,
            rejections: 0.0,
            unscreened: false,
            costs: VecDeque::new(),
            held: None,
            cleared: Vec::new(),
        };
        let name = Method::<S>::name(self);
        drive(problem, name, &options.driver, &mut step, start)
    }
}

/// The state of the iteration: the curve (its scaling D and last λ), the radius Δ, the
/// step of the last proposal (which the advance evaluates first), and, for the hybrid, the
/// relative fall of ε at the last step and the iterate with A replaced by the differenced
/// Hessian.
struct TrustRegion<'o> {
    options: &'o LevenbergMarquardtOptions,
    /// The first radius: one own scale of the unknowns instead of MINPACK's.
    cautious: bool,
    curve: Curve,
    radius: f64,
    proposed: Option<CurveStep>,
    newton: Option<Linearization>,
    fall: Option<f64>,
    /// The adaptive model's secant part and which model it uses.
    secant: Secant,
    /// The plain residuals at the iterate, for the steps' geodesic acceleration.
    geodesic: Geodesic,
    /// Under hierarchical optimisation, what the noise scales take from the model's matrix
    /// at the iterate (`Problem::profile_curvature`), with the iterate's z and ε.
    profile: Option<(Vec<f64>, f64, DMatrix<f64>)>,
    /// The share of recent trials rejected (an average fading by [`SCREEN_MEMORY`] a
    /// trial): from [`SCREEN_FROM`] on, trials are screened by a plain integration.
    rejections: f64,
    /// Whether a screened trial's plain cost and its sensitivities' differed by more than
    /// [`SCREEN_AGREEMENT`]·rtol·ε in this run: it is screened no more.
    unscreened: bool,
    /// The costs of this run's last [`CRAWL_WINDOW`] + 1 iterates, oldest first, which tell
    /// whether it crawls ([`CRAWL_FALL`]).
    costs: VecDeque<f64>,
    /// The unknowns the last trial that could not be integrated held off their bounds, until
    /// its retry is taken (they stay held) or is not (they are released).
    held: Option<Held>,
    /// The unknowns released at this iterate, which its trials do not hold off again.
    cleared: Vec<usize>,
}

/// Unknowns held off their bounds by a trial that could not be integrated, until its retry
/// decides, with that trial and the radius its failure would leave.
struct Held {
    unknowns: Vec<usize>,
    radius: f64,
    trial: CurveStep,
}

/// NL2SOL's S ≈ Σ rᵢ∇²rᵢ (half of it, in the units of A = JᵀWJ: the model is
/// ε + 2Uᵀδ + δᵀ(A + S)δ), and whether the step uses A + S (the augmented model) or A.
#[derive(Default)]
struct Secant {
    s: Option<DMatrix<f64>>,
    augmented: bool,
}

impl Secant {
    /// The structured secant update after the accepted step `step` = z₊ − z from `from` to
    /// `to`: y# = (U₊ − U) − A₊·step is what Σ rᵢ∇²rᵢ did along the step; S₊ satisfies
    /// S₊·step = y# with the least change (the symmetric rank-two update of Dennis, Gay and
    /// Welsch, with y = U₊ − U in the role of the metric), after sizing S by
    /// τ = min(1, |stepᵀy#| / |stepᵀS step|). Skipped where yᵀstep ≤ 0.
    fn update(&mut self, from: &Linearization, to: &Linearization, step: &DVector<f64>) {
        let k = step.len();
        let y = &to.gradient - &from.gradient;
        let ys = y.dot(step);
        if !(ys > 0.0 && ys.is_finite()) {
            return;
        }
        let sharp = &y - &to.normal * step;
        let s = self.s.get_or_insert_with(|| DMatrix::zeros(k, k));
        let s_step = &*s * step;
        let curvature = step.dot(&s_step);
        let tau = match curvature.abs() > 0.0 {
            true => (step.dot(&sharp).abs() / curvature.abs()).min(1.0),
            false => 1.0,
        };
        let residual = &sharp - &s_step * tau;
        let update = (&residual * y.transpose() + &y * residual.transpose()) / ys
            - (&y * y.transpose()) * (residual.dot(step) / (ys * ys));
        let next = &*s * tau + update;
        if next.iter().all(|v| v.is_finite()) {
            *s = next;
        }
    }

    /// `lin` with A + S in place of A, where the augmented model is used and S is known.
    fn model(&self, lin: &Linearization) -> Option<Linearization> {
        match (&self.s, self.augmented) {
            (Some(s), true) => Some(Linearization { normal: &lin.normal + s, ..lin.clone() }),
            _ => None,
        }
    }

    /// After a step from `from` with decrease `actual`: the model that predicted it better is
    /// the next step's.
    fn choose(&mut self, from: &Linearization, step: &DVector<f64>, actual: f64) {
        let Some(s) = &self.s else { return };
        let gauss_newton = from.predicted_decrease(step);
        let augmented = gauss_newton - step.dot(&(s * step));
        self.augmented = (augmented - actual).abs() < (gauss_newton - actual).abs();
    }
}

impl TrustRegion<'_> {
    /// `model` (at the iterate) as the profile sees it: its matrix less what the noise
    /// scales take (`Problem::profile_curvature`); None where the driver does not profile
    /// the scales.
    fn profiled(&self, model: &Linearization) -> Option<Linearization> {
        let (z, cost, c) = self.profile.as_ref()?;
        (*z == model.z && cost.to_bits() == model.cost.to_bits()).then(|| Linearization {
            z: model.z.clone(),
            cost: model.cost,
            gradient: model.gradient.clone(),
            normal: &model.normal - c,
            residuals: None,
            norm: model.norm,
            experiment_costs: Vec::new(),
            counts: model.counts,
        })
    }

    /// The trial step for the current radius from the iterate `lin`: on Newton's model when
    /// there is one at this iterate, else on Gauss–Newton's; with geodesic acceleration, bent
    /// by its second-order term, the radius halved (without a linearization) while the path
    /// bends too much over the step.
    fn step<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        lin: &Linearization,
    ) -> Result<CurveStep, Failure> {
        let problem = ev.problem();
        let max_condition = self.options.driver.max_condition;
        let negligible = negligible_step(problem, &lin.z, self.options.driver.step_tolerance);
        loop {
            let model = self.newton.as_ref().filter(|n| same_iterate(n, lin)).unwrap_or(lin);
            let profiled = self.profiled(model);
            let model = profiled.as_ref().unwrap_or(model);
            let v = self.curve.within(problem, model, self.radius, max_condition)?;
            if !self.options.geodesic {
                return Ok(v);
            }
            match self.geodesic.accelerate(ev, model, &self.curve, &v, max_condition)? {
                Accelerated::Step(step) => return Ok(step),
                Accelerated::Unavailable => return Ok(v),
                Accelerated::TooCurved if v.delta.norm() <= negligible => return Ok(v),
                Accelerated::TooCurved => self.radius = 0.5 * v.scaled_norm,
            }
        }
    }

    /// The hybrid's model at the iterate `lin`: Gauss–Newton's after a step that lowered ε
    /// by at least [`FAST_FALL`] of itself (and at the start), else Newton's, A ← ∂U/∂z
    /// (differenced once per iterate). The scaling D stays JᵀWJ's, so the trust region
    /// measures steps as Levenberg–Marquardt's does; where the Hessian is indefinite, the
    /// curve's λ grows until A + λD² is positive definite.
    fn model<S: System>(
        &mut self,
        ev: &Evaluations<'_, S>,
        lin: &Linearization,
    ) -> Result<(), Failure> {
        if self.options.hessian == Hessian::Adaptive {
            self.newton = self.secant.model(lin);
            return Ok(());
        }
        // An exact fit's 0/0 counts as fast.
        let fast = self.fall.is_none_or(|f| f >= FAST_FALL || f.is_nan());
        if self.options.hessian == Hessian::GaussNewton || fast {
            self.newton = None;
        } else if !self.newton.as_ref().is_some_and(|n| same_iterate(n, lin)) {
            self.newton =
                differenced_hessian(ev, lin)?.map(|normal| Linearization { normal, ..lin.clone() });
        }
        Ok(())
    }
}

impl<S: System> Step<S> for TrustRegion<'_> {
    /// Each trial is judged against the current linearization's ε at the same scales.
    fn profiles(&self) -> bool {
        true
    }

    /// A trial whose integration fails is rejected and the radius shrinks.
    fn retreats(&self) -> bool {
        true
    }

    /// Far from a minimum the trust region needs the model's shape, not its last digits.
    fn coarse_first(&self) -> bool {
        true
    }

    /// Linearizes at the start; D from its A, Δ = factor·‖D z₀‖ (factor when that is 0).
    ///
    /// A start begins the hybrid afresh: each round of the noise scales' closed form starts
    /// the step again at the point the last round ended, with new weights, where a Newton
    /// model kept from that round would be the old problem's.
    fn start(&mut self, ev: &Evaluations<'_, S>, z: Vec<f64>) -> Result<Iterate, Failure> {
        (self.newton, self.fall, self.secant) = (None, None, Secant::default());
        (self.rejections, self.unscreened) = (0.0, false);
        self.costs.clear();
        self.curve.guarded.clear();
        self.curve.held_off.clear();
        (self.held, self.cleared) = (None, Vec::new());
        let lin = ev.linearize(&z)?;
        self.curve.rescale(&lin);
        let scaled = self.curve.scaled_norm(&z);
        let factor = self.options.factor;
        self.radius = if scaled > 0.0 { factor * scaled } else { factor };
        if self.cautious {
            let unknowns = ev.problem().unknowns().list();
            let own: Vec<f64> =
                unknowns.iter().zip(&z).map(|(u, &z)| u.coordinate_scale(z)).collect();
            self.radius = self.curve.scaled_norm(&own);
        }
        Ok(Iterate::linearized(lin))
    }

    /// The same point at the refined integration; the radius and the scaling stay, Newton's
    /// model is differenced again.
    fn restart(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Iterate, Failure> {
        self.newton = None;
        ev.linearize(&current.z).map(Iterate::linearized)
    }

    fn propose(&mut self, ev: &Evaluations<'_, S>, current: &Iterate) -> Result<Proposal, Failure> {
        let lin = current.linearization.as_ref().expect("the iterates are linearized");
        self.curve.rescale(lin);
        self.profile = match ev.profiling() {
            true => ev.problem().profile_curvature(lin).map(|c| (lin.z.clone(), lin.cost, c)),
            false => None,
        };
        self.model(ev, lin)?;
        let trial = self.step(ev, lin)?;
        let z = ev.problem().unknowns().moved(&current.z, trial.delta.as_slice(), 1.0);
        let condition = Some(trial.condition.value());
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
        let resolution = problem.cost_resolution(lin.cost, lin.norm);
        // The plain and the sensitivities' cost of one point agree to rtol·ε where they
        // take one path (the check that keeps a run screened).
        let agreement = SCREEN_AGREEMENT * problem.integrator().rtol * lin.cost.abs();
        let negligible = negligible_step(problem, &current.z, self.options.driver.step_tolerance);
        let crawling = self.options.correct && self.crawls(current.cost, lin.cost);
        let mut trial = match self.proposed.take() {
            Some(trial) => trial,
            None => self.step(ev, lin)?,
        };
        let mut z = proposal.z;
        self.held = None;
        // Trials left; a trial blamed on the bounds it put unknowns on does not count (its
        // retry does).
        let mut left = self.options.max_rejections + 1;
        while left > 0 {
            let ratio = |decrease: f64| match trial.predicted > 0.0 {
                true => decrease / trial.predicted,
                false => f64::NEG_INFINITY,
            };
            // Screened: integrated plain first, and with sensitivities only where that does
            // not reject it. The decrease is then the difference of two costs, which it is
            // above ε's resolution.
            let screened = self.options.screen
                && !self.unscreened
                && self.rejections >= SCREEN_FROM
                && trial.predicted > resolution
                && !problem.is_continuous();
            let (mut evaluated, mut decrease) = match screened {
                true => match ev.residuals(&z) {
                    Ok(r) => {
                        let gain = if ev.profiling() { problem.profile_gain_of(&r) } else { 0.0 };
                        let decrease = lin.cost - r.norm_squared() + gain;
                        if ratio(decrease) < ACCEPT {
                            (None, decrease)
                        } else {
                            let (l, decrease) =
                                self.evaluate(ev, lin, &z, trial.predicted, resolution)?;
                            // The premise: the plain cost is the sensitivities' to ε's
                            // accuracy. Where it is not (an oscillator's phase, say), the
                            // two would take different paths, and the run is not screened
                            // again.
                            let plain = r.norm_squared();
                            if l.as_ref().is_some_and(|l| (l.cost - plain).abs() > agreement) {
                                self.unscreened = true;
                            }
                            (l, decrease)
                        }
                    }
                    Err(budget @ Failure::Budget { .. }) => return Err(budget),
                    Err(_) => (None, f64::NEG_INFINITY),
                },
                false => self.evaluate(ev, lin, &z, trial.predicted, resolution)?,
            };
            // In a crawl, a rejected trial that left the valley's floor is brought back
            // towards it, and the corrected point is judged by the same test.
            if crawling
                && ratio(decrease) < ACCEPT
                && !self.curve.guarded.contains(&true)
                && let Some(l) = &evaluated
                && let Some((c, at)) = self.corrected(ev, lin, l, &trial)?
            {
                let gain = if ev.profiling() { problem.profile_gain(&c) } else { 0.0 };
                let corrected = actual_decrease(lin, &c, trial.predicted, resolution) + gain;
                if corrected > decrease {
                    (evaluated, decrease, z) = (Some(c), corrected, at);
                }
            }
            let rho = ratio(decrease);
            let rejected = !(evaluated.is_some() && rho >= ACCEPT);
            if observer::trials_listening() {
                observer::report_trial(&TrialReport {
                    method: method_name(self.options),
                    model: self.model_name(lin),
                    from: lin.cost,
                    radius: self.radius,
                    step: trial.scaled_norm,
                    lambda: trial.lambda,
                    predicted: trial.predicted,
                    // (−∞ where the trial could not be integrated: not a decrease.)
                    actual: if decrease.is_finite() { decrease } else { f64::NAN },
                    ratio: if decrease.is_finite() { rho } else { f64::NAN },
                    accepted: !rejected,
                });
            }
            // A rejected trial that went over a kink where a switch time passes a sample
            // time is blamed on the kink: the unknowns it took over one keep to their kinks
            // from now on, and the radius stays for the retry.
            let crossed = rejected && self.guard_crossed(problem, &current.z, &z);
            // A trial that could not be integrated after it put unknowns on bounds they were
            // not on is blamed on those bounds (where the model may not be integrable though
            // it is on either side): the unknowns are held off them from now on, and the
            // same step is tried with them held off. Where that retry is not taken either,
            // the bounds are not shown to be to blame (a step too long fails on either side
            // of them): they are released, not suspected again from this iterate, and the
            // run goes on from the first trial as if they had never been suspected.
            let failed = evaluated.is_none() && decrease == f64::NEG_INFINITY;
            let released = match self.held.take() {
                Some(held) if rejected => {
                    for &i in &held.unknowns {
                        self.curve.held_off[i] = false;
                    }
                    self.cleared.extend(&held.unknowns);
                    (self.radius, trial) = (held.radius, held.trial);
                    true
                }
                _ => false,
            };
            let walled =
                failed && !crossed && !released && self.hold_off(problem, &current.z, &z, &trial);
            if !walled {
                self.rejections = (1.0 - SCREEN_MEMORY) * self.rejections
                    + SCREEN_MEMORY * f64::from(u8::from(rejected));
                left -= 1;
            }
            if released || walled {
                // Blamed: the retry keeps the radius; released: the first failure's radius
                // is back (above).
            } else if rho < 0.25 && !crossed {
                self.radius = self.shrunk(&trial);
            } else if !crossed && (rho >= 0.75 || trial.lambda == 0.0) {
                self.radius = 2.0 * trial.scaled_norm;
            }
            if self.options.hessian == Hessian::Adaptive && decrease.is_finite() && !released {
                let profiled = self.profiled(lin);
                self.secant.choose(profiled.as_ref().unwrap_or(lin), &trial.delta, decrease);
            }
            if let Some(l) = evaluated.filter(|_| rho >= ACCEPT) {
                self.release_kinks(problem, &l);
                self.cleared.clear();
                self.fall = Some((lin.cost - l.cost) / lin.cost);
                // Not over a kink of a switch time: the secant's premise, a smooth objective
                // along the step, fails there (a to-and-fro step of two slivers would teach it
                // the slope's jump over them as curvature).
                if self.options.hessian == Hessian::Adaptive && !self.curve.guarded.contains(&true)
                {
                    let step = DVector::from_iterator(
                        l.z.len(),
                        l.z.iter().zip(&lin.z).map(|(a, b)| a - b),
                    );
                    self.secant.update(lin, &l, &step);
                }
                return Ok(Advance::Moved(Iterate::linearized(l)));
            }
            // The other model may predict the rejected step's outcome better: the retry
            // uses it.
            if self.options.hessian == Hessian::Adaptive {
                self.newton = self.secant.model(lin);
            }
            if trial.delta.norm() <= negligible || !(self.radius > 0.0 && self.radius.is_finite()) {
                return Ok(Advance::Stop(Rule::Step));
            }
            // The same step again (the Gauss–Newton step, inside the shrunk region) would give
            // the same ρ: the radius halves until the step changes, without integrating it.
            let mut next = self.step(ev, lin)?;
            for _ in 0..MAX_SAME {
                if next.delta != trial.delta {
                    break;
                }
                self.radius *= 0.5;
                next = self.step(ev, lin)?;
            }
            trial = next;
            z = problem.unknowns().moved(&current.z, trial.delta.as_slice(), 1.0);
        }
        Ok(Advance::Stop(Rule::NoDescent))
    }
}

impl TrustRegion<'_> {
    /// The model the steps from the iterate `lin` are found on now: Newton's where there is
    /// one at `lin` (the hybrid's differenced Hessian, or NL2SOL's augmented A + S), else
    /// Gauss–Newton's.
    fn model_name(&self, lin: &Linearization) -> &'static str {
        let newton = self.newton.as_ref().is_some_and(|n| same_iterate(n, lin));
        match (newton, self.options.hessian) {
            (true, Hessian::Adaptive) => "augmented",
            (true, _) => "newton",
            (false, _) => "gauss-newton",
        }
    }

    /// Records the cost of the iterate an advance starts from, and whether the run crawls
    /// there: its cost fell by less than [`CRAWL_FALL`] of ε over the last [`CRAWL_WINDOW`]
    /// iterations. `cost` is the iterate's as the driver records it, `epsilon` its ε: under
    /// hierarchical optimisation the cost is the profile's, twice the NLL up to a constant,
    /// whose differences compare between iterates but whose size is the constant's (it
    /// crosses 0), so the fall is measured against ε, as the driver's progress rule measures
    /// it.
    fn crawls(&mut self, cost: f64, epsilon: f64) -> bool {
        self.costs.push_back(cost);
        if self.costs.len() > CRAWL_WINDOW + 1 {
            self.costs.pop_front();
        }
        crawled(&self.costs, epsilon)
    }

    /// The trial `l` (the step `trial` from the iterate `lin`) corrected by a chord step with
    /// the iterate's Jacobian J and the same λ (with λ = 0 and no bound in the way, the
    /// Gauss–Newton step from the trial with J):
    /// (A + λD²) c = −Jᵀ(r(z + δ) − r(z) − Jδ), solved on the unknowns the step leaves free,
    /// and z + δ + c put in the box, linearized. The bend r(z + δ) − r(z) − Jδ is what the
    /// linear model missed over the step; in a curved valley it is the step's departure from
    /// the floor, and c brings it back, as Transtrum and Sethna's geodesic acceleration does
    /// with a second difference over a tenth of the step ([`sysid_core::method::Geodesic`]),
    /// here over the whole step. None where there are no residual rows, the system is
    /// singular, or the corrected point cannot be integrated.
    fn corrected<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        lin: &Linearization,
        l: &Linearization,
        trial: &CurveStep,
    ) -> Result<Option<(Linearization, Vec<f64>)>, Failure> {
        let problem = ev.problem();
        let (Some(rows), Some(at)) = (&lin.residuals, &l.residuals) else { return Ok(None) };
        if at.r.len() != rows.r.len() {
            return Ok(None);
        }
        let bend = &at.r - &rows.r - &rows.jacobian * &trial.delta;
        let force = -rows.jacobian.tr_mul(&bend);
        let (lo, hi) = self.curve.step_box(problem, lin, false);
        let max_condition = self.options.driver.max_condition;
        let Some(c) = self.curve.correction(lin, trial, &force, (&lo, &hi), max_condition) else {
            return Ok(None);
        };
        let delta = DVector::from_fn(trial.delta.len(), |i, _| match c[i] {
            0.0 => trial.delta[i],
            c => (trial.delta[i] + c).clamp(lo[i], hi[i]),
        });
        let z = problem.unknowns().moved(&lin.z, delta.as_slice(), 1.0);
        match ev.linearize(&z) {
            Ok(c) => Ok(Some((c, z))),
            Err(budget @ Failure::Budget { .. }) => Err(budget),
            Err(_) => Ok(None),
        }
    }

    /// Guards the unknowns a trial from `from` to `to` took over a kink where a switch time
    /// passes a sample time ([`Curve::guarded`](sysid_core::method::Curve)): their steps keep
    /// to the kinks next to them, overstepped by a sliver. Whether any was newly guarded.
    fn guard_crossed<S: System>(&mut self, problem: &Problem<S>, from: &[f64], to: &[f64]) -> bool {
        let mut any = false;
        let guarded = &mut self.curve.guarded;
        guarded.resize(from.len(), false);
        for (i, around) in problem.kinks(from).into_iter().enumerate() {
            if let Some(a) = around
                && !guarded[i]
                && (to[i] < a.lo || to[i] > a.hi)
            {
                guarded[i] = true;
                any = true;
            }
        }
        any
    }

    /// The radius after the rejected trial `trial`: ½·min(Δ, 10‖Dδ‖), MINPACK's.
    fn shrunk(&self, trial: &CurveStep) -> f64 {
        0.5 * self.radius.min(10.0 * trial.scaled_norm)
    }

    /// Holds off their bounds ([`Curve::held_off`](sysid_core::method::Curve)) the unknowns
    /// that the trial `trial` from `from` to `to` put on a bound they were not on (to
    /// rounding), but for those cleared of it at this iterate, and keeps the trial and the
    /// radius its failure would leave until the retry decides. Whether any was held off.
    fn hold_off<S: System>(
        &mut self,
        problem: &Problem<S>,
        from: &[f64],
        to: &[f64],
        trial: &CurveStep,
    ) -> bool {
        let held = &mut self.curve.held_off;
        held.resize(from.len(), false);
        let mut unknowns = Vec::new();
        for (i, u) in problem.unknowns().list().iter().enumerate() {
            let (lo, hi) = u.coordinate_bounds();
            let on =
                |z: f64, b: f64| (z - b).abs() <= 4.0 * f64::EPSILON * (from[i].abs() + b.abs());
            let onto = |b: f64| b.is_finite() && on(to[i], b) && !on(from[i], b);
            if !held[i] && !self.cleared.contains(&i) && (onto(lo) || onto(hi)) {
                held[i] = true;
                unknowns.push(i);
            }
        }
        if unknowns.is_empty() {
            return false;
        }
        self.held = Some(Held { unknowns, radius: self.shrunk(trial), trial: trial.clone() });
        true
    }

    /// Releases the guarded unknowns of the new iterate `lin` that are no longer held by a
    /// kink: not at one, or at one their descent direction leads away from.
    fn release_kinks<S: System>(&mut self, problem: &Problem<S>, lin: &Linearization) {
        if !self.curve.guarded.contains(&true) {
            return;
        }
        let kinks = problem.kinks(&lin.z);
        for (i, guarded) in self.curve.guarded.iter_mut().enumerate() {
            let held = kinks[i].is_some_and(|a| a.at(lin.z[i], -lin.gradient[i]).is_some());
            *guarded &= held;
        }
    }

    /// The trial point z linearized, with its decrease from `lin`: under hierarchical
    /// optimisation the profile's (the scales then move to the trial's closed form, which
    /// lowers ε further). `None` and −∞ where the model cannot be integrated there (a step
    /// too long).
    fn evaluate<S: System>(
        &self,
        ev: &Evaluations<'_, S>,
        lin: &Linearization,
        z: &[f64],
        predicted: f64,
        resolution: f64,
    ) -> Result<(Option<Linearization>, f64), Failure> {
        match ev.linearize(z) {
            Ok(l) => {
                let gain = if ev.profiling() { ev.problem().profile_gain(&l) } else { 0.0 };
                let decrease = actual_decrease(lin, &l, predicted, resolution) + gain;
                Ok((Some(l), decrease))
            }
            Err(budget @ Failure::Budget { .. }) => Err(budget),
            Err(_) => Ok((None, f64::NEG_INFINITY)),
        }
    }
}

/// Whether the model `n` (Newton's, kept from an earlier call) is the one at the iterate
/// `lin`: the same point and the same ε to the bit.
fn same_iterate(n: &Linearization, lin: &Linearization) -> bool {
    n.z == lin.z && n.cost.to_bits() == lin.cost.to_bits()
}

/// Whether `costs`, the last [`CRAWL_WINDOW`] + 1 iterates' oldest first, fell by less than
/// [`CRAWL_FALL`] of `epsilon`, the last one's ε.
fn crawled(costs: &VecDeque<f64>, epsilon: f64) -> bool {
    match (costs.front(), costs.back()) {
        (Some(first), Some(last)) if costs.len() > CRAWL_WINDOW => {
            first - last < CRAWL_FALL * epsilon.abs()
        }
        _ => false,
    }
}

/// The step length below which a step does not count: tol·(‖z‖ + tol), tol the resolvable
/// step tolerance.
fn negligible_step<S: System>(problem: &Problem<S>, z: &[f64], step_tolerance: f64) -> f64 {
    let step_tolerance = problem.resolvable_step(step_tolerance);
    let z_norm = z.iter().map(|v| v * v).sum::<f64>().sqrt();
    step_tolerance * (z_norm + step_tolerance)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Costs falling evenly by `fall` over the window, from `first`.
    fn window(first: f64, fall: f64) -> VecDeque<f64> {
        (0..=CRAWL_WINDOW).map(|i| first - fall * i as f64 / CRAWL_WINDOW as f64).collect()
    }

    /// Under hierarchical optimisation a cost is the profile's, 2·NLL up to a constant that
    /// can put it near 0: the crawl is judged against ε, so the same fall is a crawl or not
    /// whatever the constant.
    #[test]
    fn a_crawl_is_judged_against_epsilon_not_the_profiles_constant() {
        let epsilon = 313.0;
        let slow = 0.5 * CRAWL_FALL * epsilon;
        let fast = 2.0 * CRAWL_FALL * epsilon;
        for first in [0.1, -40.0, 1e4] {
            assert!(crawled(&window(first, slow), epsilon), "from {first}");
            assert!(!crawled(&window(first, fast), epsilon), "from {first}");
        }
        let mut short = window(0.1, slow);
        short.pop_front();
        assert!(!crawled(&short, epsilon), "a window not yet full");
    }
}
