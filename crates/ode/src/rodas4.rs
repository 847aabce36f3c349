//! Rodas4 (Hairer & Wanner, Solving ODE II, Section IV.7; their code RODAS): a
//! Rosenbrock method of order 4 with an embedded method of order 3 for error control and a
//! dense output of order 3, L-stable and stiffly accurate.
//!
//! Why a Rosenbrock method: a stage is one linear solve with the same matrix
//! E = I/(γh) − ∂f/∂x, factorised once per step, and no Newton iteration whose convergence
//! must be watched. With the Jacobian exact (dual numbers) this is reliable on stiff
//! identification problems of the size sysid meets (n up to a few hundred). The variational
//! equations share the factorisation: the Jacobian of [y; S] is block lower triangular with
//! every diagonal block equal to ∂f/∂y, so each stage solves with E once for y and once per
//! sensitivity column (the simultaneous-corrector structure), the coupling blocks
//! ∂(J s_j + ∂f/∂α_j)/∂y coming from one hyper-dual evaluation each.
//!
//! Stage equations (increments k_i in units of x):
//!
//! E k_i = f(t + c_i h, x + Σ_{j<i} a_ij k_j) + Σ_{j<i} (c_ij / h) k_j + h d_i ∂f/∂t,
//!
//! x_new = x + Σ a_6j k_j + k_6 (the sixth stage input is the embedded order-3 solution, k_6
//! the error estimate). The non-autonomous term ∂f/∂t is a one-sided difference quotient
//! taken inside the current segment: [`System`](crate::System)s receive t as a number, so
//! it cannot be a dual. It enters as h·d_i·∂f/∂t, so its error (~1e-8 relative) stays below
//! the tolerances of a fit. A system that declares itself
//! [autonomous](crate::System::autonomous) (a model file whose equations do not mention t,
//! without inputs) skips it: ∂f/∂t = 0 exactly, and one evaluation of f per step less.

use crate::control::Control;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::stepper::Stepper;
use crate::work::{Evaluator, Work};

// Hairer's RODAS coefficients (METH = 1), as published; verified against the order
// conditions in the tests below.
const GAMMA: f64 = 0.25;
const C2: f64 = 0.386;
const C3: f64 = 0.21;
const C4: f64 = 0.63;
const D1: f64 = 0.25;
const D2: f64 = -0.1043;
const D3: f64 = 0.1035;
const D4: f64 = -0.036_200_000_000_000_23;
const A21: f64 = 1.544;
const A31: f64 = 0.946_678_528_081_582_6;
const A32: f64 = 0.255_701_169_898_328_4;
const A41: f64 = 3.314_825_187_068_521;
const A42: f64 = 2.896_124_015_972_201;
const A43: f64 = 0.998_641_913_997_781_7;
const A51: f64 = 1.221_224_509_226_641;
const A52: f64 = 6.019_134_481_288_629;
const A53: f64 = 12.537_083_329_320_87;
const A54: f64 = -0.687_886_036_105_895;
const C21: f64 = -5.6688;
const C31: f64 = -2.430_093_356_833_875;
const C32: f64 = -0.206_359_915_709_191_5;
const C41: f64 = -0.107_352_905_815_137_5;
const C42: f64 = -9.594_562_251_023_355;
const C43: f64 = -20.470_286_148_096_16;
const C51: f64 = 7.496_443_313_967_647;
const C52: f64 = -10.246_804_314_643_52;
const C53: f64 = -33.999_903_528_199_05;
const C54: f64 = 11.708_908_932_061_6;
const C61: f64 = 8.083_246_795_921_522;
const C62: f64 = -7.981_132_988_064_893;
const C63: f64 = -31.521_594_328_743_71;
const C64: f64 = 16.319_305_431_231_36;
const C65: f64 = -6.058_818_238_834_054;
// Dense output: x(θ) = (1 − θ) x + θ (x_new + (1 − θ)(K₁ + θ K₂)), K = Σ h_ij k_j.
const H21: f64 = 10.126_235_083_445_86;
const H22: f64 = -7.487_995_877_610_167;
const H23: f64 = -34.800_918_615_557_47;
const H24: f64 = -7.992_771_707_568_823;
const H25: f64 = 1.025_137_723_295_662;
const H31: f64 = -0.676_280_339_280_125_3;
const H32: f64 = 6.087_714_651_680_015;
const H33: f64 = 16.430_843_208_924_78;
const H34: f64 = 24.767_225_114_183_86;
const H35: f64 = -6.594_389_125_716_872;

/// Step-size control of RODAS: h_new = h / clamp(err^{1/4} / 0.9, 1/6, 5), plain control
/// (the order-3 estimate's exponent, no memory of the previous error).
const CONTROL: Control = Control { exponent: 0.25, beta: 0.0, max_factor: 6.0 };

/// The Rodas4 scheme.
pub(crate) struct Rodas4;

impl<R: Rhs> Stepper<R> for Rodas4 {
    /// One Rodas4 step from (t, w.x) of size h: the solution in w.x_new, the stage increments
    /// k₁..k₆ in w.k[0..6], and the error norm (of k₆).
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError> {
        let n = w.x.len();
        ev.rosenbrock_start(w, t, h, GAMMA)?;
        let [k1, k2, k3, k4, k5, k6, _, _] = &mut w.k;
        let (x, y, f0, ft) = (&w.x[..n], &mut w.tmp, &w.f0[..n], &w.ft[..n]);
        // Stage 1.
        for i in 0..n {
            k1[i] = f0[i] + h * D1 * ft[i];
        }
        ev.solve(k1);
        // Stage 2.
        for i in 0..n {
            y[i] = x[i] + A21 * k1[i];
        }
        ev.f(t + C2 * h, y, k2);
        for i in 0..n {
            k2[i] += C21 / h * k1[i] + h * D2 * ft[i];
        }
        ev.solve(k2);
        // Stage 3.
        for i in 0..n {
            y[i] = x[i] + A31 * k1[i] + A32 * k2[i];
        }
        ev.f(t + C3 * h, y, k3);
        for i in 0..n {
            k3[i] += (C31 * k1[i] + C32 * k2[i]) / h + h * D3 * ft[i];
        }
        ev.solve(k3);
        // Stage 4.
        for i in 0..n {
            y[i] = x[i] + A41 * k1[i] + A42 * k2[i] + A43 * k3[i];
        }
        ev.f(t + C4 * h, y, k4);
        for i in 0..n {
            k4[i] += (C41 * k1[i] + C42 * k2[i] + C43 * k3[i]) / h + h * D4 * ft[i];
        }
        ev.solve(k4);
        // Stage 5, at t + h (d₅ = 0).
        for i in 0..n {
            y[i] = x[i] + A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i];
        }
        ev.f(t + h, y, k5);
        for i in 0..n {
            k5[i] += (C51 * k1[i] + C52 * k2[i] + C53 * k3[i] + C54 * k4[i]) / h;
        }
        ev.solve(k5);
        // Stage 6: its input is the embedded order-3 solution.
        for i in 0..n {
            y[i] += k5[i];
        }
        ev.f(t + h, y, k6);
        for i in 0..n {
            k6[i] += (C61 * k1[i] + C62 * k2[i] + C63 * k3[i] + C64 * k4[i] + C65 * k5[i]) / h;
        }
        ev.solve(k6);
        for i in 0..n {
            w.x_new[i] = y[i] + k6[i];
        }
        Ok(ev.error_norm(k6, x, &w.x_new))
    }

    /// From the stage increments in `w.k`: r₁ = x, r₂ = x_new − x, r₃ = K₁, r₄ = K₂, r₅ = 0
    /// (the form of [`crate::Interpolant`]).
    fn dense(&self, _: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64) {
        let n = w.x.len();
        let [r1, r2, r3, r4, r5] = w.interpolant.coefficients_mut();
        let k = &w.k;
        for i in 0..n {
            r1[i] = w.x[i];
            r2[i] = w.x_new[i] - w.x[i];
            r3[i] = H21 * k[0][i] + H22 * k[1][i] + H23 * k[2][i] + H24 * k[3][i] + H25 * k[4][i];
            r4[i] = H31 * k[0][i] + H32 * k[1][i] + H33 * k[2][i] + H34 * k[3][i] + H35 * k[4][i];
            r5[i] = 0.0;
        }
        w.interpolant.set_span(t, t_next);
    }

    fn control(&self) -> Option<Control> {
        Some(CONTROL)
    }
}

#[cfg(test)]
mod tests {
    //! The coefficients against the order conditions of Rosenbrock methods.
    use super::*;
    use crate::rosenbrock_conditions::{Transformed, assert_order_four};
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn coefficients_satisfy_the_order_conditions() {
        let lower = |rows: [[f64; 5]; 6]| {
            DMatrix::from_fn(6, 6, |i, j| if j < i { rows[i][j] } else { 0.0 })
        };
        let c = lower([
            [0.0; 5],
            [C21, 0.0, 0.0, 0.0, 0.0],
            [C31, C32, 0.0, 0.0, 0.0],
            [C41, C42, C43, 0.0, 0.0],
            [C51, C52, C53, C54, 0.0],
            [C61, C62, C63, C64, C65],
        ]);
        // Stage 6's input is stage 5's plus k₅; x_new is stage 6's plus k₆.
        let a = lower([
            [0.0; 5],
            [A21, 0.0, 0.0, 0.0, 0.0],
            [A31, A32, 0.0, 0.0, 0.0],
            [A41, A42, A43, 0.0, 0.0],
            [A51, A52, A53, A54, 0.0],
            [A51, A52, A53, A54, 1.0],
        ]);
        assert_order_four(&Transformed {
            gamma: GAMMA,
            a,
            c,
            m: DVector::from_vec(vec![A51, A52, A53, A54, 1.0, 1.0]),
            nodes: vec![0.0, C2, C3, C4, 1.0, 1.0],
            d: vec![D1, D2, D3, D4, 0.0, 0.0],
        });
    }
}
