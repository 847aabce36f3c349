//! Random expressions: printed, parsed back and compiled, they evaluate as an independent
//! tree walk does, and their dual-number derivatives agree with finite differences.

use crate::common;

use common::{expressions, reference, resolve, rounding_amplification};
use num_dual::Dual64;
use proptest::prelude::*;
use sysid_model::expr::{Expr, Program, parse};

/// Whether every subexpression of `e` is moderate (finite, below 1e3 in size) at the point.
/// Where one is infinite (x/0, then tanh of it) the value may be finite but the derivative is
/// undefined; where one is huge, rounding differences between equally valid evaluations
/// (x³ as x·x·x or by powf) are amplified beyond the tolerance (sin(−2.75/t³) at small t).
fn moderate_throughout(e: &Expr, x: f64, y: f64, k: f64, t: f64) -> bool {
    let sub = |e: &Expr| moderate_throughout(e, x, y, k, t);
    reference(e, x, y, k, t).abs() < 1e3
        && match e {
            Expr::Num(_) | Expr::Name(..) => true,
            Expr::Neg(a) => sub(a),
            Expr::Bin(_, a, b) => sub(a) && sub(b),
            Expr::Call(_, args, _) => args.iter().all(sub),
        }
}

/// Whether `parse` refused a constant subexpression that is not a finite number.
fn constant_error(err: &sysid_model::expr::ExprError) -> bool {
    err.message.contains("is not a finite number") || err.message.contains("a constant zero")
}

/// Smooth expressions (no abs, min, max: their kinks defeat finite differences).
fn smooth() -> impl Strategy<Value = Expr> {
    expressions(false)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn compiled_expressions_evaluate_and_differentiate(
        e in smooth(),
        x in 0.2..2.0f64, y in -1.5..1.5f64, k in 0.3..1.7f64, t in 0.0..2.0f64,
    ) {
        let text = e.to_string();
        // A constant that is not a finite number (log(0), x / 0) is refused by the reader.
        let parsed = parse(&text);
        prop_assume!(!parsed.as_ref().is_err_and(constant_error));
        let parsed = parsed.map_err(|err| TestCaseError::fail(format!("{text}: {err}")))?;
        let program = Program::compile(&parsed, &resolve).unwrap();
        let expected = reference(&e, x, y, k, t);
        prop_assume!(moderate_throughout(&e, x, y, k, t));
        // Equally valid evaluations (the compiled program, the tree walk, dual numbers: tan
        // as sin/cos or not, x³ as x·x·x or by powf) round each subexpression by a few ulp,
        // and the expression amplifies each rounding by up to `amplification`: 1e-13
        // (about 450 ulp) times that, relative to the larger of the value and 1. An
        // evaluation that amplifies rounding a million times is no test of either path.
        let amplification = rounding_amplification(&e, x, y, k, t);
        prop_assume!(amplification < 1e6);
        let tolerance = |v: f64| 1e-13 * amplification.max(1.0) * v.abs().max(1.0);
        let value = program.eval::<f64>(t, &[x, y], &[k], &[]);
        prop_assert!((value - expected).abs() <= tolerance(expected), "{text}: {value} vs {expected}");

        // ∂/∂x by dual numbers against central differences, Richardson-extrapolated from
        // steps h and h/2. Where the two differences disagree (a pole or a fast oscillation
        // nearby: cos(3 tan x) close to π/2) the difference quotient is no reference.
        let dual = program.eval::<Dual64>(t, &[Dual64::new(x, 1.0), Dual64::from_re(y)], &[Dual64::from_re(k)], &[]);
        prop_assert!((dual.re - value).abs() <= tolerance(value), "{text}: {} vs {value}", dual.re);
        let f = |x: f64| program.eval::<f64>(t, &[x, y], &[k], &[]);
        let central = |h: f64| (f(x + h) - f(x - h)) / (2.0 * h);
        let (coarse, fine) = (central(1e-4), central(5e-5));
        let fd = (4.0 * fine - coarse) / 3.0;
        prop_assume!(fd.is_finite() && dual.eps.abs() < 1e4);
        prop_assume!((fine - coarse).abs() <= 1e-6 * fd.abs().max(1.0));
        prop_assert!((dual.eps - fd).abs() <= 1e-7 * dual.eps.abs().max(1.0), "{text}: d/dx {} vs {fd}", dual.eps);
    }

    #[test]
    fn the_parser_never_panics(text in "[-+*/^()., xyk0-9a-z]{0,40}") {
        let _ = parse(&text);
    }
}

#[test]
fn kinks_take_a_side() {
    let program = |text: &str| Program::compile(&parse(text).unwrap(), &resolve).unwrap();
    let d = |text: &str, x: f64| {
        program(text)
            .eval::<Dual64>(
                0.0,
                &[Dual64::new(x, 1.0), Dual64::from_re(0.0)],
                &[Dual64::from_re(0.0)],
                &[],
            )
            .eps
    };
    assert!((d("abs(x)", -2.0) + 1.0).abs() < 1e-15);
    assert!((d("min(x, 1)", 0.5) - 1.0).abs() < 1e-15);
    assert!(d("min(x, 1)", 1.5).abs() < 1e-15);
    assert!((d("max(x, 1)", 1.5) - 1.0).abs() < 1e-15);
}

/// tanh of a large argument is ±1 with derivative 0 through dual numbers too: num-dual's
/// sinh/cosh is ∞/∞ = NaN there (a steep switch tanh(k·(x − x₀)); symbolic.rs's property
/// test found it as tanh(y⁻²) at y = 0, the property test above had stepped around it). The
/// value exactly f64's tanh, the derivative against the closed form k / cosh²(k·x) to the
/// rounding of 1 − tanh² (1e-15 of its largest value, k), on both sides of the change of
/// formula at |k·x| = 20 and where sinh overflows (|k·x| = 1 000).
#[test]
fn tanh_stays_finite_through_dual_numbers_at_large_arguments() {
    let program = Program::compile(&parse("tanh(k * x)").unwrap(), &resolve).unwrap();
    let cases =
        [(1.0, 0.3), (1.0, 19.5), (1.0, 20.0), (1.0, 20.5), (1.0, -20.5), (1e3, 1.0), (1e3, -1.0)];
    for (k, x) in cases {
        let d = program.eval::<Dual64>(
            0.0,
            &[Dual64::new(x, 1.0), Dual64::from_re(0.0)],
            &[Dual64::from_re(k)],
            &[],
        );
        assert_eq!(d.re.to_bits(), (k * x).tanh().to_bits(), "tanh({k} · {x}): {}", d.re);
        let slope = k / (k * x).cosh().powi(2);
        assert!((d.eps - slope).abs() <= 1e-15 * k, "∂/∂x tanh({k} · {x}): {} vs {slope}", d.eps);
    }
}
