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
use crate::experiment::Planned;
use crate::problem::Problem;

/// How the gradient of the NLL is had.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensitivities {
    /// Forward sensitivities of every slot, integrated with the states: the residuals'
    /// Jacobian, of which the gradient is Jᵀr.
    Forward,
    /// One backward adjoint integration per experiment along its states. An experiment the
    /// adjoint does not handle (state events, samples before t0), or whose backward
    /// integration fails, is integrated forward.
    Adjoint,
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
    /// does not handle (state events, samples before t0) and those whose backward
    /// integration failed. Empty for [`Sensitivities::Forward`].
    pub fell_back: Vec<usize>,
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
        if how == Sensitivities::Forward {
            let lin = self.residuals_and_jacobian(z)?;
            let gradient = self.objective_gradient(&lin, false);
            let counts = lin.counts;
            return Ok(self.nll(&lin).map(|nll| NllGradient {
                nll,
                gradient,
                counts,
                fell_back: Vec::new(),
            }));
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
        let all = self.each_experiment(|e| experiment_gradient(e, &at, k))?;
        let (mut gradient, mut counts) = (vec![0.0; k], Counts::default());
        for (rows, u, _) in &all {
            gradient.iter_mut().zip(u).for_each(|(g, u)| *g += u);
            counts += rows.counts;
        }
        let fell_back = (0..all.len()).filter(|&i| !all[i].2).collect();
        let costs = all.iter().map(|(rows, ..)| rows.r.iter().map(|r| r * r).sum::<f64>());
        let Some(nlls) = self.nlls(costs) else { return Ok(None) };
        gradient
            .extend(self.scale_gradient(all.iter().flat_map(|(rows, ..)| rows.r.iter().copied())));
        if let Some(i) = gradient.iter().position(|g| !g.is_finite()) {
            return Err(OdeError::NonFinite {
                t: self.span().0,
                what: format!("component {i} of the NLL's gradient"),
            });
        }
        Ok(Some(NllGradient { nll: nlls.iter().sum(), gradient, counts, fell_back }))
    }
}

/// Whether the adjoint handles experiment `e`: no state events, no sample before t0.
fn adjoint_applies<S: System>(e: &Planned<S>) -> bool {
    e.system().n_events() == 0 && e.sampled().times.first().is_none_or(|&t| t >= e.t0)
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
    let (y0, p) = e.point(at.v);
    let times = &e.sampled().times;
    let ivp = Ivp::new(e.system(), e.t0, &y0, &p);
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
    Ok((rows, u, true))
}

/// One experiment's rows and U = Jᵀr from its forward sensitivities.
fn forward_gradient<S: System>(
    e: &Planned<S>,
    at: &At<'_>,
    k: usize,
) -> Result<(Rows, Vec<f64>, bool), OdeError> {
    let rows = experiment_rows(e, at, k)?;
    let u = rows.gradient(k);
    Ok((rows, u, false))
}
