//! Every model integration a method makes goes through [`Evaluations`]: it counts the work,
//! enforces the hard budget of integrations (inside line searches and step halvings too, so
//! no fit runs without an end), and turns what cannot be used (an integration failure, a
//! cost or gradient that overflows) into a [`Failure`] that names the point.
//!
//! The driver may refine the integration during a run ([`refine`](Evaluations::refine)):
//! from then on every evaluation integrates at a tenth of the tolerances, so that the
//! certificate is measured more accurately than it is tested.
//!
//! While a method that retreats from a failed trial proposes and moves, the driver
//! [paces](Evaluations::pace) it: each integration may take at most [`PACE`] times the steps
//! of the iterate's own evaluation (rounded up to a power of two, at least [`PACE_FLOOR`],
//! never more than the integrator's `max_steps`; a preequilibration's steady-state solve
//! keeps the integrator's own limit, as its steps are not among those counted). A trial
//! step into a region where the model
//! needs far more work than at the iterate (a stiff blow-up, say) then fails as soon as that
//! is clear, and the method shortens the step, instead of spending the whole step budget to
//! learn the same; the iterates' own cost moves the limit with them. The certificate's
//! evaluations are never paced, nor is the accurate plain cost ([`Evaluations::cost`]).

use std::cell::{Cell, RefCell};

use nalgebra::DVector;
use sysid_ode::{Counts, Integrator, OdeError, Scheme, System};

use crate::evaluate::Linearization;
use crate::problem::Problem;
use crate::termination::Failure;

/// Counted, budgeted access to a problem's evaluations. One per fit; not shared between
/// threads.
pub struct Evaluations<'p, S> {
    base: &'p Problem<S>,
    /// The problem as evaluated now, once the driver refined its integrator tolerances or
    /// set its noise scales.
    refined: Option<Problem<S>>,
    budget: u64,
    counts: Cell<Counts>,
    /// Whether the driver sets the noise scales to their closed form at every iterate.
    profiling: bool,
    /// The step limit of each experiment's integration while the integrations are
    /// [paced](Self::pace) below the problem's own `max_steps`.
    limit: Option<usize>,
    /// The error of the last integration made here, where it failed ([`last_failed`](Self::last_failed)).
    failed: RefCell<Option<OdeError>>,
}

/// A paced integration may take this many times the steps (accepted and rejected) of the
/// iterate's evaluation.
pub const PACE: u64 = 10;

/// The least step limit of a paced integration.
pub const PACE_FLOOR: usize = 1024;

/// The relative tolerance a [coarse first](crate::method::Step::coarse_first) run integrates
/// at until its iterates close in on a minimum ([`coarser`]).
pub const COARSE_RTOL: f64 = 1e-6;

/// `integrator` at [`COARSE_RTOL`], its atol scaled by the same factor, for the first stage
/// of a coarse-first run; `None` where that would not be at least 10 times looser: a fixed
/// step, or rtol already above a tenth of [`COARSE_RTOL`].
pub fn coarser(integrator: &Integrator) -> Option<Integrator> {
    if integrator.fixed_step.is_some() || integrator.rtol > 0.1 * COARSE_RTOL {
        return None;
    }
    let factor = COARSE_RTOL / integrator.rtol;
    Some(Integrator { rtol: COARSE_RTOL, atol: integrator.atol * factor, ..*integrator })
}

/// The tightest relative tolerance [`Evaluations::finer`] refines to.
pub const FINEST_RTOL: f64 = 1e-12;

/// `integrator` at a tenth of its rtol and atol ([`Evaluations::finer`]), or `None` where
/// that cannot be more accurate: a fixed step, or rtol already at [`FINEST_RTOL`]. An atol
/// above rtol is taken as rtol first.
pub fn finer(integrator: &Integrator) -> Option<Integrator> {
    if integrator.fixed_step.is_some() || integrator.rtol * 0.1 < FINEST_RTOL * 0.99 {
        return None;
    }
    let mut finer = *integrator;
    finer.rtol *= 0.1;
    finer.atol = integrator.atol.min(integrator.rtol) * 0.1;
    Some(finer)
}

/// The scheme an integration at the finest tolerances is compared with
/// ([`Evaluations::reference`]): one of another order and construction that integrates the
/// same models. `auto`, which steps with DOP853 at such tolerances and with Rodas5P where
/// the model is stiff, against Rodas4 (neither of its own: against Rodas5P a stiff model
/// would be integrated twice the same way, a difference of 0 that measures nothing);
/// DOPRI5 and DOP853 against each other (explicit, as the user chose them); a Rosenbrock
/// scheme against the other; BDF against Rodas5P.
pub fn other_scheme(scheme: Scheme) -> Scheme {
    match scheme {
        Scheme::Auto | Scheme::Rodas5p => Scheme::Rodas4,
        Scheme::Rodas4 | Scheme::Bdf => Scheme::Rodas5p,
        Scheme::Dopri5 | Scheme::Rk4 => Scheme::Dop853,
        Scheme::Dop853 => Scheme::Dopri5,
    }
}

/// The relative tolerance of the error-controlled integration a fixed-step run's
/// certificate is measured against ([`Evaluations::reference`]).
pub const REFERENCE_RTOL: f64 = 1e-10;

impl<'p, S: System> Evaluations<'p, S> {
    /// Evaluations of `problem` with a budget of `budget` integrations.
    pub fn new(problem: &'p Problem<S>, budget: u64) -> Self {
        Self {
            base: problem,
            refined: None,
            budget,
            counts: Cell::new(Counts::default()),
            profiling: false,
            limit: None,
            failed: RefCell::new(None),
        }
    }

    /// The error of the last integration made through these evaluations, where it failed:
    /// a method that stops after its trials could not be integrated (a trust region shrunk
    /// to nothing at the edge of where the model has a solution) says so by it.
    pub fn last_failed(&self) -> Option<OdeError> {
        self.failed.borrow().clone()
    }

    /// The problem, at the integrator tolerances of the run so far.
    pub fn problem(&self) -> &Problem<S> {
        self.refined.as_ref().unwrap_or(self.base)
    }

    /// The problem integrated at a tenth of the current rtol and atol, or `None` where that
    /// cannot be more accurate: a fixed step (the run keeps the scheme it was given), or
    /// rtol already at [`FINEST_RTOL`]. An atol above rtol is taken as rtol first: an
    /// absolute tolerance larger than the relative one controls nothing for states of order
    /// 1 (`--atol 1e300` would otherwise be "refined" to 1e299).
    pub fn finer(&self) -> Option<Problem<S>> {
        let problem = self.problem();
        problem.clone().with_integrator(finer(problem.integrator())?).ok()
    }

    /// Whether [`reference`](Self::reference) is another scheme at the same tolerances
    /// (rtol already within a factor 10 of [`FINEST_RTOL`]) rather than a finer integration.
    pub fn reference_is_another_scheme(&self) -> bool {
        let integrator = self.problem().integrator();
        integrator.fixed_step.is_none() && finer(integrator).is_none()
    }

    /// The problem as the certificate measures its integration error against: [`finer`]
    /// for an error-controlled integration; where rtol is already within a factor 10 of
    /// [`FINEST_RTOL`], so that nothing is finer, the same tolerances with another scheme
    /// ([`other_scheme`]: their difference is the larger of the two errors, unless they
    /// happen to cancel); for a fixed step, the same model integrated with error control at
    /// rtol [`REFERENCE_RTOL`](crate::method::REFERENCE_RTOL) (DOPRI5, or the Rosenbrock
    /// scheme of a fixed-step Rosenbrock run), so that a step too coarse to resolve the
    /// model shows in the error instead of passing as exact.
    ///
    /// [`finer`]: Self::finer
    pub fn reference(&self) -> Option<Problem<S>> {
        let problem = self.problem();
        let integrator = problem.integrator();
        if integrator.fixed_step.is_none() {
            if let Some(finer) = self.finer() {
                return Some(finer);
            }
            let mut other = *integrator;
            other.scheme = other_scheme(integrator.scheme);
            return problem.clone().with_integrator(other).ok();
        }
        let mut reference = *integrator;
        reference.fixed_step = None;
        reference.scheme = match integrator.scheme {
            Scheme::Rk4 | Scheme::Dopri5 | Scheme::Auto => Scheme::Dopri5,
            Scheme::Dop853 => Scheme::Dop853,
            stiff @ (Scheme::Rodas4 | Scheme::Rodas5p | Scheme::Bdf) => stiff,
        };
        reference.rtol = REFERENCE_RTOL;
        reference.atol = integrator.atol.min(REFERENCE_RTOL) * 0.1;
        problem.clone().with_integrator(reference).ok()
    }

    /// Evaluates from now on with `problem` (one of [`finer`](Self::finer)'s).
    pub fn refine(&mut self, problem: Problem<S>) {
        self.refined = Some(problem);
    }

    /// Whether the driver sets the noise scales to their closed form at every iterate
    /// (hierarchical optimisation: a [profiling](crate::method::Step::profiles) method's
    /// model is then the profile's).
    pub fn profiling(&self) -> bool {
        self.profiling
    }

    /// Marks the run as one that sets the scales at every iterate.
    pub(crate) fn profile_scales(&mut self) {
        self.profiling = true;
    }

    /// Evaluates from now on with the noise scales at `sigma` (one per
    /// [`Problem::scales`]), at the integration of the run so far.
    pub fn set_scales(&mut self, sigma: &[f64]) {
        self.refined = Some(self.problem().with_scales(sigma));
    }

    /// Paces the integrations from now on at the work of an iterate whose evaluation took
    /// `iterate` (see the module's documentation), or, with `None`, stops pacing them.
    pub(crate) fn pace(&mut self, iterate: Option<&Counts>) {
        self.limit = iterate.and_then(|iterate| {
            let work = (iterate.steps + iterate.rejected_steps).saturating_mul(PACE);
            let limit = usize::try_from(work).unwrap_or(usize::MAX).max(PACE_FLOOR);
            let limit = limit.checked_next_power_of_two().unwrap_or(usize::MAX);
            (limit < self.problem().integrator().max_steps).then_some(limit)
        });
    }

    /// The integrator of the experiments' next integration: the problem's, with the step
    /// limit of the [pace](Self::pace) while there is one. (Settings computed by integration,
    /// a preequilibration's steady state, keep the problem's own: their steps are not among
    /// those the limit is drawn from.)
    fn integrator(&self) -> Integrator {
        let own = *self.problem().integrator();
        match self.limit {
            Some(limit) => Integrator { max_steps: limit.min(own.max_steps), ..own },
            None => own,
        }
    }

    /// The work so far.
    pub fn counts(&self) -> Counts {
        self.counts.get()
    }

    /// The budget of integrations.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Runs `integrate`, which makes model integrations and returns its work, if the budget
    /// allows another; a failure is reported at the values of `z`.
    pub fn run<T>(
        &self,
        z: &[f64],
        integrate: impl FnOnce() -> Result<(T, Counts), OdeError>,
    ) -> Result<T, Failure> {
        // An evaluation integrates every experiment once, each counting as one: it is made
        // only where all of them fit in the budget (with two experiments and a budget of 7,
        // the fourth evaluation had made 8).
        let used = self.counts.get().integrations;
        let cost = self.problem().experiments().len().max(1) as u64;
        if used.saturating_add(cost) > self.budget {
            return Err(Failure::Budget { integrations: self.budget });
        }
        match integrate() {
            Ok((value, counts)) => {
                self.add(counts);
                *self.failed.borrow_mut() = None;
                Ok(value)
            }
            // The model integrated; a residual's square overflowed, or a σ fell below what
            // the likelihood's rows hold.
            Err(OdeError::Unrepresentable { what, .. }) => {
                // Counted as the failures below are: one integration (its work is not known
                // here), so that the budget still ends every fit.
                self.add(Counts { integrations: 1, ..Counts::default() });
                *self.failed.borrow_mut() = None;
                Err(Failure::NonFinite { what, at: self.values(z) })
            }
            Err(error) => {
                // A failed integration counts as one; one that ran out of steps or blew up,
                // with the steps it took (accepted and rejected together, as the budget
                // counts them). Other failures' work is not known here.
                let steps = match error {
                    OdeError::TooManySteps { steps, .. }
                    | OdeError::Stiff { steps, .. }
                    | OdeError::BlowUp { steps, .. } => steps as u64,
                    _ => 0,
                };
                self.add(Counts { integrations: 1, steps, ..Counts::default() });
                *self.failed.borrow_mut() = Some(error.clone());
                Err(Failure::Integration { error, at: self.values(z) })
            }
        }
    }

    /// Adds work done outside [`run`](Self::run).
    pub fn add(&self, counts: Counts) {
        let mut c = self.counts.get();
        c += counts;
        self.counts.set(c);
    }

    /// ε, U and A at z ([`Problem::linearize`]), all finite.
    pub fn linearize(&self, z: &[f64]) -> Result<Linearization, Failure> {
        let lin =
            self.run(z, || self.problem().linearize_with(z, &self.integrator()).map(with_counts))?;
        self.check(z, &lin)?;
        Ok(lin)
    }

    /// The weighted residuals and their Jacobian at z
    /// ([`Problem::residuals_and_jacobian`]), with ε, U and A, all finite.
    pub fn residuals_and_jacobian(&self, z: &[f64]) -> Result<Linearization, Failure> {
        let lin = self
            .run(z, || self.problem().linearize_sampled(z, &self.integrator()).map(with_counts))?;
        self.check(z, &lin)?;
        Ok(lin)
    }

    /// The weighted residuals at z ([`Problem::residuals`]), with a finite sum of squares.
    pub fn residuals(&self, z: &[f64]) -> Result<DVector<f64>, Failure> {
        let r = self.run(z, || self.problem().residuals_with(&self.integrator(), z))?;
        if !r.norm_squared().is_finite() {
            return Err(self.overflow(z, "the cost ε", Some(&r)));
        }
        Ok(r)
    }

    /// ε at z by the accurate plain integration ([`Problem::cost`]), finite.
    pub fn cost(&self, z: &[f64]) -> Result<f64, Failure> {
        let cost = self.run(z, || self.problem().cost(z))?;
        if !cost.is_finite() {
            return Err(self.overflow(z, "the cost ε", None));
        }
        Ok(cost)
    }

    fn values(&self, z: &[f64]) -> Vec<f64> {
        self.problem().unknowns().values(z)
    }

    fn check(&self, z: &[f64], lin: &Linearization) -> Result<(), Failure> {
        let r = lin.residuals.as_ref().map(|w| &w.r);
        if !lin.cost.is_finite() {
            return Err(self.overflow(z, "the cost ε", r));
        }
        if lin.gradient.iter().any(|v| !v.is_finite()) {
            return Err(self.overflow(z, "the gradient U", None));
        }
        if lin.normal.iter().any(|v| !v.is_finite()) {
            return Err(self.overflow(z, "the normal matrix A", None));
        }
        Ok(())
    }

    /// A non-finite quantity at z; for the cost, the residual row that overflows (the
    /// largest one when only their sum does).
    fn overflow(&self, z: &[f64], what: &str, r: Option<&DVector<f64>>) -> Failure {
        let what = match r {
            Some(r) if !r.is_empty() => {
                let row = r.iamax();
                format!(
                    "{what} (the weighted residual of {} is {:e}; its square overflows)",
                    self.problem().describe_row(row),
                    r[row]
                )
            }
            _ => what.to_string(),
        };
        Failure::NonFinite { what: format!("{what} is not finite"), at: self.values(z) }
    }
}

fn with_counts(lin: Linearization) -> (Linearization, Counts) {
    let counts = lin.counts;
    (lin, counts)
}

#[cfg(test)]
mod tests {
    use sysid_ode::testing::Decay;

    use super::*;
    use crate::{Data, Experiment, Setting};

    /// x' = −k x from x(0) = 1, sampled at t = 1 and 2, integrated by DOPRI5: a handful of
    /// steps at k = 0.5; at k = 1e4 stability limits the steps to about 3.3/k, some 6 000.
    fn decay() -> Problem<Decay> {
        let t = [1.0, 2.0];
        let experiment = Experiment {
            name: "decay".into(),
            also: Vec::new(),
            system: Decay::new(),
            t0: 0.0,
            initial: vec![Setting::Value(1.0)],
            parameters: vec![Setting::Unknown("k".into())],
            data: Data::discrete().series("x", &t, &[0.6, 0.4]),
        };
        let integrator = Integrator { scheme: Scheme::Dopri5, ..Integrator::default() };
        Problem::builder(Decay::new())
            .unknown("k", 0.5)
            .experiment(experiment)
            .integrator(integrator)
            .build()
            .expect("a valid problem")
    }

    /// The certificate's reference: a tenth of the tolerances while there is one; at the
    /// finest rtol the same tolerances with another scheme, whose cost differs from the
    /// working integration's by the size of the larger of their errors (each measured
    /// against the closed form x(t) = e^{−kt}).
    #[test]
    fn at_the_finest_rtol_the_reference_is_another_scheme() {
        let problem = decay();
        let ev = Evaluations::new(&problem, 100);
        let reference = ev.reference().expect("a finer integration");
        assert_eq!(reference.integrator().scheme, Scheme::Dopri5);
        assert!((reference.integrator().rtol - 0.1 * problem.integrator().rtol).abs() < 1e-20);
        let tight = Integrator { rtol: 5e-12, atol: 5e-16, ..*problem.integrator() };
        let finest = problem.clone().with_integrator(tight).expect("valid tolerances");
        let ev = Evaluations::new(&finest, 100);
        let reference = ev.reference().expect("another scheme");
        assert_eq!(reference.integrator().scheme, Scheme::Dop853);
        assert_eq!((reference.integrator().rtol, reference.integrator().atol), (5e-12, 5e-16));
        let exact: f64 = [(1.0, 0.6), (2.0, 0.4)]
            .iter()
            .map(|&(t, b): &(f64, f64)| ((-0.5 * t).exp() - b).powi(2))
            .sum();
        let cost = |p: &Problem<Decay>| p.cost(&[0.5]).expect("integrates").0;
        let (working, other) = (cost(&finest), cost(&reference));
        let errors = ((working - exact).abs(), (other - exact).abs());
        let measured = (working - other).abs();
        // Here 3.1e-15 against errors of 1.7e-15 and 4.8e-15 (4.5e-12 of ε).
        let larger = errors.0.max(errors.1);
        assert!(measured >= 0.25 * larger && larger < 1e-11 * exact, "{measured:e}, {errors:?}");
        // `auto` steps with DOP853 and Rodas5P there: it is compared with neither.
        for scheme in [Scheme::Auto, Scheme::Rodas5p] {
            let finest = Integrator { scheme, ..tight };
            let problem = problem.clone().with_integrator(finest).expect("valid");
            let other = Evaluations::new(&problem, 100).reference().expect("another scheme");
            assert_eq!(other.integrator().scheme, Scheme::Rodas4);
        }
    }

    #[test]
    fn a_paced_trial_fails_at_ten_times_the_iterates_steps_and_counts_them() {
        let problem = decay();
        let mut ev = Evaluations::new(&problem, 100);
        let iterate = ev.linearize(&[0.5]).expect("k = 0.5 integrates").counts;
        let work = iterate.steps + iterate.rejected_steps;
        assert!(10 * work < PACE_FLOOR as u64, "{work} steps at the iterate");
        // Unpaced, the stiff point integrates within the 100 000-step budget.
        let free = ev.residuals(&[1e4]).map(|r| r.len());
        assert_eq!(free, Ok(2));
        let unpaced = ev.counts().steps;
        assert!(unpaced > 4 * PACE_FLOOR as u64, "{unpaced} steps in all");
        // Paced at the iterate, it fails at the floor's 1 024 steps, and they are counted.
        ev.pace(Some(&iterate));
        let before = ev.counts();
        match ev.residuals(&[1e4]) {
            Err(Failure::Integration {
                error: OdeError::Stiff { steps, .. } | OdeError::TooManySteps { steps, .. },
                ..
            }) => assert_eq!(steps, PACE_FLOOR),
            other => panic!("expected the step limit, got {other:?}"),
        }
        let after = ev.counts();
        assert_eq!(after.integrations - before.integrations, 1);
        assert_eq!(after.steps - before.steps, PACE_FLOOR as u64);
        // The point the iterate is at still integrates, paced.
        assert!(ev.residuals(&[0.5]).is_ok());
        // Unpaced again, the stiff point integrates.
        ev.pace(None);
        assert!(ev.residuals(&[1e4]).is_ok());
        // An iterate whose own work is a tenth of the budget or more leaves it as it is.
        ev.pace(Some(&Counts { steps: 10_000, ..Counts::default() }));
        assert!(ev.residuals(&[1e4]).is_ok());
    }

    #[test]
    fn the_pace_is_ten_times_the_iterates_work_rounded_up_to_a_power_of_two() {
        let problem = decay();
        let mut ev = Evaluations::new(&problem, 100);
        ev.pace(Some(&Counts { steps: 150, rejected_steps: 20, ..Counts::default() }));
        assert_eq!(ev.integrator().max_steps, 2048, "10 × 170 = 1 700, rounded up");
        ev.pace(None);
        assert_eq!(ev.integrator().max_steps, 100_000);
    }
}
