//! Rodas5P (Steinebach, "Construction of Rosenbrock–Wanner method Rodas5P and numerical
//! benchmarks within the Julia Differential Equations package", BIT 63, 2023): a Rosenbrock
//! method of order 5 with an embedded method of order 4 and a dense output of order 4,
//! L-stable and stiffly accurate, eight stages.
//!
//! Why beside Rodas4: at the tight tolerances identification asks for (rtol 1e-8 and
//! below) the step size of an order-p method grows like tol^(−1/p); one order more takes
//! roughly half the steps of Rodas4 there, for eight stages instead of six, and each stage
//! costs the same (one evaluation of f and one back-substitution with the factorised
//! E = I/(γh) − ∂f/∂x, the sensitivities included, as in [`crate::rodas4`]).
//!
//! Stage equations, in the same transformed form as Rodas4 (increments k_i in units of x):
//!
//! E k_i = f(t + c_i h, x + Σ_{j<i} a_ij k_j) + Σ_{j<i} (c_ij / h) k_j + h d_i ∂f/∂t,
//!
//! where stages 6, 7 and 8 are evaluated at t + h, stage 7's input is stage 6's plus k₆ and
//! stage 8's is stage 7's plus k₇ (the embedded order-4 solution); x_new = stage 8's input
//! + k₈, and k₈ is the error estimate.

use crate::control::Control;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::stepper::Stepper;
use crate::work::{Evaluator, Work};

/// The number of stages.
const STAGES: usize = 8;
const GAMMA: f64 = 0.211_937_563_194_290_14;
/// The nodes c_i: where stage i evaluates f, as a share of the step.
const NODES: [f64; STAGES] = [
    0.0,
    0.635_812_689_582_870_4,
    0.409_579_839_339_753_5,
    0.976_930_672_506_071_6,
    0.428_840_360_955_866_4,
    1.0,
    1.0,
    1.0,
];
/// d_i: the weights of h ∂f/∂t.
const D: [f64; STAGES] = [
    0.211_937_563_194_290_14,
    -0.423_875_126_388_580_27,
    -0.338_462_712_623_592_4,
    1.804_645_287_288_273_4,
    2.325_825_639_765_069,
    0.0,
    0.0,
    0.0,
];
/// a_ij for stages 2 to 6 (row i − 1, the first i − 1 entries); stages 7 and 8 add the
/// previous increment to the previous input.
const A: [[f64; 5]; 5] = [
    [3.0, 0.0, 0.0, 0.0, 0.0],
    [2.849_394_379_747_939, 0.458_422_422_044_639_23, 0.0, 0.0, 0.0],
    [-6.954_028_509_809_101, 2.489_845_061_869_568, -10.358_996_098_473_584, 0.0, 0.0],
    [
        2.802_998_627_562_896_4,
        0.507_246_473_622_820_6,
        -0.398_831_254_177_052_4,
        -0.047_211_872_304_046_41,
        0.0,
    ],
    [
        -7.502_846_399_306_121,
        2.561_846_144_803_919,
        -11.627_539_656_261_098,
        -0.182_687_676_599_422_56,
        0.030_198_172_008_377_946,
    ],
];
/// c_ij (row i − 1, the first i − 1 entries) for stages 2 to 8.
const C: [[f64; 7]; 7] = [
    [-14.155_112_264_123_755, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [-17.972_960_358_859_52, -2.859_693_295_451_294, 0.0, 0.0, 0.0, 0.0, 0.0],
    [147.121_502_757_117_16, -1.412_214_027_182_13, 71.689_402_513_023_58, 0.0, 0.0, 0.0, 0.0],
    [
        165.435_170_248_716_76,
        -0.459_282_345_649_112_6,
        42.909_383_369_586_03,
        -5.961_986_721_573_306,
        0.0,
        0.0,
        0.0,
    ],
    [
        24.854_864_614_690_072,
        -3.000_922_700_283_218_6,
        47.493_111_002_076_8,
        5.581_419_782_155_812_5,
        -0.661_069_182_524_947_1,
        0.0,
        0.0,
    ],
    [
        30.912_732_140_285_99,
        -3.120_824_334_993_797_4,
        77.799_546_460_708_92,
        34.286_460_282_947_83,
        -19.097_331_116_725_623,
        -28.087_943_162_872_662,
        0.0,
    ],
    [
        37.802_771_233_905_63,
        -3.257_196_902_907_227_6,
        112.269_188_494_963_27,
        66.934_723_124_404_7,
        -40.066_189_370_910_02,
        -54.667_802_628_779_68,
        -9.488_616_523_096_27,
    ],
];
/// Dense output: x(θ) = (1 − θ) x + θ (x_new + (1 − θ)(K₁ + θ (K₂ + θ K₃))),
/// K_m = Σ_j H[m][j] k_j.
const H: [[f64; STAGES]; 3] = [
    [
        25.948_786_856_663_858,
        -2.557_972_484_584_623_5,
        10.433_815_404_888_879,
        -2.367_925_102_268_520_4,
        0.524_948_541_321_073,
        1.124_108_831_045_040_4,
        0.427_287_619_443_187_4,
        -0.172_022_210_701_554_93,
    ],
    [
        -9.915_688_506_951_71,
        -0.968_994_459_411_515_4,
        3.043_803_724_297_845_3,
        -24.495_224_566_215_796,
        20.176_138_334_709_044,
        15.980_663_614_246_51,
        -6.789_040_303_419_874,
        -6.710_236_069_923_372,
    ],
    [
        11.419_903_575_922_262,
        2.887_964_514_613_699_4,
        72.921_379_959_960_29,
        80.125_118_346_226_43,
        -52.072_871_366_152_654,
        -59.789_936_252_667_29,
        -0.155_826_842_827_519_13,
        4.883_087_185_713_722,
    ],
];

/// Step-size control as for RODAS, with the order-4 estimate's exponent 1/5.
const CONTROL: Control = Control { exponent: 0.2, beta: 0.0, max_factor: 6.0 };

/// The Rodas5P scheme.
pub(crate) struct Rodas5p;

/// The input of stage i ≥ 1 into `y`: x + Σ_{j<i} a_ij k_j for stages 2 to 6, in one pass;
/// for stages 7 and 8, the previous stage's input (in `y`) plus the previous increment.
fn stage_input(i: usize, x: &[f64], done: &[Vec<f64>], y: &mut [f64]) {
    let n = y.len();
    if i <= 5 {
        y.copy_from_slice(x);
        let mut terms: [(&[f64], f64); 5] = [(&[], 0.0); 5];
        for ((term, kj), &a) in terms.iter_mut().zip(done).zip(&A[i - 1][..i]) {
            *term = (&kj[..n], a);
        }
        accumulate(y, &terms[..i]);
    } else {
        accumulate(y, &[(&done[i - 1][..n], 1.0)]);
    }
}

/// out += Σ_j c_j v_j over the (v_j, c_j) in `terms` (at most [`STAGES`]), in one pass.
fn accumulate(out: &mut [f64], terms: &[(&[f64], f64)]) {
    match terms.len() {
        0 => {}
        1 => accumulate_fixed::<1>(out, terms),
        2 => accumulate_fixed::<2>(out, terms),
        3 => accumulate_fixed::<3>(out, terms),
        4 => accumulate_fixed::<4>(out, terms),
        5 => accumulate_fixed::<5>(out, terms),
        6 => accumulate_fixed::<6>(out, terms),
        7 => accumulate_fixed::<7>(out, terms),
        _ => accumulate_fixed::<STAGES>(out, terms),
    }
}

/// [`accumulate`] with the number of terms known at compile time: the sum for each element
/// stays in a register, and the loop vectorises over the elements.
#[inline(always)]
fn accumulate_fixed<const T: usize>(out: &mut [f64], terms: &[(&[f64], f64)]) {
    let n = out.len();
    let vectors: [&[f64]; T] = std::array::from_fn(|j| &terms[j].0[..n]);
    let coefficients: [f64; T] = std::array::from_fn(|j| terms[j].1);
    for (m, o) in out.iter_mut().enumerate() {
        let mut v = *o;
        for j in 0..T {
            v += coefficients[j] * vectors[j][m];
        }
        *o = v;
    }
}

impl<R: Rhs> Stepper<R> for Rodas5p {
    /// One Rodas5P step from (t, w.x) of size h: the solution in w.x_new, the stage
    /// increments k₁..k₈ in w.k, and the error norm (of k₈).
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError> {
        let n = w.x.len();
        ev.rosenbrock_start(w, t, h, GAMMA)?;
        let (x, y, ft) = (&w.x[..n], &mut w.tmp[..n], &w.ft[..n]);
        for i in 0..STAGES {
            let (done, rest) = w.k.split_at_mut(i);
            let ki = &mut rest[0][..n];
            if i == 0 {
                ki.copy_from_slice(&w.f0[..n]);
            } else {
                stage_input(i, x, done, y);
                ev.f(t + NODES[i] * h, y, ki);
            }
            // k_i += Σ_{j<i} (c_ij / h) k_j + h d_i ∂f/∂t, in one pass.
            let mut terms: [(&[f64], f64); STAGES] = [(&[], 0.0); STAGES];
            let c_row: &[f64] = if i == 0 { &[] } else { &C[i - 1][..i] };
            for ((term, kj), &c) in terms.iter_mut().zip(done.iter()).zip(c_row) {
                *term = (&kj[..n], c / h);
            }
            let mut count = i;
            if D[i] != 0.0 {
                terms[count] = (ft, h * D[i]);
                count += 1;
            }
            accumulate(ki, &terms[..count]);
            ev.solve(ki);
        }
        let k8 = &w.k[STAGES - 1][..n];
        for ((v, y), k) in w.x_new[..n].iter_mut().zip(y.iter()).zip(k8) {
            *v = y + k;
        }
        Ok(ev.error_norm(k8, x, &w.x_new))
    }

    /// From the stage increments in `w.k`: r₁ = x, r₂ = x_new − x, r₃ = K₁,
    /// r₄ = K₂ + K₃, r₅ = −K₃ (the form of [`crate::Interpolant`]: θ K₃ = K₃ − (1 − θ) K₃).
    fn dense(&self, _: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64) {
        let n = w.x.len();
        let [r1, r2, r3, r4, r5] = w.interpolant.coefficients_mut();
        let k = &w.k;
        for i in 0..n {
            r1[i] = w.x[i];
            r2[i] = w.x_new[i] - w.x[i];
            let mut big_k = [0.0; 3];
            for (sum, row) in big_k.iter_mut().zip(&H) {
                *sum = row.iter().zip(k).map(|(h, kj)| h * kj[i]).sum();
            }
            r3[i] = big_k[0];
            r4[i] = big_k[1] + big_k[2];
            r5[i] = -big_k[2];
        }
        w.interpolant.set_span(t, t_next);
    }

    fn control(&self) -> Option<Control> {
        Some(CONTROL)
    }
}

#[cfg(test)]
mod tests {
    //! The coefficients against the order conditions of Rosenbrock methods up to order four
    //! (order five, and the dense output: crates/ode/tests/stiff.rs, by the observed order
    //! and against the closed form).
    use super::*;
    use crate::rosenbrock_conditions::{Transformed, assert_order_four};
    use nalgebra::{DMatrix, DVector};

    /// a_ij of all eight stage inputs and the weights of x_new.
    fn inputs() -> (DMatrix<f64>, DVector<f64>) {
        let mut a = DMatrix::zeros(STAGES, STAGES);
        for i in 1..6 {
            for j in 0..i {
                a[(i, j)] = A[i - 1][j];
            }
        }
        // Stages 7 and 8: the previous input plus the previous increment.
        for i in 6..STAGES {
            for j in 0..i - 1 {
                a[(i, j)] = a[(i - 1, j)];
            }
            a[(i, i - 1)] = 1.0;
        }
        let mut m = DVector::from_fn(STAGES, |j, _| a[(STAGES - 1, j)]);
        m[STAGES - 1] = 1.0;
        (a, m)
    }

    #[test]
    fn coefficients_satisfy_the_order_conditions() {
        let (a, m) = inputs();
        let c = DMatrix::from_fn(STAGES, STAGES, |i, j| if j < i { C[i - 1][j] } else { 0.0 });
        assert_order_four(&Transformed {
            gamma: GAMMA,
            a,
            c,
            m,
            nodes: NODES.to_vec(),
            d: D.to_vec(),
        });
    }
}
