//! What a step works with: the right-hand side as a scheme calls it (counted, evaluated on
//! the inside of the current segment) and the stage vectors, allocated once per integration.

use crate::counts::{Costs, Counts};
use crate::interpolant::Interpolant;
use crate::lu::FactorError;
use crate::options::{Integrator, STATE_FLOOR};
use crate::rhs::Rhs;
use crate::signal::Side;

/// Preallocated stage vectors: nothing is allocated inside the step loop.
pub(crate) struct Work {
    pub(crate) k: [Vec<f64>; 8],
    pub(crate) tmp: Vec<f64>,
    pub(crate) x: Vec<f64>,
    pub(crate) x_new: Vec<f64>,
    /// Rosenbrock: f(t, x) and ∂f/∂t at the start of the step.
    pub(crate) f0: Vec<f64>,
    pub(crate) ft: Vec<f64>,
    /// DOP853's stages beyond `k` ([`MORE`](crate::dop853::MORE) of them; none for the
    /// other schemes).
    pub(crate) more: Vec<Vec<f64>>,
    pub(crate) interpolant: Interpolant,
}

impl Work {
    /// Stage vectors of length n, and `more` of them beyond `k` (DOP853's further stages for
    /// an integration that may step with it, else none).
    pub(crate) fn new(n: usize, more: usize) -> Self {
        Self {
            k: std::array::from_fn(|_| vec![0.0; n]),
            tmp: vec![0.0; n],
            x: vec![0.0; n],
            x_new: vec![0.0; n],
            f0: vec![0.0; n],
            ft: vec![0.0; n],
            more: (0..more).map(|_| vec![0.0; n]).collect(),
            interpolant: Interpolant::new(n),
        }
    }
}

/// Which one-sided limit a stage at time s in the segment between a and b takes: the one
/// from inside the segment, since discontinuities lie only on segment ends.
#[inline]
fn side_in(a: f64, b: f64, s: f64) -> Side {
    let (lo, hi) = (a.min(b), a.max(b));
    if s - lo <= hi - s { Side::After } else { Side::Before }
}

/// The right-hand side as the schemes see it: every evaluation counted, and taken from the
/// inside of the segment being integrated; with the tolerances the error norm weighs by.
pub(crate) struct Evaluator<'r, R: Rhs> {
    pub(crate) rhs: &'r mut R,
    pub(crate) cfg: Integrator,
    pub(crate) counts: Counts,
    /// What the right-hand side's calls cost ([`Rhs::costs`]), as of its last factorisation.
    pub(crate) costs: Costs,
    /// Start and end of the current segment, in the direction of integration.
    pub(crate) seg: (f64, f64),
    /// Whether the segment's start and end are stops inside the integration (a
    /// discontinuity or a switch), rather than its first or last time.
    pub(crate) stops: (bool, bool),
    /// The error norm's per-column floors, allocated once.
    pub(crate) floors: Vec<f64>,
    /// Per column, rtol·m_j (m_j its largest entry): the relative part of its floor, for the
    /// rows of states with a [floor of their own](state_floors); allocated once.
    pub(crate) relative: Vec<f64>,
    /// The absolute floor of each state where one state's is below atol ([`state_floors`]);
    /// empty where every state's is atol.
    pub(crate) state_floors: Vec<f64>,
}

impl<R: Rhs> Evaluator<'_, R> {
    #[inline]
    pub(crate) fn f(&mut self, t: f64, x: &[f64], dx: &mut [f64]) {
        self.counts.rhs_evaluations += 1;
        self.counts.operations += self.costs.eval;
        let side = self.side(t);
        self.rhs.eval(self.at(t), side, x, dx);
    }

    /// Overwrites r with E⁻¹ r, E from the last [`factor`](Self::factor), counted.
    #[inline]
    pub(crate) fn solve(&mut self, r: &mut [f64]) {
        self.counts.operations += self.costs.solve;
        self.rhs.solve(r);
    }

    /// Evaluates the Jacobian at (t, x) from `side` and factorises E = I·`inv_gamma_h` − J,
    /// counted; the costs are asked again, since the matrix may be new.
    pub(crate) fn factor(
        &mut self,
        t: f64,
        side: Side,
        x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        self.counts.jacobians += 1;
        let factored = self.rhs.factor(self.at(t), side, x, inv_gamma_h);
        self.costs = self.rhs.costs();
        self.counts.operations += self.costs.factor;
        factored
    }

    /// The time a stage at t is evaluated at: t, or one unit in the last place inside the
    /// segment where t is a stop. A switch in time written in the equations
    /// (`if(lt(t, 24), …)`) then takes its value from inside the segment, as an input
    /// signal does by its [`Side`]; the step lands on the stop exactly.
    #[inline]
    pub(crate) fn at(&self, t: f64) -> f64 {
        let inward = |t: f64, towards: f64| if towards > t { t.next_up() } else { t.next_down() };
        if self.stops.1 && t.to_bits() == self.seg.1.to_bits() {
            inward(t, self.seg.0)
        } else if self.stops.0 && t.to_bits() == self.seg.0.to_bits() {
            inward(t, self.seg.1)
        } else {
            t
        }
    }

    #[inline]
    pub(crate) fn side(&self, t: f64) -> Side {
        side_in(self.seg.0, self.seg.1, t)
    }

    /// What every Rosenbrock step from (t, w.x) of size h starts with: E = I/(γh) − ∂f/∂x
    /// factorised there, f(t, x) in `w.f0`, and ∂f/∂t in `w.ft`: 0 for an
    /// [autonomous](Rhs::autonomous) right-hand side, else a one-sided difference quotient
    /// inside the step (see [`crate::rodas4`]).
    pub(crate) fn rosenbrock_start(
        &mut self,
        w: &mut Work,
        t: f64,
        h: f64,
        gamma: f64,
    ) -> Result<(), FactorError> {
        let side = self.side(t);
        self.factor(t, side, &w.x, 1.0 / (gamma * h))?;
        self.f(t, &w.x, &mut w.f0);
        if self.rhs.autonomous() {
            w.ft.fill(0.0);
            return Ok(());
        }
        let delta = (1e-7 * t.abs().max(1.0)).min(0.5 * h.abs()) * h.signum();
        let t_delta = t + delta;
        let delta = t_delta - t;
        self.f(t_delta, &w.x, &mut w.ft);
        for (ft, f0) in w.ft.iter_mut().zip(&w.f0) {
            *ft = (*ft - f0) / delta;
        }
        Ok(())
    }

    /// The error norm sqrt(mean((e_i / sk_i)²)), sk_i = atol_i + rtol·max(|x_i|, |x̂_i|),
    /// atol_i the state's [own floor](state_floors) where it has one, else atol.
    ///
    /// Where the right-hand side [measures its errors as vectors](Rhs::errors_as_vectors),
    /// atol is max(atol, rtol·m), m the largest entry of the component's vector.
    ///
    /// For an augmented state [y; S] whose right-hand side gives its [columns](Rhs::column_atol),
    /// a sensitivity S_ij is measured as a component of its column, a vector:
    /// sk_ij = max(atol_i·c_j, rtol·m_j) + rtol·max(|S_ij|, |Ŝ_ij|), m_j the column's largest
    /// entry at either end of the step. An entry 1e-8 of its column's largest (a state the
    /// parameter hardly moves) is then held to rtol of the column, as the column is used,
    /// not to atol on its own: held to atol, such entries set the step on Weber's problem,
    /// where half the trial steps were rejected for entries of 1e-11 in columns of 1e-3.
    pub(crate) fn error_norm(&mut self, e: &[f64], x: &[f64], xn: &[f64]) -> f64 {
        let [norm] = self.error_norms([e], x, xn);
        norm
    }

    /// [`error_norm`](Self::error_norm) of each of E error estimates of the same step (DOP853
    /// has two), the floors (each range's or column's largest entry) found once for all E.
    pub(crate) fn error_norms<const E: usize>(
        &mut self,
        es: [&[f64]; E],
        x: &[f64],
        xn: &[f64],
    ) -> [f64; E] {
        let (rtol, atol) = (self.cfg.rtol, self.cfg.atol);
        // Every estimate is as long as the state it measures.
        let len = es[0].len();
        let mut sums = [[0.0; 4]; E];
        let norms = |sums: &[[f64; 4]; E]| sums.map(|sum| (total(&sum) / len as f64).sqrt());
        if self.rhs.errors_as_vectors() {
            let states = self.rhs.states().min(len);
            for range in [0..states, states..len] {
                let (x, xn) = (&x[range.clone()], &xn[range.clone()]);
                let largest = x.iter().chain(xn).fold(0.0_f64, |m, v| m.max(v.abs()));
                let floor = atol.max(rtol * largest);
                for (sum, e) in sums.iter_mut().zip(es) {
                    add_squares(sum, (&e[range.clone()], x, xn), rtol, |_| floor);
                }
            }
            return norms(&sums);
        }
        // Without sensitivity columns every component is a state.
        let columns = self.rhs.column_atol().unwrap_or(&[]);
        let k = columns.len();
        let n = len / (1 + k);
        let own = &self.state_floors;
        for (sum, e) in sums.iter_mut().zip(es) {
            let states = (&e[..n], &x[..n], &xn[..n]);
            if own.is_empty() {
                add_squares(sum, states, rtol, |_| atol);
            } else {
                add_squares(sum, states, rtol, |i| own[i]);
            }
        }
        if k > 0 {
            // Each column's floor max(atol·c_j, rtol·m_j), its largest entry m_j found in one
            // pass over the rows of S (n × k, row by row), then the entries row by row.
            let floors = &mut self.floors;
            floors.clear();
            floors.resize(k, 0.0);
            fn rows(v: &[f64], n: usize, k: usize) -> std::slice::ChunksExact<'_, f64> {
                v[n..n + n * k].chunks_exact(k)
            }
            for (row, row_new) in rows(x, n, k).zip(rows(xn, n, k)) {
                for ((m, &a), &b) in floors.iter_mut().zip(row).zip(row_new) {
                    *m = m.max(a.abs()).max(b.abs());
                }
            }
            let relative = &mut self.relative;
            relative.clear();
            if !own.is_empty() {
                relative.extend(floors.iter().map(|m| rtol * m));
            }
            for (m, &c) in floors.iter_mut().zip(columns) {
                *m = (atol * c).max(rtol * *m);
            }
            let floors = &floors[..k];
            for (sum, e) in sums.iter_mut().zip(es) {
                let ends = rows(x, n, k).zip(rows(xn, n, k));
                for (i, (row_e, (row, row_new))) in rows(e, n, k).zip(ends).enumerate() {
                    let entries = (row_e, row, row_new);
                    // A state held below atol holds its sensitivities alike, in each
                    // column's units: its floor in place of atol.
                    match own.get(i) {
                        Some(&f) if f < atol => {
                            let floor = |j: usize| (f * columns[j]).max(relative[j]);
                            add_squares(sum, entries, rtol, floor);
                        }
                        _ => add_squares(sum, entries, rtol, |j| floors[j]),
                    }
                }
            }
        }
        norms(&sums)
    }
}

/// The absolute floor of each state of an integration from x0 (states and sensitivities),
/// in place of atol: min(atol, [`STATE_FLOOR`]·rtol·|size_i|), the sizes the right-hand side
/// [gives](Rhs::state_sizes) (the model's own initial values, [`Ivp::sized`](crate::Ivp::sized)),
/// and atol for every state where it gives none. An absolute tolerance above a state's size
/// controls nothing of it: a population that starts at 1e-14 under atol 1e-12 is integrated
/// as if it were 0 until it has grown past atol, and wherever it grows (Beer_MolBioSystems2014's
/// bacteria, started at 1e-14 from its bounds, reach 1 with an error of orders of magnitude).
/// Scaled by rtol, so that an integration at a tenth of the tolerances (the certificate's)
/// holds such a state ten times as tightly and measures its error. A state of size 0,
/// or of atol/(STATE_FLOOR·rtol) or above, keeps atol. Empty where every state keeps it, and
/// for right-hand sides that [measure their errors as vectors](Rhs::errors_as_vectors) (an
/// adjoint's λ, not states).
pub(crate) fn state_floors<R: Rhs>(cfg: &Integrator, rhs: &R, x0: &[f64]) -> Vec<f64> {
    if rhs.errors_as_vectors() {
        return Vec::new();
    }
    let k = rhs.column_atol().map_or(0, <[f64]>::len);
    let n = x0.len() / (1 + k);
    let Some(sizes) = rhs.state_sizes().filter(|s| s.len() == n) else { return Vec::new() };
    let floor = |v: f64| {
        let own = STATE_FLOOR * cfg.rtol * v.abs();
        if own > 0.0 && own < cfg.atol { own.max(f64::MIN_POSITIVE) } else { cfg.atol }
    };
    if sizes.iter().all(|&v| floor(v) >= cfg.atol) {
        return Vec::new();
    }
    sizes.iter().map(|&v| floor(v)).collect()
}

/// Adds to the four partial sums `sum` the squared scaled errors (e_i / sk_i)², sk_i =
/// floor(i) + rtol·max(|x_i|, |x̂_i|), entry i to sum i mod 4: consecutive additions then do
/// not wait on each other, and the loop vectorises. The total differs from a sum taken in
/// one chain by rounding only.
#[inline(always)]
fn add_squares(
    sum: &mut [f64; 4],
    (e, x, xn): (&[f64], &[f64], &[f64]),
    rtol: f64,
    floor: impl Fn(usize) -> f64,
) {
    let (x, xn) = (&x[..e.len()], &xn[..e.len()]);
    // In groups of four as arrays: indexed one by one, the loop stayed scalar, a division
    // and two jumps per component (11 % of Raia's NLL + gradient in this norm).
    let (e4, e_rest) = e.as_chunks::<4>();
    let (x4, x_rest) = x.as_chunks::<4>();
    let (xn4, xn_rest) = xn.as_chunks::<4>();
    for (c, ((e, x), xn)) in e4.iter().zip(x4).zip(xn4).enumerate() {
        let floors: [f64; 4] = std::array::from_fn(|lane| floor(4 * c + lane));
        for lane in 0..4 {
            let q = scaled(e[lane], floors[lane] + rtol * x[lane].abs().max(xn[lane].abs()));
            sum[lane] += q * q;
        }
    }
    let whole = e4.len() * 4;
    for (lane, ((e, x), xn)) in e_rest.iter().zip(x_rest).zip(xn_rest).enumerate() {
        let q = scaled(*e, floor(whole + lane) + rtol * x.abs().max(xn.abs()));
        sum[lane] += q * q;
    }
}

/// The partial sums of [`add_squares`], added.
fn total(sum: &[f64; 4]) -> f64 {
    (sum[0] + sum[1]) + (sum[2] + sum[3])
}

/// The scaled error e/sk of one component, sk = atol + rtol·|x|: 0 for a component that is
/// 0 and has no error (its scale is 0 only under a purely relative tolerance, atol = 0, and
/// 0/0 would poison the norm), ∞ for an error where there is no scale.
#[inline]
fn scaled(e: f64, sk: f64) -> f64 {
    if sk > 0.0 {
        e / sk
    } else if e == 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::{add_squares, scaled};

    /// The scaled error is the quotient wherever the scale is positive, to the bit, and 0
    /// or ∞ where there is no scale (0, or NaN from a NaN state).
    #[test]
    fn scaled_errors_are_the_quotient_or_the_cases_without_a_scale() {
        for (e, sk) in [(3.0, 7.0), (-1e-300, 3e-10), (0.0, 1.0), (1.0, f64::MIN_POSITIVE)] {
            assert_eq!(scaled(e, sk).to_bits(), (e / sk).to_bits(), "{e} / {sk}");
        }
        let bits = |e: f64, sk: f64| scaled(e, sk).to_bits();
        assert_eq!(bits(0.0, 0.0), 0.0f64.to_bits());
        assert_eq!(bits(-0.0, 0.0), 0.0f64.to_bits());
        assert_eq!(bits(2.0, 0.0), f64::INFINITY.to_bits());
        assert_eq!(bits(-2.0, 0.0), f64::INFINITY.to_bits());
        assert_eq!(bits(0.0, f64::NAN), 0.0f64.to_bits());
        assert_eq!(bits(1.0, f64::NAN), f64::INFINITY.to_bits());
    }

    /// The partial sums take entry i into sum i mod 4, in order, whatever the length (the
    /// groups of four and the rest alike), with each entry's own floor: the same sums to the
    /// bit as adding the entries one by one.
    #[test]
    fn squares_go_to_the_sum_of_their_index_mod_four() {
        for len in 0..14 {
            let e: Vec<f64> = (0..len).map(|i| (i as f64 * 0.7).sin() * 1e-6).collect();
            let x: Vec<f64> = (0..len).map(|i| (i as f64 * 1.3).cos()).collect();
            let xn: Vec<f64> = (0..len).map(|i| (i as f64 * 0.4).sin() - 0.5).collect();
            let floor = |i: usize| 1e-9 * (1 + i % 3) as f64;
            let rtol = 1e-6;
            let mut sum = [0.5, 0.25, 0.125, 1.0];
            let mut expected = sum;
            for i in 0..len {
                let q = scaled(e[i], floor(i) + rtol * x[i].abs().max(xn[i].abs()));
                expected[i % 4] += q * q;
            }
            add_squares(&mut sum, (&e, &x, &xn), rtol, floor);
            assert_eq!(sum.map(f64::to_bits), expected.map(f64::to_bits), "length {len}");
        }
    }
}
