//! The shooting grid and the evaluation of the model on it.
//!
//! Nodes t0 = τ_0 < τ_1 < … < τ_M = t_N cut the data interval into M shooting intervals;
//! τ_1 … τ_{M−1} are sample times, spread evenly by count. Interval j starts from the node
//! value s_j (s_0 = y(t0) of the unknowns z, s_j for j ≥ 1 free variables of the iteration)
//! and holds the samples at τ_j ≤ t < τ_{j+1} (the last one also those at τ_M). One sweep
//! integrates every interval from its own node: the residual rows of its samples and, except
//! for the last, the matching defect
//!
//!   d_j = y(τ_{j+1}; τ_j, s_j, α) − s_{j+1},   j = 0 … M − 2.
//!
//! With sensitivities, each interval integrates ∂y/∂(s_j, α) for all n node values and the
//! parameters that depend on the unknowns (the experiment's parameter slots), so that the
//! end of interval j gives G_j = ∂y(τ_{j+1})/∂s_j and P_j = ∂y(τ_{j+1})/∂α, and each
//! residual row its gradient with respect to (s_j, α). Condensing maps them to the unknowns'
//! coordinates through the experiment's slot matrix.
//!
//! Each experiment has a grid of its own; a problem's grids are shot one after the other.

use nalgebra::{DMatrix, DVector};
use sysid_core::{Problem, Transform, plan::Planned};
use sysid_ode::{Counts, Integrator, Ivp, Observable, ObservableGradient, OdeError, System, Wrt};

/// One shooting interval: its start τ_j and the times it is evaluated at (its samples, then
/// τ_{j+1} for every interval but the last).
#[derive(Clone, Debug)]
pub(crate) struct Interval {
    pub(crate) start: f64,
    pub(crate) times: Vec<f64>,
}

/// A residual row: the interval of its sample, the index of its time there, and the sample.
#[derive(Clone, Copy, Debug)]
struct Row {
    interval: usize,
    local: usize,
    observable: Observable,
    transform: Transform,
    value: f64,
    sqrt_weight: f64,
}

/// The shooting grid of one experiment, and which sensitivity column is which.
#[derive(Clone, Debug)]
pub(crate) struct Grid {
    /// The experiment's index in the problem.
    pub(crate) experiment: usize,
    pub(crate) intervals: Vec<Interval>,
    rows: Vec<Row>,
    /// Every state's node value, then every parameter slot.
    wrt: Vec<Wrt>,
    /// (slot, its column in `wrt`) for the parameter slots.
    pub(crate) parameters: Vec<(usize, usize)>,
    /// (slot, state) for the initial-value slots.
    pub(crate) initial: Vec<(usize, usize)>,
    /// n.
    pub(crate) states: usize,
}

/// The model on the grid at a point (z, s_1 … s_{M−1}).
#[derive(Clone, Debug)]
pub(crate) struct Shot {
    /// Weighted residuals, in the problem's row order.
    pub(crate) r: DVector<f64>,
    /// d_0 … d_{M−2}, one after the other (n each).
    pub(crate) defects: DVector<f64>,
    /// The derivatives, when the sweep computed sensitivities.
    pub(crate) derivatives: Option<Derivatives>,
}

/// The derivatives of a sweep.
#[derive(Clone, Debug)]
pub(crate) struct Derivatives {
    /// Row by row, ∂r/∂(s_j, α) of the row's interval j: n node columns, then one per
    /// parameter slot.
    pub(crate) rows: DMatrix<f64>,
    /// For j = 0 … M − 2, [G_j | P_j] (n × (n + parameter slots)).
    pub(crate) ends: Vec<DMatrix<f64>>,
}

impl Shot {
    /// ε of the shot, ‖r‖².
    pub(crate) fn cost(&self) -> f64 {
        self.r.norm_squared()
    }
}

/// Sample times of one interval per this many, by default.
const SAMPLES_PER_INTERVAL: usize = 5;

impl Grid {
    /// The grid of experiment `experiment` with `intervals` shooting intervals (or the
    /// default), fewer when there are not enough distinct sample times after t0.
    pub(crate) fn new<S: System>(
        problem: &Problem<S>,
        experiment: usize,
        intervals: Option<usize>,
    ) -> Self {
        let e = &problem.experiments()[experiment];
        let sampled = e.sampled();
        let t0 = e.t0();
        let after: Vec<f64> = sampled.times.iter().copied().filter(|&t| t > t0).collect();
        let m = intervals
            .unwrap_or(
                (sampled.times.len() / SAMPLES_PER_INTERVAL).min(crate::DEFAULT_MAX_INTERVALS),
            )
            .clamp(1, after.len().max(1));
        // Interior nodes at sample times spread evenly by count; τ_M is the last sample.
        let mut starts = vec![t0];
        for j in 1..m {
            let t = after[(j * after.len()) / m - 1];
            if t > *starts.last().expect("t0") && t < *after.last().expect("a sample") {
                starts.push(t);
            }
        }
        let interval_of = |t: f64| starts.iter().rposition(|&s| s <= t).unwrap_or(0);
        let mut intervals: Vec<Interval> =
            starts.iter().map(|&start| Interval { start, times: Vec::new() }).collect();
        let mut local = vec![0; sampled.times.len()];
        for (m, &t) in sampled.times.iter().enumerate() {
            let j = interval_of(t);
            local[m] = intervals[j].times.len();
            intervals[j].times.push(t);
        }
        for j in 0..intervals.len() - 1 {
            let end = intervals[j + 1].start;
            intervals[j].times.push(end);
        }
        let rows = sampled
            .series
            .iter()
            .flat_map(|s| {
                s.samples.iter().map(|sample| Row {
                    interval: interval_of(sampled.times[sample.index]),
                    local: local[sample.index],
                    observable: s.observable,
                    transform: s.transform,
                    value: sample.value,
                    sqrt_weight: sample.sqrt_weight,
                })
            })
            .collect();
        let n = e.system().signature().n_states();
        let mut wrt: Vec<Wrt> = (0..n).map(Wrt::InitialValue).collect();
        let (mut parameters, mut initial) = (Vec::new(), Vec::new());
        for (slot, w) in e.slots().iter().enumerate() {
            match *w {
                Wrt::Parameter(_) => {
                    parameters.push((slot, wrt.len()));
                    wrt.push(*w);
                }
                Wrt::InitialValue(state) => initial.push((slot, state)),
            }
        }
        Self { experiment, intervals, rows, wrt, parameters, initial, states: n }
    }

    fn experiment<'p, S: System>(&self, problem: &'p Problem<S>) -> &'p Planned<S> {
        &problem.experiments()[self.experiment]
    }

    /// M.
    pub(crate) fn len(&self) -> usize {
        self.intervals.len()
    }

    /// The interval of each residual row, in row order.
    pub(crate) fn row_intervals(&self) -> impl Iterator<Item = usize> + '_ {
        self.rows.iter().map(|row| row.interval)
    }

    /// Number of node columns plus parameter columns of a sensitivity.
    fn columns(&self) -> usize {
        self.wrt.len()
    }

    /// The node values of a start z: s_0 = y(t0), and for j ≥ 1 the data where a state is
    /// measured (linear interpolation of its samples, held constant beyond them) and
    /// otherwise the state integrated over interval j − 1 from s_{j−1} (s_{j−1} itself where
    /// that integration fails), with the work of those integrations (one integration of the
    /// horizon, none when every state is measured).
    pub(crate) fn initial_nodes<S: System>(
        &self,
        problem: &Problem<S>,
        z: &[f64],
    ) -> (Vec<f64>, Counts) {
        let n = self.states;
        let e = self.experiment(problem);
        let (y0, p) = e.point(&problem.values_at(z));
        let measured = measured_states(e, n);
        let all_measured = measured.iter().all(Option::is_some);
        let mut nodes = Vec::with_capacity(n * self.len().saturating_sub(1));
        let mut counts = Counts::default();
        let mut previous = y0;
        for j in 1..self.len() {
            let from = &self.intervals[j - 1];
            let end = self.intervals[j].start;
            let ivp = Ivp::new(e.system(), from.start, &previous, &p);
            let integrated = if all_measured {
                previous.clone()
            } else {
                match ivp.solve(problem.integrator(), &[end]) {
                    Ok(t) if t.state(0).iter().all(|v| v.is_finite()) => {
                        counts += t.counts();
                        t.state(0).to_vec()
                    }
                    _ => previous.clone(),
                }
            };
            let node: Vec<f64> = (0..n)
                .map(|i| match &measured[i] {
                    Some(samples) => interpolate(samples, end),
                    None => integrated[i],
                })
                .collect();
            nodes.extend_from_slice(&node);
            previous = node;
        }
        counts.integrations = counts.integrations.min(1);
        (nodes, counts)
    }

    /// One sweep at z and the node values `nodes` (s_1 … s_{M−1}), with sensitivities when
    /// `derivatives`. The work of every interval is summed and counted as one integration:
    /// a sweep integrates the horizon once.
    pub(crate) fn shoot<S: System>(
        &self,
        problem: &Problem<S>,
        integrator: &Integrator,
        (z, nodes): (&[f64], &[f64]),
        derivatives: bool,
    ) -> Result<(Shot, Counts), OdeError> {
        let n = self.states;
        let c = self.columns();
        let e = self.experiment(problem);
        let (y0, p) = e.point(&problem.values_at(z));
        let mut r = DVector::zeros(self.rows.len());
        let mut defects = DVector::zeros(n * (self.len() - 1));
        let mut row_derivatives = derivatives.then(|| DMatrix::zeros(self.rows.len(), c));
        let mut ends = Vec::new();
        let mut counts = Counts::default();
        let mut grad = vec![0.0; c];
        let mut og = ObservableGradient::new(e.system(), &p, &self.wrt);
        let mut plain = ObservableGradient::new(e.system(), &p, &[]);
        for (j, interval) in self.intervals.iter().enumerate() {
            let start = if j == 0 { &y0[..] } else { &nodes[(j - 1) * n..j * n] };
            let ivp = Ivp::new(e.system(), interval.start, start, &p);
            let rows = self.rows.iter().enumerate().filter(|(_, row)| row.interval == j);
            let last = interval.times.len() - 1;
            if let Some(jac) = row_derivatives.as_mut() {
                let sol = ivp.solve_sensitivities(integrator, &self.wrt, &interval.times)?;
                counts += sol.counts();
                for (index, row) in rows {
                    let t = interval.times[row.local];
                    let s = sol.sensitivity_slice(row.local);
                    let h = og.eval(t, sol.state(row.local), s, row.observable, &mut grad);
                    r[index] = row.sqrt_weight * (row.transform.apply(h) - row.value);
                    let slope = row.sqrt_weight * row.transform.derivative(h);
                    for (col, g) in grad.iter().enumerate() {
                        jac[(index, col)] = slope * g;
                    }
                }
                if j + 1 < self.len() {
                    ends.push(sol.sensitivity(last).into_owned());
                    self.defect(&mut defects, j, sol.state(last), nodes);
                }
            } else {
                let sol = ivp.solve(integrator, &interval.times)?;
                counts += sol.counts();
                for (index, row) in rows {
                    let t = interval.times[row.local];
                    let h = match row.observable {
                        Observable::State(i) => sol.state(row.local)[i],
                        observable => plain.eval(t, sol.state(row.local), &[], observable, &mut []),
                    };
                    r[index] = row.sqrt_weight * (row.transform.apply(h) - row.value);
                }
                if j + 1 < self.len() {
                    self.defect(&mut defects, j, sol.state(last), nodes);
                }
            }
        }
        counts.integrations = 1;
        let finite = |m: &DMatrix<f64>| m.iter().all(|v| v.is_finite());
        let t_end = self.intervals.last().map_or(e.t0(), |i| i.times[i.times.len() - 1]);
        if !r.iter().chain(defects.iter()).all(|v| v.is_finite())
            || !row_derivatives.as_ref().is_none_or(finite)
            || !ends.iter().all(finite)
        {
            return Err(OdeError::NonFinite {
                t: t_end,
                what: "the multiple-shooting sweep".into(),
            });
        }
        let derivatives = row_derivatives.map(|rows| Derivatives { rows, ends });
        Ok((Shot { r, defects, derivatives }, counts))
    }

    fn defect(&self, defects: &mut DVector<f64>, j: usize, end: &[f64], nodes: &[f64]) {
        let n = self.states;
        for i in 0..n {
            defects[j * n + i] = end[i] - nodes[j * n + i];
        }
    }
}

/// For each state measured directly, its samples as (t, value) in time order.
fn measured_states<S: System>(e: &Planned<S>, n: usize) -> Vec<Option<Vec<(f64, f64)>>> {
    let sampled = e.sampled();
    let mut measured = vec![None; n];
    for s in &sampled.series {
        if let Observable::State(i) = s.observable
            && measured[i].is_none()
            && !s.samples.is_empty()
        {
            let mut points: Vec<(f64, f64)> =
                s.samples.iter().map(|x| (sampled.times[x.index], x.measured)).collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            measured[i] = Some(points);
        }
    }
    measured
}

/// Piecewise-linear interpolation of time-ordered points at t, constant beyond them.
fn interpolate(points: &[(f64, f64)], t: f64) -> f64 {
    let after = points.partition_point(|p| p.0 <= t);
    match after {
        0 => points[0].1,
        a if a == points.len() => points[a - 1].1,
        a => {
            let (t0, v0) = points[a - 1];
            let (t1, v1) = points[a];
            // t0 ≤ t < t1 by the partition.
            v0 + (v1 - v0) * (t - t0) / (t1 - t0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::interpolate;

    #[test]
    fn interpolation_is_linear_between_samples_and_constant_beyond() {
        let points = [(0.0, 1.0), (1.0, 3.0), (3.0, -1.0)];
        let at = |t: f64| interpolate(&points, t);
        let expected = [(-1.0, 1.0), (0.5, 2.0), (2.0, 1.0), (3.0, -1.0), (9.0, -1.0)];
        for (t, want) in expected {
            assert!((at(t) - want).abs() <= 1e-15, "at {t}: {} against {want}", at(t));
        }
    }
}
