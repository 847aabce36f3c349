//! Dormand–Prince 8(5,3) (Hairer's DOP853): an explicit Runge–Kutta scheme of order 8 in
//! twelve stages, its error estimated by Hairer's blend of an order-5 and an order-3
//! embedded solution, with a dense output of order 7 that costs three more stages on the
//! steps where it is wanted, and Hairer's estimate of h·λ for the stiffness test.
//!
//! At tight tolerances its steps grow as tol^(−1/8) where DOPRI5's grow as tol^(−1/5): at
//! rtol 1e-12 it takes a fraction of DOPRI5's evaluations for twice their number a step.
//!
//! Coefficients: P. J. Prince and J. R. Dormand, "High order embedded Runge–Kutta
//! formulae", J. Comput. Appl. Math. 7 (1981) 67–75, in the form of E. Hairer, S. P. Nørsett
//! and G. Wanner, Solving Ordinary Differential Equations I, 2nd ed. (1993), Section II.10,
//! and Hairer's code DOP853 (the error estimate, the dense output's extra stages and
//! coefficients). Stages are numbered as there: 1–12 the step's, 13 the evaluation at the
//! new point (the next step's first), 14–16 the dense output's.

// The coefficients as published, to 30 digits: more than a double holds.
#![allow(clippy::excessive_precision)]

use crate::control::Control;
use crate::lu::FactorError;
use crate::rhs::Rhs;
use crate::stepper::Stepper;
use crate::work::{Evaluator, Work};

const C2: f64 = 0.052_600_151_958_767_731_878_558_754_448_8;
const C3: f64 = 0.078_900_227_938_151_597_817_838_131_673_2;
const C4: f64 = 0.118_350_341_907_227_396_726_757_197_510;
const C5: f64 = 0.281_649_658_092_772_603_273_242_802_490;
const C6: f64 = 1.0 / 3.0;
const C7: f64 = 0.25;
const C8: f64 = 4.0 / 13.0;
const C9: f64 = 127.0 / 195.0;
const C10: f64 = 0.6;
const C11: f64 = 6.0 / 7.0;
const C14: f64 = 0.1;
const C15: f64 = 0.2;
const C16: f64 = 7.0 / 9.0;

const A21: f64 = 5.260_015_195_876_773_187_855_875_444_88e-2;
const A31: f64 = 1.972_505_698_453_789_945_445_953_291_83e-2;
const A32: f64 = 5.917_517_095_361_369_836_337_859_875_49e-2;
const A41: f64 = 2.958_758_547_680_684_918_168_929_937_75e-2;
const A43: f64 = 8.876_275_643_042_054_754_506_789_813_24e-2;
const A51: f64 = 2.413_651_341_592_666_855_023_697_986_65e-1;
const A53: f64 = -8.845_494_793_282_860_853_448_649_627_17e-1;
const A54: f64 = 9.248_340_032_617_920_031_157_379_665_43e-1;
const A61: f64 = 3.703_703_703_703_703_703_703_703_703_7e-2;
const A64: f64 = 1.708_286_087_294_738_712_796_044_821_73e-1;
const A65: f64 = 1.254_676_875_668_224_250_166_918_141_23e-1;
const A71: f64 = 3.710_937_5e-2;
const A74: f64 = 1.702_522_110_195_440_393_149_780_602_72e-1;
const A75: f64 = 6.021_653_898_045_596_068_502_193_972_83e-2;
const A76: f64 = -1.757_812_5e-2;
const A81: f64 = 3.709_200_011_850_479_271_087_793_198_36e-2;
const A84: f64 = 1.703_839_257_122_399_938_102_140_547_05e-1;
const A85: f64 = 1.072_620_304_463_732_846_518_091_991_68e-1;
const A86: f64 = -1.531_943_774_862_440_175_279_361_582_36e-2;
const A87: f64 = 8.273_789_163_814_022_887_584_737_660_02e-3;
const A91: f64 = 6.241_109_587_160_757_171_144_295_778_12e-1;
const A94: f64 = -3.360_892_629_446_941_294_068_571_098_25;
const A95: f64 = -8.682_193_468_417_260_068_181_898_914_53e-1;
const A96: f64 = 2.759_209_969_944_670_830_494_156_007_97e1;
const A97: f64 = 2.015_406_755_047_789_340_861_867_889_79e1;
const A98: f64 = -4.348_988_418_106_995_884_773_662_551_44e1;
const A10_1: f64 = 4.776_625_364_382_643_658_904_339_085_27e-1;
const A10_4: f64 = -2.488_114_619_971_667_641_926_425_864_68;
const A10_5: f64 = -5.902_908_268_368_429_963_714_464_757_43e-1;
const A10_6: f64 = 2.123_005_144_818_119_423_472_889_498_97e1;
const A10_7: f64 = 1.527_923_363_288_242_358_325_969_229_38e1;
const A10_8: f64 = -3.328_821_096_898_486_291_944_532_655_87e1;
const A10_9: f64 = -2.033_120_170_850_862_613_582_229_285_93e-2;
const A11_1: f64 = -9.371_424_300_859_873_257_170_402_165_8e-1;
const A11_4: f64 = 5.186_372_428_844_063_708_300_238_532_09;
const A11_5: f64 = 1.091_437_348_996_729_578_185_002_546_54;
const A11_6: f64 = -8.149_787_010_746_926_125_139_972_673_57;
const A11_7: f64 = -1.852_006_565_999_695_986_415_661_807_01e1;
const A11_8: f64 = 2.273_948_709_935_050_428_189_700_567_34e1;
const A11_9: f64 = 2.493_605_552_679_652_389_870_893_967_62;
const A11_10: f64 = -3.046_764_471_898_219_500_382_366_902_2;
const A12_1: f64 = 2.273_310_147_516_538_207_923_597_684_49;
const A12_4: f64 = -1.053_449_546_673_725_019_840_666_898_79e1;
const A12_5: f64 = -2.000_872_058_224_862_499_096_757_184_44;
const A12_6: f64 = -1.795_893_186_311_879_891_727_659_505_34e1;
const A12_7: f64 = 2.794_888_452_941_996_005_084_998_088_37e1;
const A12_8: f64 = -2.858_998_277_135_023_694_740_655_086_74;
const A12_9: f64 = -8.872_856_933_530_629_544_335_492_892_58;
const A12_10: f64 = 1.236_056_717_579_430_306_472_662_015_28e1;
const A12_11: f64 = 6.433_927_460_157_635_303_559_704_840_46e-1;

// The solution of order 8.
const B1: f64 = 5.429_373_411_656_876_223_805_357_663_63e-2;
const B6: f64 = 4.450_312_892_752_408_881_441_139_505_66;
const B7: f64 = 1.891_517_899_314_500_383_042_815_990_44;
const B8: f64 = -5.801_203_960_010_584_781_467_211_422_7;
const B9: f64 = 3.111_643_669_578_198_944_089_160_623_7e-1;
const B10: f64 = -1.521_609_496_625_160_785_561_788_068_05e-1;
const B11: f64 = 2.013_654_008_040_303_483_747_765_375_01e-1;
const B12: f64 = 4.471_061_572_777_259_051_768_855_690_43e-2;

// The order-3 solution's weights, where they differ from the order-8 ones (stages 1, 9, 12).
const BHH1: f64 = 0.244_094_488_188_976_377_952_755_905_512;
const BHH2: f64 = 0.733_846_688_281_611_857_341_361_741_547;
const BHH3: f64 = 0.220_588_235_294_117_647_058_823_529_412e-1;

// The order-8 solution minus the order-5 one.
const ER1: f64 = 0.131_200_449_941_948_807_325_010_299_6e-1;
const ER6: f64 = -0.122_515_644_637_620_444_072_056_975_3e1;
const ER7: f64 = -0.495_758_949_657_250_191_521_407_995_2;
const ER8: f64 = 0.166_437_718_245_498_653_696_153_041_5e1;
const ER9: f64 = -0.350_328_848_749_973_681_688_648_729_0;
const ER10: f64 = 0.334_179_118_713_017_479_029_731_884_1;
const ER11: f64 = 0.819_232_064_851_157_124_657_074_261_3e-1;
const ER12: f64 = -0.223_553_078_638_862_952_588_442_784_5e-1;

// The dense output's three more stages (14, 15, 16; stage 13 is f at the new point).
const A14: [f64; 8] = [
    5.616_750_228_304_795_233_929_092_196_81e-2,  // 1
    2.535_002_102_166_248_110_887_947_653_33e-1,  // 7
    -2.462_390_374_708_024_899_174_414_754_41e-1, // 8
    -1.241_914_232_638_163_604_690_101_406_26e-1, // 9
    1.532_917_982_787_656_973_120_632_268_5e-1,   // 10
    8.201_052_295_634_689_884_916_666_020_57e-3,  // 11
    7.567_897_660_545_699_761_386_035_895_84e-3,  // 12
    -8.298e-3,                                    // 13
];
const A15: [f64; 8] = [
    3.183_464_816_350_214_050_607_684_732_61e-2,  // 1
    2.830_090_967_236_677_552_883_229_614_02e-2,  // 6
    5.354_198_830_743_856_762_237_973_843_72e-2,  // 7
    -5.492_374_857_139_098_846_465_693_403_06e-2, // 8
    -1.083_473_286_972_493_228_585_093_169_94e-4, // 11
    3.825_710_908_356_584_129_549_201_923_23e-4,  // 12
    -3.404_650_086_874_045_608_029_771_144_92e-4, // 13
    1.413_124_436_746_325_002_780_746_183_66e-1,  // 14
];
const A16: [f64; 8] = [
    -4.288_963_015_837_919_234_085_735_386_92e-1, // 1
    -4.697_621_415_361_163_843_144_494_472_06,    // 6
    7.683_421_196_062_599_041_842_409_538_78,     // 7
    4.068_989_818_397_110_079_702_135_543_31,     // 8
    3.567_271_874_552_811_092_706_695_430_21e-1,  // 9
    -1.399_024_165_159_014_621_294_180_097_34e-3, // 13
    2.947_514_789_152_772_338_955_627_214_9,      // 14
    -9.150_958_472_179_870_010_818_701_871_38,    // 15
];

/// The dense output's r₅..r₈ (divided by h), each a combination of the stages
/// 1, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16 in that order.
const D: [[f64; 12]; 4] = [
    [
        -0.842_893_827_610_901_286_513_534_911_42e1,
        0.566_714_953_519_377_769_625_317_835_90,
        -0.306_894_994_594_989_169_127_973_047_27e1,
        0.238_466_765_651_206_982_877_281_496_80e1,
        0.211_703_458_244_502_827_671_551_499_46e1,
        -0.871_391_583_777_972_992_067_899_074_90,
        0.224_043_743_026_078_827_585_417_716_50e1,
        0.631_578_778_769_468_818_155_702_492_90,
        -0.889_903_364_513_333_108_206_981_174_00e-1,
        0.181_485_055_208_547_272_566_564_049_62e2,
        -0.919_463_239_247_835_540_004_519_844_36e1,
        -0.443_603_638_759_489_396_643_105_720_00e1,
    ],
    [
        0.104_275_086_425_791_346_034_131_510_09e2,
        0.242_283_491_775_258_182_884_301_753_19e3,
        0.165_200_451_717_270_281_985_053_948_87e3,
        -0.374_546_754_722_690_202_795_183_121_52e3,
        -0.221_136_668_531_253_060_362_709_385_78e2,
        0.773_343_266_847_226_383_896_038_988_08e1,
        -0.306_740_847_310_893_981_820_612_136_26e2,
        -0.933_213_052_643_022_787_295_672_217_06e1,
        0.156_972_381_217_708_438_861_310_910_75e2,
        -0.311_394_032_195_651_776_772_828_504_11e2,
        -0.935_292_435_884_447_838_657_138_626_64e1,
        0.358_168_414_863_940_837_524_658_985_40e2,
    ],
    [
        0.199_850_532_420_024_338_209_876_536_17e2,
        -0.387_037_308_749_351_765_551_059_017_42e3,
        -0.189_178_138_195_167_568_828_308_383_28e3,
        0.527_808_159_205_423_649_005_610_166_86e3,
        -0.115_739_025_399_596_301_261_418_711_34e2,
        0.688_123_269_469_630_001_696_669_226_61e1,
        -0.100_060_509_669_108_384_031_838_609_80e1,
        0.777_713_779_805_344_320_928_692_657_40,
        -0.277_820_575_235_350_840_659_320_043_39e1,
        -0.601_966_952_312_641_207_582_673_808_46e2,
        0.843_204_055_066_771_610_181_599_037_84e2,
        0.119_922_911_361_827_893_280_351_300_30e2,
    ],
    [
        -0.256_939_334_627_037_490_033_125_861_29e2,
        -0.154_189_748_690_236_433_740_539_936_27e3,
        -0.231_529_379_176_045_495_675_360_391_09e3,
        0.357_639_117_910_614_123_782_853_499_10e3,
        0.934_053_241_836_243_100_039_076_917_04e2,
        -0.374_583_231_364_516_331_568_751_393_51e2,
        0.104_099_649_508_962_300_451_472_461_84e3,
        0.298_402_934_266_605_031_233_443_635_79e2,
        -0.435_334_565_900_111_437_544_321_750_58e2,
        0.963_245_539_591_882_829_483_949_506_00e2,
        -0.391_772_616_756_154_391_652_314_861_72e2,
        -0.149_726_836_257_985_625_814_221_252_76e3,
    ],
];

/// Hairer's I-controller for DOP853: h_new = h·0.9/err^(1/8), the step growing at most
/// sixfold.
const CONTROL: Control = Control { exponent: 0.125, beta: 0.0, max_factor: 6.0 };

/// Hairer's stiffness estimate is compared with 3.25 for DOPRI5 and 6.1 for DOP853, each
/// just inside its stability boundary on the negative real axis (3.3 and about 6). The
/// estimate is returned on DOPRI5's scale, so that the one test ([`crate::stiffness`])
/// serves both.
const DOP853_TO_DOPRI5: f64 = 3.25 / 6.1;

/// The stages the step keeps beyond [`Work::k`]: 7 to 12, the order-3 difference, and the
/// dense output's 14 to 16 ([`Work::new`] allocates them for an integration by DOP853).
pub(crate) const MORE: usize = 10;

/// The DOP853 scheme.
pub(crate) struct Dop853;

/// out = x + h·Σ cⱼ kⱼ over T terms, the sum for each element kept in a register.
#[inline(always)]
fn stage<const T: usize>(out: &mut [f64], x: &[f64], h: f64, terms: [(f64, &[f64]); T]) {
    let n = out.len();
    let (x, vectors) = (&x[..n], terms.map(|(_, v)| &v[..n]));
    let coefficients = terms.map(|(c, _)| c);
    for (i, o) in out.iter_mut().enumerate() {
        let mut s = 0.0;
        for j in 0..T {
            s += coefficients[j] * vectors[j][i];
        }
        *o = x[i] + h * s;
    }
}

/// out = h·Σ cⱼ kⱼ over T terms.
#[inline(always)]
fn combination<const T: usize>(out: &mut [f64], h: f64, terms: [(f64, &[f64]); T]) {
    let n = out.len();
    let vectors = terms.map(|(_, v)| &v[..n]);
    let coefficients = terms.map(|(c, _)| c);
    for (i, o) in out.iter_mut().enumerate() {
        let mut s = 0.0;
        for j in 0..T {
            s += coefficients[j] * vectors[j][i];
        }
        *o = h * s;
    }
}

impl<R: Rhs> Stepper<R> for Dop853 {
    /// One DOP853 step from (t, w.x) with `k[0]` = f(t, x): the solution in w.x_new,
    /// f(t + h, x_new) in `k[6]`, the twelfth stage's argument in w.tmp, the stages 2–6 in
    /// `k[1..6]` and 7–12 in `w.more`; returns Hairer's error norm
    /// ‖e₅‖² / √(‖e₅‖² + 0.01‖e₃‖²), e₅ and e₃ the differences from the order-5 and
    /// order-3 solutions, each measured by the error norm of every scheme.
    fn step(
        &self,
        ev: &mut Evaluator<'_, R>,
        w: &mut Work,
        t: f64,
        h: f64,
    ) -> Result<f64, FactorError> {
        let n = w.x.len();
        let Work { k, tmp, x, x_new, more, .. } = w;
        let [k1, k2, k3, k4, k5, k6, k13, e5] = k;
        let [k7, k8, k9, k10, k11, k12, e3, ..] = &mut more[..] else {
            unreachable!("Work::new allocates DOP853's stages")
        };
        let (x, tmp) = (&x[..n], &mut tmp[..n]);
        stage(tmp, x, h, [(A21, k1)]);
        ev.f(t + C2 * h, tmp, k2);
        stage(tmp, x, h, [(A31, k1), (A32, k2)]);
        ev.f(t + C3 * h, tmp, k3);
        stage(tmp, x, h, [(A41, k1), (A43, k3)]);
        ev.f(t + C4 * h, tmp, k4);
        stage(tmp, x, h, [(A51, k1), (A53, k3), (A54, k4)]);
        ev.f(t + C5 * h, tmp, k5);
        stage(tmp, x, h, [(A61, k1), (A64, k4), (A65, k5)]);
        ev.f(t + C6 * h, tmp, k6);
        stage(tmp, x, h, [(A71, k1), (A74, k4), (A75, k5), (A76, k6)]);
        ev.f(t + C7 * h, tmp, k7);
        stage(tmp, x, h, [(A81, k1), (A84, k4), (A85, k5), (A86, k6), (A87, k7)]);
        ev.f(t + C8 * h, tmp, k8);
        stage(tmp, x, h, [(A91, k1), (A94, k4), (A95, k5), (A96, k6), (A97, k7), (A98, k8)]);
        ev.f(t + C9 * h, tmp, k9);
        stage(
            tmp,
            x,
            h,
            [
                (A10_1, k1),
                (A10_4, k4),
                (A10_5, k5),
                (A10_6, k6),
                (A10_7, k7),
                (A10_8, k8),
                (A10_9, k9),
            ],
        );
        ev.f(t + C10 * h, tmp, k10);
        stage(
            tmp,
            x,
            h,
            [
                (A11_1, k1),
                (A11_4, k4),
                (A11_5, k5),
                (A11_6, k6),
                (A11_7, k7),
                (A11_8, k8),
                (A11_9, k9),
                (A11_10, k10),
            ],
        );
        ev.f(t + C11 * h, tmp, k11);
        stage(
            tmp,
            x,
            h,
            [
                (A12_1, k1),
                (A12_4, k4),
                (A12_5, k5),
                (A12_6, k6),
                (A12_7, k7),
                (A12_8, k8),
                (A12_9, k9),
                (A12_10, k10),
                (A12_11, k11),
            ],
        );
        ev.f(t + h, tmp, k12);
        let xn = &mut x_new[..n];
        stage(
            xn,
            x,
            h,
            [(B1, k1), (B6, k6), (B7, k7), (B8, k8), (B9, k9), (B10, k10), (B11, k11), (B12, k12)],
        );
        ev.f(t + h, xn, k13);
        combination(
            &mut e5[..n],
            h,
            [
                (ER1, k1),
                (ER6, k6),
                (ER7, k7),
                (ER8, k8),
                (ER9, k9),
                (ER10, k10),
                (ER11, k11),
                (ER12, k12),
            ],
        );
        combination(
            &mut e3[..n],
            h,
            [
                (B1 - BHH1, k1),
                (B6, k6),
                (B7, k7),
                (B8, k8),
                (B9 - BHH2, k9),
                (B10, k10),
                (B11, k11),
                (B12 - BHH3, k12),
            ],
        );
        let [err5, err3] = ev.error_norms([e5, e3], x, xn);
        let squared = err5 * err5;
        let denominator = (squared + 0.01 * err3 * err3).sqrt();
        // Both zero: an exact step. NaN passes on, and the loop retries shorter.
        Ok(if denominator == 0.0 { 0.0 } else { squared / denominator })
    }

    /// Hairer's dense output of order 7: r₁..r₄ the cubic Hermite interpolant's (both ends
    /// and their slopes), r₅..r₈ from the stages, three of them (14–16) evaluated here.
    fn dense(&self, ev: &mut Evaluator<'_, R>, w: &mut Work, t: f64, t_next: f64) {
        let h = t_next - t;
        let n = w.x.len();
        let Work { k, tmp, x, x_new, more, interpolant, .. } = w;
        let [k1, _, _, _, _, k6, k13, _] = k;
        let [k7, k8, k9, k10, k11, k12, _, k14, k15, k16] = &mut more[..] else {
            unreachable!("Work::new allocates DOP853's stages")
        };
        let (x, xn, tmp) = (&x[..n], &x_new[..n], &mut tmp[..n]);
        stage(
            tmp,
            x,
            h,
            [
                (A14[0], k1),
                (A14[1], k7),
                (A14[2], k8),
                (A14[3], k9),
                (A14[4], k10),
                (A14[5], k11),
                (A14[6], k12),
                (A14[7], k13),
            ],
        );
        ev.f(t + C14 * h, tmp, k14);
        stage(
            tmp,
            x,
            h,
            [
                (A15[0], k1),
                (A15[1], k6),
                (A15[2], k7),
                (A15[3], k8),
                (A15[4], k11),
                (A15[5], k12),
                (A15[6], k13),
                (A15[7], k14),
            ],
        );
        ev.f(t + C15 * h, tmp, k15);
        stage(
            tmp,
            x,
            h,
            [
                (A16[0], k1),
                (A16[1], k6),
                (A16[2], k7),
                (A16[3], k8),
                (A16[4], k9),
                (A16[5], k13),
                (A16[6], k14),
                (A16[7], k15),
            ],
        );
        ev.f(t + C16 * h, tmp, k16);
        interpolant.set_hermite((t, t_next), (x, xn), (&k1[..n], &k13[..n]));
        let [_, _, _, _, r5, r6, r7, r8] = interpolant.coefficients8_mut();
        let stages: [&[f64]; 12] = [k1, k6, k7, k8, k9, k10, k11, k12, k13, k14, k15, k16];
        for (r, d) in [r5, r6, r7, r8].into_iter().zip(&D) {
            combination(&mut r[..n], h, std::array::from_fn::<_, 12, _>(|j| (d[j], stages[j])));
        }
    }

    fn control(&self) -> Option<Control> {
        Some(CONTROL)
    }

    fn first_step_order(&self) -> i32 {
        8
    }

    /// h ‖f(x_new) − f(x₁₂)‖ / ‖x_new − x₁₂‖, both at t + h (x₁₂ the twelfth stage's
    /// argument, left in w.tmp), on DOPRI5's scale ([`DOP853_TO_DOPRI5`]).
    fn stiffness_estimate(&self, w: &Work, h: f64) -> Option<f64> {
        let n = w.x.len();
        let (k13, k12) = (&w.k[6][..n], &w.more[5][..n]);
        let (xn, x12) = (&w.x_new[..n], &w.tmp[..n]);
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..n {
            num += (k13[i] - k12[i]) * (k13[i] - k12[i]);
            den += (xn[i] - x12[i]) * (xn[i] - x12[i]);
        }
        Some(if den > 0.0 { DOP853_TO_DOPRI5 * h.abs() * (num / den).sqrt() } else { 0.0 })
    }
}

#[cfg(test)]
mod tests {
    //! The coefficients against the conditions a mistyped digit would break (to the
    //! rounding of their sums): each stage's row sums to its node, the weights to 1, the error weights to 0, and the order-8
    //! weights integrate t^q exactly up to q = 7 along the nodes (Σ bᵢ cᵢ^q = 1/(q + 1)).
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 2e-15 * a.abs().max(b.abs()).max(1.0)
    }

    #[test]
    fn rows_sum_to_their_nodes() {
        let rows: [(f64, &[f64]); 14] = [
            (C2, &[A21]),
            (C3, &[A31, A32]),
            (C4, &[A41, A43]),
            (C5, &[A51, A53, A54]),
            (C6, &[A61, A64, A65]),
            (C7, &[A71, A74, A75, A76]),
            (C8, &[A81, A84, A85, A86, A87]),
            (C9, &[A91, A94, A95, A96, A97, A98]),
            (C10, &[A10_1, A10_4, A10_5, A10_6, A10_7, A10_8, A10_9]),
            (C11, &[A11_1, A11_4, A11_5, A11_6, A11_7, A11_8, A11_9, A11_10]),
            (1.0, &[A12_1, A12_4, A12_5, A12_6, A12_7, A12_8, A12_9, A12_10, A12_11]),
            (C14, &A14),
            (C15, &A15),
            (C16, &A16),
        ];
        for (i, (c, row)) in rows.iter().enumerate() {
            // Rounding relative to the terms' sizes (up to 44 in a row summing to 0.6).
            let (sum, size): (f64, f64) = (row.iter().sum(), row.iter().map(|a| a.abs()).sum());
            assert!(
                (sum - c).abs() <= 4.0 * f64::EPSILON * size,
                "row {}: {sum} against {c}",
                i + 2
            );
        }
    }

    #[test]
    fn weights_are_consistent_and_of_order_eight_on_quadrature() {
        let b =
            [(B1, 0.0), (B6, C6), (B7, C7), (B8, C8), (B9, C9), (B10, C10), (B11, C11), (B12, 1.0)];
        for q in 0..8 {
            let sum: f64 = b.iter().map(|(w, c)| w * f64::powi(*c, q)).sum();
            assert!(close(sum, 1.0 / f64::from(q + 1)), "q = {q}: {sum}");
        }
        let e5: f64 = [ER1, ER6, ER7, ER8, ER9, ER10, ER11, ER12].iter().sum();
        assert!(e5.abs() < 1e-15, "order-5 difference's weights sum to {e5}");
        assert!(close(BHH1 + BHH2 + BHH3, 1.0), "order-3 weights");
    }

    #[test]
    fn dense_output_is_exact_for_a_constant_slope() {
        // With f constant the solution is a line, which r₁ + θ r₂ is (r₃ = r₄ = 0): each of
        // r₅..r₈, h·f·Σ dⱼ, must vanish.
        for (m, d) in D.iter().enumerate() {
            let sum: f64 = d.iter().sum();
            assert!(
                sum.abs() < 1e-11 * d.iter().map(|v| v.abs()).sum::<f64>(),
                "r{}: {sum}",
                m + 5
            );
        }
    }
}
