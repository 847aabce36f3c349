//! Quadratures along a trajectory, for a continuous record b(t) (Goodman 1966, Section III):
//!
//! ε = Σ_o w_o ∫ r_o² dt,  U = Σ_o w_o ∫ r_o G_o dt (eq. 22),  A = Σ_o w_o ∫ G_oᵀ G_o dt (eq. 24),
//!
//! with r_o(t) = h_o(y(t)) − b_o(t) and G_o = ∂h_o/∂z (S(t) for a measured state).
//!
//! They are accumulated step by step during the one integration that also gives y and S: on
//! each accepted step the integrand is evaluated from the step's dense output. The step is
//! split at the record's samples (where a sampled record has kinks), and each piece is
//! integrated by adaptive Gauss–Kronrod (7, 15), bisected until the Kronrod–Gauss difference
//! of every entry is below `rtol` times that entry's natural scale (ε for the cost,
//! √(ε A_ii) for U_i, √(A_ii A_jj) for A_ij, each on the piece; the bounds Cauchy–Schwarz
//! puts on them). On a piece of a sampled record the integrand is a polynomial of degree ≤ 10
//! and one Kronrod rule (exact to degree 22) is already exact.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector};

use crate::counts::Counts;
use crate::error::OdeError;
use crate::interpolant::Interpolant;
use crate::ivp::{Ivp, ObservableGradient};
use crate::options::Integrator;
use crate::signal::{Side, Signal};
use crate::system::{Observable, System};
use crate::wrt::Wrt;

/// A continuous record b(t) of one measured quantity.
#[derive(Clone)]
pub enum Record {
    /// Samples, linearly interpolated between them (the usual data file).
    Samples(Signal),
    /// A function of time, known everywhere.
    Function(Arc<dyn Fn(f64) -> f64 + Send + Sync>),
}

impl std::fmt::Debug for Record {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Record::Samples(s) => write!(f, "Record::Samples({} samples)", s.times().len()),
            Record::Function(_) => write!(f, "Record::Function"),
        }
    }
}

impl Record {
    /// A record given as a function of time.
    pub fn function(f: impl Fn(f64) -> f64 + Send + Sync + 'static) -> Self {
        Record::Function(Arc::new(f))
    }

    /// b(t).
    pub fn value(&self, t: f64) -> f64 {
        match self {
            Record::Samples(s) => s.value(t, Side::After),
            Record::Function(f) => f(t),
        }
    }

    /// Times where b(t) is not smooth (the samples of a sampled record).
    pub fn knots(&self) -> &[f64] {
        match self {
            Record::Samples(s) => s.times(),
            Record::Function(_) => &[],
        }
    }
}

/// One measured quantity of a continuous record, with its weight w_o (eq. 32: 1/σ_o²).
#[derive(Clone, Debug)]
pub struct RecordedOutput {
    /// What is measured.
    pub observable: Observable,
    /// The weight w_o.
    pub weight: f64,
    /// The record b_o(t).
    pub record: Record,
}

/// The integrals ε, U and A over the record.
#[derive(Clone, Debug, PartialEq)]
pub struct LeastSquaresIntegrals {
    /// ε = Σ_o w_o ∫ r_o² dt.
    pub cost: f64,
    /// U_i = Σ_o w_o ∫ r_o G_o,i dt (eq. 22).
    pub gradient: DVector<f64>,
    /// A_ij = Σ_o w_o ∫ G_o,i G_o,j dt (eq. 24), symmetric.
    pub normal: DMatrix<f64>,
    /// The work done by the integration.
    pub counts: Counts,
}

// Gauss–Kronrod (7, 15) nodes and weights on [−1, 1] (Piessens et al., QUADPACK qk15).
const XGK: [f64; 8] = [
    0.991_455_371_120_812_6,
    0.949_107_912_342_758_5,
    0.864_864_423_359_769_1,
    0.741_531_185_599_394_4,
    0.586_087_235_467_691_1,
    0.405_845_151_377_397_2,
    0.207_784_955_007_898_5,
    0.0,
];
const WGK: [f64; 8] = [
    0.022_935_322_010_529_22,
    0.063_092_092_629_978_55,
    0.104_790_010_322_250_18,
    0.140_653_259_715_525_92,
    0.169_004_726_639_267_9,
    0.190_350_578_064_785_4,
    0.204_432_940_075_298_9,
    0.209_482_141_084_727_83,
];
/// Gauss weights of the 7-point rule, on the nodes XGK[1], XGK[3], XGK[5], XGK[7].
const WG: [f64; 4] = [
    0.129_484_966_168_869_7,
    0.279_705_391_489_276_7,
    0.381_830_050_505_118_9,
    0.417_959_183_673_469_4,
];

/// Deepest bisection of one piece; beyond it the Kronrod estimate is accepted as it is.
const MAX_DEPTH: u32 = 40;

/// Adaptive Gauss–Kronrod integration of a vector-valued function with reusable buffers.
pub struct GaussKronrod {
    dim: usize,
    value: Vec<f64>,
    kronrod: Vec<f64>,
    gauss: Vec<f64>,
    stack: Vec<(f64, f64, u32)>,
}

impl GaussKronrod {
    /// For integrands of length `dim`.
    pub fn new(dim: usize) -> Self {
        Self {
            dim,
            value: vec![0.0; dim],
            kronrod: vec![0.0; dim],
            gauss: vec![0.0; dim],
            stack: Vec::with_capacity(64),
        }
    }

    /// Adds ∫_a^b f to `acc`, bisecting a piece until `accept(kronrod, gauss)` holds.
    pub fn integrate(
        &mut self,
        a: f64,
        b: f64,
        acc: &mut [f64],
        mut f: impl FnMut(f64, &mut [f64]),
        accept: impl Fn(&[f64], &[f64]) -> bool,
    ) {
        self.stack.clear();
        self.stack.push((a, b, 0));
        while let Some((lo, hi, depth)) = self.stack.pop() {
            let (c, r) = (0.5 * (lo + hi), 0.5 * (hi - lo));
            self.kronrod.iter_mut().for_each(|v| *v = 0.0);
            self.gauss.iter_mut().for_each(|v| *v = 0.0);
            for (j, &x) in XGK.iter().enumerate() {
                let nodes: &[f64] = if x == 0.0 { &[0.0] } else { &[-1.0, 1.0] };
                for &sign in nodes {
                    f(c + sign * r * x, &mut self.value);
                    for i in 0..self.dim {
                        self.kronrod[i] += WGK[j] * r * self.value[i];
                        if j % 2 == 1 {
                            self.gauss[i] += WG[j / 2] * r * self.value[i];
                        }
                    }
                }
            }
            if depth >= MAX_DEPTH || accept(&self.kronrod, &self.gauss) {
                for (a, k) in acc.iter_mut().zip(&self.kronrod) {
                    *a += k;
                }
            } else {
                self.stack.push((c, hi, depth + 1));
                self.stack.push((lo, c, depth + 1));
            }
        }
    }
}

/// Index of A_ij (i ≤ j) in the packed upper triangle that follows ε and U.
fn packed(k: usize, i: usize, j: usize) -> usize {
    1 + k + i * k - i * (i + 1) / 2 + j
}

impl<S: System> Ivp<'_, S> {
    /// Integrates y and S = ∂y/∂z (columns `wrt`) from t0 over the record span
    /// [t_lo, t_hi] (both directions when t0 lies inside) and accumulates ε, U and A.
    /// `rtol` is the relative accuracy of the quadratures.
    pub fn least_squares_integrals(
        &self,
        integrator: &Integrator,
        wrt: &[Wrt],
        outputs: &[RecordedOutput],
        (t_lo, t_hi): (f64, f64),
        rtol: f64,
    ) -> Result<LeastSquaresIntegrals, OdeError> {
        let k = wrt.len();
        let n = self.y0.len();
        let dim = 1 + k + k * (k + 1) / 2;
        let mut acc = vec![0.0; dim];
        let mut gk = GaussKronrod::new(dim);
        let mut obs = ObservableGradient::new(self.system, self.p, wrt);
        let mut x = vec![0.0; n * (1 + k)];
        let mut grad = vec![0.0; k];
        let mut breaks: Vec<f64> = Vec::new();
        let mut integrand = |step: &Interpolant, t: f64, out: &mut [f64]| {
            step.eval(t, &mut x);
            out.iter_mut().for_each(|v| *v = 0.0);
            let (y, s) = x.split_at(n);
            for o in outputs {
                let r = obs.eval(t, y, s, o.observable, &mut grad) - o.record.value(t);
                out[0] += o.weight * r * r;
                for i in 0..k {
                    out[1 + i] += o.weight * r * grad[i];
                    for j in i..k {
                        out[packed(k, i, j)] += o.weight * grad[i] * grad[j];
                    }
                }
            }
        };
        let accept = |kr: &[f64], ga: &[f64]| {
            let within = |c: usize, scale: f64| (kr[c] - ga[c]).abs() <= rtol * scale;
            let cost = kr[0].abs();
            let diag = |i: usize| kr[packed(k, i, i)].abs();
            within(0, cost)
                && (0..k).all(|i| within(1 + i, (cost * diag(i)).sqrt()))
                && (0..k)
                    .all(|i| (i..k).all(|j| within(packed(k, i, j), (diag(i) * diag(j)).sqrt())))
        };
        let counts = self.integrate_steps(integrator, wrt, (t_lo, t_hi), |step| {
            let (a, b) = step.bounds();
            let (a, b) = (a.max(t_lo), b.min(t_hi));
            if a >= b {
                return;
            }
            breaks.clear();
            breaks.push(a);
            for o in outputs {
                let knots = o.record.knots();
                let first = knots.partition_point(|&s| s <= a);
                breaks.extend(knots[first..].iter().take_while(|&&s| s < b));
            }
            breaks.push(b);
            breaks.sort_by(f64::total_cmp);
            breaks.dedup();
            for piece in breaks.windows(2) {
                gk.integrate(
                    piece[0],
                    piece[1],
                    &mut acc,
                    |t, out| integrand(step, t, out),
                    accept,
                );
            }
        })?;
        let mut normal = DMatrix::zeros(k, k);
        for i in 0..k {
            for j in i..k {
                normal[(i, j)] = acc[packed(k, i, j)];
                normal[(j, i)] = acc[packed(k, i, j)];
            }
        }
        Ok(LeastSquaresIntegrals {
            cost: acc[0],
            gradient: DVector::from_column_slice(&acc[1..1 + k]),
            normal,
            counts,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_round_trips() {
        for k in 1..6 {
            let mut c = 1 + k;
            for i in 0..k {
                for j in i..k {
                    assert_eq!(packed(k, i, j), c);
                    c += 1;
                }
            }
        }
    }

    #[test]
    fn gauss_kronrod_is_exact_on_polynomials_and_adapts_to_oscillation() {
        let mut gk = GaussKronrod::new(2);
        let mut acc = [0.0; 2];
        gk.integrate(
            -1.0,
            2.0,
            &mut acc,
            |t, out| {
                out[0] = t.powi(21);
                out[1] = (25.0 * t).sin();
            },
            |k, g| (0..2).all(|i| (k[i] - g[i]).abs() <= 1e-12),
        );
        let exact0 = (2f64.powi(22) - 1.0) / 22.0;
        let exact1 = ((-25.0f64).cos() - (50.0f64).cos()) / 25.0;
        assert!((acc[0] - exact0).abs() <= 1e-13 * exact0.abs(), "{} vs {exact0}", acc[0]);
        assert!((acc[1] - exact1).abs() <= 1e-13, "{} vs {exact1}", acc[1]);
    }
}
