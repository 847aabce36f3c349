//! The NLL with its gradient, by forward sensitivities or by adjoints.
//!
//! The gradient of the NLL is U = Jᵀr (r the weighted residual rows, J = ∂r/∂z). Forward
//! sensitivities form J, one column per slot (an initial value or parameter that depends on
//! an unknown), integrated with the states: n·(1 + slots) values. The methods that need J
//! itself (Gauss–Newton, Levenberg–Marquardt, the trust regions' normal matrix) have to
//! integrate them. The gradient alone does not: each row's ∂R/∂z is
//! ∂R/∂y(t_m)·S(t_m)·∂slot/∂z plus what depends on the unknowns directly, so
//!
//! U = Σ_m c_mᵀ S(t_m) ∂slot/∂z + (direct), c_m = Σ_{rows at t_m} R ∂R/∂y(t_m),
//!
//! and the sum Σ_m c_mᵀ S(t_m) is one backward integration of n + slots values
//! ([`Ivp::adjoint`](sysid_ode::Ivp::adjoint)) along the states. c_m and the direct part are
//! the rows' own derivatives, formed by the same code that forms J (so that the two ways
//! cannot disagree on what a row is): once with the slots as columns and their sensitivities
//! zero (the direct part), once with the states as columns, their sensitivities the identity
//! and nothing direct (c_m).

use nalgebra::DMatrix;
use sysid_ode::{Counts, Ivp, OdeError, System, Wrt};

use crate::evaluate::{At, Rows, experiment_rows, sample_rows, slot_matrix};
use crate::experiment::{Choice, Planned};
use crate::problem::Problem;

/// How the gradient of the NLL is had.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensitivities {
    /// Forward sensitivities of every slot, integrated with the states: the residuals'
    /// Jacobian, of which the gradient is Jᵀr.
    Forward,
    /// One backward adjoint integration per experiment along its states (through its state
    /// events by their jump conditions). An experiment the adjoint does not handle (samples
    /// before t0, a state event at t0 or at its last sample), or whose backward integration
    /// fails, is integrated forward.
    Adjoint,
    /// Each experiment by whichever of the two did less work the first time its gradient
    /// was asked for: that first time it is computed both ways, each with its cached steady
    /// state forgotten before it (so that both solve it), and the work of each is the
    /// arithmetic its integrations counted ([`Counts::operations`]), the adjoint's weighted
    /// by [`ADJOINT_OPERATION_COST`]. The adjoint is chosen where its weighted work is the
    /// smaller, and the chosen way's gradient is returned; later gradients take that way only.
    /// The choice is the same on every run and every machine. An experiment the adjoint does
    /// not handle, or whose backward integration failed at that first gradient, goes forward
    /// (reported in [`NllGradient::fell_back`]); a first point where either way cannot be
    /// integrated is not counted from, and the next gradient counts again. The choice belongs
    /// to the problem and its copies at other noise scales, and is made again when the free
    /// unknowns or the integrator change.
    Auto,
}

/// The NLL at a point and its gradient.
#[derive(Clone, Debug, PartialEq)]
pub struct NllGradient {
    /// The negative log-likelihood (without the priors' term).
    pub nll: f64,
    /// ∂NLL/∂z for the free unknowns' coordinates, then the noise scales': the order of
    /// [`Problem::parameters`].
    pub gradient: Vec<f64>,
    /// The work done.
    pub counts: Counts,
    /// The experiments (indices into [`Problem::experiments`]) whose part of the gradient
    /// came from forward sensitivities although adjoints were asked for: those the adjoint
    /// does not handle (samples before t0, a state event at t0 or at the last sample) and
    /// those whose backward integration failed. Empty for [`Sensitivities::Forward`].
    pub fell_back: Vec<usize>,
    /// The experiments whose part of the gradient came from the adjoint.
    pub by_adjoint: Vec<usize>,
}

impl<S: System> Problem<S> {
    /// The NLL at z and its gradient, by forward sensitivities or by adjoints; `None` for a
    /// continuous record, which has no likelihood.
    pub fn nll_gradient(
        &self,
        z: &[f64],
        how: Sensitivities,
    ) -> Result<Option<NllGradient>, OdeError> {
        if self.is_continuous() {
            return Ok(None);
        }
        let k = self.unknowns.len();
        let (v, free_index, chain) = (self.values_at(z), self.free_index(), self.chain(z));
        let at = At {
            v: &v,
            free_index: &free_index,
            chain: &chain,
            integrator: &self.integrator,
            jacobian: true,
        };
        // Each experiment's U = Jᵀr on its own: the problem's whole linearization would also
        // form the normal matrix JᵀJ, which the gradient does not need (Beer, 72 unknowns:
        // 68 → 37 ms by forward sensitivities on one thread).
        let all = self.each_experiment(|e| match how {
            Sensitivities::Forward => {
                forward_gradient(e, &at, k).map(|(rows, u, _)| (rows, u, false, false))
            }
            Sensitivities::Adjoint => experiment_gradient(e, &at, k)
                .map(|(rows, u, adjoint)| (rows, u, adjoint, !adjoint)),
            Sensitivities::Auto => auto_gradient(e, &at, k),
        })?;
        let (mut gradient, mut counts) = (vec![0.0; k], Counts::default());
        for (rows, u, ..) in &all {
            gradient.iter_mut().zip(u).for_each(|(g, u)| *g += u);
            counts += rows.counts;
        }
        let by_adjoint = (0..all.len()).filter(|&i| all[i].2).collect();
        let fell_back = (0..all.len()).filter(|&i| all[i].3).collect();
        let costs = all.iter().map(|(rows, ..)| rows.r.iter().map(|r| r * r).sum::<f64>());
        let Some(nlls) = self.nlls(costs) else { return Ok(None) };
        gradient
            .extend(self.scale_gradient(all.iter().flat_map(|(rows, ..)| rows.r.iter().copied())));
        if let Some(i) = gradient.iter().position(|g| !g.is_finite()) {
            // Named: the gradient is in the order of the parameters.
            return Err(OdeError::NonFinite {
                t: self.span().0,
                what: format!(
                    "the NLL's derivative with respect to `{}`",
                    self.parameters()[i].name
                ),
            });
        }
        Ok(Some(NllGradient { nll: nlls.iter().sum(), gradient, counts, fell_back, by_adjoint }))
    }
}

/// What one counted operation of an adjoint gradient costs, in forward sensitivities' counted
/// operations, for [`Sensitivities::Auto`]'s choice.
///
/// [`Counts::operations`] charges each evaluation, factorisation and solve what its
/// structure says (a compiled program's operations, the products' multiply–adds, the
/// eliminations), not what the integrator does around them. The backward integration does
/// more of that per operation: it interpolates the forward solution and stops at every
/// sample, restarting there. Measured over the collection (docs/petab.md, one thread, the
/// median of 5 evaluations each way), an adjoint gradient's time per counted operation was
/// 0.7–5.4 times a forward gradient's, the median 2.2, when the backward steps also stopped
/// at every end of a forward step; 0.5–6.0, the median 1.4, since they do not (2026-12-03).
/// The weight is above the median so that the adjoint is taken only where it is clearly
/// ahead: forward's gradient is the one the fits' linearization has. Any weight from 1.6 to
/// 3.3 picks the faster way on every problem of the collection measured but Laske, whose
/// count (forward 1.28 times the adjoint's) lies among those where forward is faster (Weber
/// 1.34, Elowitz 1.56), and SalazarCavazos, where the two are within 7 %. Within that range
/// the weight moves only the problems whose experiments go both ways; over the collection
/// (2026-12-04, after forward's blocks of more than 16 columns got compile-time widths) 2.5
/// takes Alkan in 0.88 of the time 3 took (53 of its 73 experiments by adjoint, not 35) and
/// Smith in 0.96, and changes no other problem's time beyond the noise; at 2 Raia and
/// Brannmark were 8 % slower, at 1.5 Elowitz 1.6 times. Since f alone and f with ∂f/∂y
/// have programs of their own (2026-12-05), the adjoint's forward pass costs less: its time
/// per counted operation is 0.75–4.2 times forward's, the median 1.7, and 2 takes Laske in
/// 0.67 of the time 2.5 took (its first condition, counted 2.36 times the adjoint's work by
/// forward sensitivities, goes by adjoint) and Schwen in 0.96; Raia and Isensee, whose
/// choices 2 also moves, are within the noise; at 1.6 Elowitz is 1.47 times slower. Once
/// the backward parts carry the automatic choice's scheme from one to the next (the same
/// day), the adjoint counts less again and the weight is 2.5 once more: at 2 Elowitz's one
/// condition (counted 2.36) went by adjoint and took 1.22 times as long, while at 2.5
/// Laske's first condition (now 2.55) still goes by adjoint; Raia and Alkan are 2–3 %
/// slower than at 2.
pub const ADJOINT_OPERATION_COST: f64 = 2.5;

/// One experiment's rows, its part of U and whether it came from the adjoint, by the way
/// [`Sensitivities::Auto`] chose for it (measuring both the first time), and whether the
/// adjoint fell back to forward sensitivities (it does not apply, or its backward integration
/// failed).
fn auto_gradient<S: System>(
    e: &Planned<S>,
    at: &At<'_>,
    k: usize,
) -> Result<(Rows, Vec<f64>, bool, bool), OdeError> {
    if !adjoint_applies(e) {
        return forward_gradient(e, at, k).map(|(rows, u, _)| (rows, u, false, true));
    }
    match e.adjoint_cheaper.get() {
        Some(Choice::Adjoint) => {
            return experiment_gradient(e, at, k).map(|(rows, u, a)| (rows, u, a, !a));
        }
        Some(Choice::Forward) => {
            return forward_gradient(e, at, k).map(|(rows, u, _)| (rows, u, false, false));
        }
        Some(Choice::AdjointFailed) => {
            return forward_gradient(e, at, k).map(|(rows, u, _)| (rows, u, false, true));
        }
        None => {}
    }
    // Each way with its cached steady state forgotten before it, so that both solve it.
    let counted = |f: &dyn Fn() -> Result<(Rows, Vec<f64>, bool), OdeError>| {
        e.forget_cached();
        f()
    };
    let adjoint = counted(&|| experiment_gradient(e, at, k));
    let forward = counted(&|| forward_gradient(e, at, k));
    // Whether the backward integration ran (false: it failed, and forward took its place).
    let adjoint_ran = matches!(&adjoint, Ok((_, _, true)));
    // The choice is kept only where both ways could be integrated here: a point where one
    // cannot says nothing of their work, and the next gradient counts again.
    let choice = match (&adjoint, &forward) {
        (Ok(_), Ok(_)) if !adjoint_ran => Some(Choice::AdjointFailed),
        (Ok((by_adjoint, ..)), Ok((by_forward, ..))) => {
            let adjoint = ADJOINT_OPERATION_COST * by_adjoint.counts.operations as f64;
            Some(match adjoint < by_forward.counts.operations as f64 {
                true => Choice::Adjoint,
                false => Choice::Forward,
            })
        }
        _ => None,
    };
    if let Some(choice) = choice {
        let _ = e.adjoint_cheaper.set(choice);
    }
    // The returned way's work counts the other's too: all of it was done.
    let other = |r: &Result<(Rows, Vec<f64>, bool), OdeError>| {
        r.as_ref().map(|(rows, ..)| rows.counts).unwrap_or_default()
    };
    let by_adjoint = choice == Some(Choice::Adjoint) || (forward.is_err() && adjoint_ran);
    match by_adjoint {
        true => {
            let extra = other(&forward);
            adjoint.map(|(mut rows, u, _)| {
                rows.counts += extra;
                (rows, u, true, false)
            })
        }
        false => {
            let extra = other(&adjoint);
            forward.map(|(mut rows, u, _)| {
                rows.counts += extra;
                (rows, u, false, !adjoint_ran)
            })
        }
    }
}

/// Whether the adjoint handles experiment `e`: no sample before t0. (A state event at t0
/// or at the last sample makes the backward integration refuse, and the experiment goes
/// forward.)
fn adjoint_applies<S: System>(e: &Planned<S>) -> bool {
    e.sampled().times.first().is_none_or(|&t| t >= e.t0)
}

/// One experiment's rows at the point `at`, its part of U = Jᵀr (k values), and whether it
/// came from the adjoint (false: from forward sensitivities).
fn experiment_gradient<S: System>(
    e: &Planned<S>,
    at: &At<'_>,
    k: usize,
) -> Result<(Rows, Vec<f64>, bool), OdeError> {
    if !adjoint_applies(e) {
        return forward_gradient(e, at, k);
    }
    let (y0, p) = e.start(at.v)?;
    let times = &e.sampled().times;
    let sizes = e.sizes(&y0);
    let ivp = Ivp::new(e.system(), e.t0, &y0, &p).sized(&sizes);
    let (n, ns) = (y0.len(), e.slots.len());
    let (trajectory, forward) = ivp.solve_dense(at.integrator, times)?;
    let dz = slot_matrix(e, at.v, at.free_index, at.chain, k);
    // The rows' direct dependence on the coordinates: through the slots with their
    // sensitivities taken as zero, and through the unknowns' values in the noise functions.
    let zeros = vec![0.0; n * ns];
    let direct =
        sample_rows(e, at, (&p, &e.slots, Some(&dz)), |m| (trajectory.state(m), &zeros[..]))?;
    // ∂R/∂y(t_m): the states as columns, their sensitivities the identity, nothing direct.
    // The identity's storage is the same row by row as column by column: it serves as the
    // states' sensitivities too.
    let states: Vec<Wrt> = (0..n).map(Wrt::InitialValue).collect();
    let none = vec![None; at.free_index.len()];
    let through = At { free_index: &none, ..*at };
    let identity = DMatrix::identity(n, n);
    let by_state = sample_rows(e, &through, (&p, &states, Some(&identity)), |m| {
        (trajectory.state(m), identity.as_slice())
    })?;
    let mut u = direct.gradient(k);
    let mut seeds = vec![0.0; times.len() * n];
    for ((r, row), &m) in by_state.r.iter().zip(by_state.jacobian.chunks(n)).zip(&by_state.samples)
    {
        seeds[m * n..(m + 1) * n].iter_mut().zip(row).for_each(|(c, j)| *c += r * j);
    }
    let mut rows = direct;
    // A backward integration that fails where the forward one did not leaves the
    // experiment to the forward sensitivities, whose gradient is the same quantity.
    let Ok((g, counts)) = ivp.adjoint(at.integrator, &e.slots, None, (&forward, times, &seeds))
    else {
        return forward_gradient(e, at, k);
    };
    for (j, u) in u.iter_mut().enumerate() {
        *u += (0..ns).map(|q| g[q] * dz[(q, j)]).sum::<f64>();
    }
    rows.counts = trajectory.counts();
    rows.counts += counts;
    rows.forget_derivatives();
    Ok((rows, u, true))
}

/// One experiment's rows and U = Jᵀr from its forward sensitivities.
fn forward_gradient<S: System>(
    e: &Planned<S>,
    at: &At<'_>,
    k: usize,
) -> Result<(Rows, Vec<f64>, bool), OdeError> {
    let mut rows = experiment_rows(e, at, k)?;
    let u = rows.gradient(k);
    // The gradient needs U alone: the rows' derivatives go now, so that a problem of many
    // experiments holds one experiment's at a time on each thread, not all of them.
    rows.forget_derivatives();
    Ok((rows, u, false))
}
