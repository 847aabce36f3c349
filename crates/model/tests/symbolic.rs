//! The symbolic Jacobians of model files against the dual-number reference: the example
//! models and random expressions, at random points; the compiled program against the
//! interpreted one, bit for bit.

use std::path::Path;

use crate::common;

use common::{expressions, reference, resolve};
use num_dual::{Dual64, HyperDual64};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sysid_model::expr::{Expr, Op, Program, parse};
use sysid_model::symbolic::Linearized;
use sysid_model::{Model, ModelSystem};
use sysid_ode::{Function, Inputs, JacobianProducts, SparseJacobian, System};

/// A function's values and its Jacobian [J_y | J_α] (row by row) at a point, through
/// [`JacobianProducts`] with unit directions: by the symbolic program, or by dual numbers
/// for a system built `with_dual_numbers`.
fn jacobians(
    sys: &ModelSystem,
    function: Function,
    x: (f64, &[f64], &[f64], &[f64]),
) -> (Vec<f64>, Vec<f64>) {
    let (t, y, p, u) = x;
    let sig = sys.signature();
    let (n, np) = (sig.n_states(), sig.n_parameters());
    let m = match function {
        Function::Rhs => n,
        Function::Outputs => sig.outputs().len(),
    };
    // Unit directions for every state and parameter: the products are the Jacobian.
    let k = n + np;
    let mut vy = vec![0.0; n * k];
    let mut vp = vec![0.0; np * k];
    for i in 0..n {
        vy[i * k + i] = 1.0;
    }
    for q in 0..np {
        vp[q * k + n + q] = 1.0;
    }
    let mut products = JacobianProducts::new(n, p, &vp, m, k);
    let (mut value, mut jacobian) = (vec![0.0; m], vec![0.0; m * k]);
    products.eval(sys, function, (t, y, u), &vy, &mut value, &mut jacobian);
    (value, jacobian)
}

/// Whether `a` and `b` agree to rounding: 1e-13 relative, or both NaN.
fn rounding(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
        || (a - b).abs() <= 1e-13 * a.abs().max(b.abs())
        || (a.is_nan() && b.is_nan())
}

/// The symbolic and the dual-number derivatives of `model` at `points` random points
/// (states, parameters and inputs drawn from [0.1, 2]): the right-hand side's and the
/// outputs' Jacobians, the right-hand side's second derivatives ∂²g/∂y∂z against hyper-dual
/// numbers, and the compiled program against the interpreted one, bit for bit.
fn agree(model: &Model, points: usize, seed: u64) {
    let name = model.file.path.display().to_string();
    let sig = model.system(Inputs::new(Vec::new())).signature().clone();
    let (n, np, nu) = (sig.n_states(), sig.n_parameters(), sig.n_inputs());
    let constant = || sysid_ode::Signal::steps(0.0, &[]).expect("a constant signal");
    let symbolic = model.system(Inputs::new((0..nu).map(|_| constant()).collect()));
    let dual = symbolic.with_dual_numbers();
    let rhs = symbolic.symbolic_rhs().expect("symbolic derivatives");
    let interpreted = rhs.interpreted();
    let second = rhs.curvature().expect("second derivatives");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..points {
        let mut draw =
            |len: usize| (0..len).map(|_| rng.random_range(0.1..2.0)).collect::<Vec<f64>>();
        let (y, p, u, t) = (draw(n), draw(np), draw(nu), draw(1)[0]);
        for function in [Function::Rhs, Function::Outputs] {
            let a = jacobians(&symbolic, function, (t, &y, &p, &u));
            let b = jacobians(&dual, function, (t, &y, &p, &u));
            for (x, z) in a.0.iter().chain(&a.1).zip(b.0.iter().chain(&b.1)) {
                assert!(rounding(*x, *z), "{name}: {function:?} {x} vs {z} at y={y:?} p={p:?}");
            }
        }

        let (mut w1, mut w2) = (rhs.workspace(), interpreted.workspace());
        rhs.eval(t, &y, &p, &u, &mut w1);
        interpreted.eval(t, &y, &p, &u, &mut w2);
        for &r in rhs.values().iter().chain(rhs.entries()) {
            let (a, b) = (w1[r as usize], w2[r as usize]);
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{name}: register {r}: {a} vs {b}"
            );
        }

        // ∂J_e/∂y_l for every entry e = (i, c) and state l: ε₁ along y_l, ε₂ along z_c.
        let mut w = second.workspace();
        second.eval(t, &y, &p, &u, &mut w);
        let mut hessian = vec![0.0; rhs.pattern().len() * n];
        for (&(e, l), &r) in second.pattern().iter().zip(second.entries()) {
            hessian[e as usize * n + l as usize] = w[r as usize];
        }
        for (e, &(i, c)) in rhs.pattern().iter().enumerate() {
            for l in 0..n {
                let yd: Vec<HyperDual64> = (0..n)
                    .map(|m| {
                        let along_c = if m == c as usize { 1.0 } else { 0.0 };
                        HyperDual64::new(y[m], if m == l { 1.0 } else { 0.0 }, along_c, 0.0)
                    })
                    .collect();
                let pd: Vec<HyperDual64> = (0..np)
                    .map(|q| {
                        HyperDual64::new(
                            p[q],
                            0.0,
                            if n + q == c as usize { 1.0 } else { 0.0 },
                            0.0,
                        )
                    })
                    .collect();
                let mut g = vec![HyperDual64::from_re(0.0); n];
                dual.rhs(t, &yd, &pd, &u, &mut g);
                let (x, z) = (hessian[e * n + l], g[i as usize].eps1eps2);
                assert!(rounding(x, z), "{name}: ∂²g_{i}/∂y_{l}∂z_{c}: {x} vs {z}");
            }
        }
    }
}

/// The example models, and the model-file twins of five catalogue systems (the nonlinear
/// ones exercise the second derivatives).
#[test]
fn example_models_and_catalogue_twins() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut paths: Vec<_> = ["falling-body", "short-period", "kinetics"]
        .iter()
        .map(|name| root.join("examples").join(name).join("model.toml"))
        .collect();
    let twins = std::fs::read_dir(root.join("tests/twins")).expect("the twins' directory");
    paths.extend(
        twins
            .map(|e| e.expect("an entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml")),
    );
    paths.sort();
    assert_eq!(paths.len(), 8, "{paths:?}");
    for path in paths {
        let model = Model::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        agree(&model, 200, 1);
    }
}

/// Whether some x^y in `e` has a negative base and an exponent that is not a number.
fn negative_base_to_a_variable_power(e: &Expr, x: f64, y: f64, k: f64, t: f64) -> bool {
    let sub = |e: &Expr| negative_base_to_a_variable_power(e, x, y, k, t);
    match e {
        Expr::Num(_) | Expr::Name(..) => false,
        Expr::Neg(a) => sub(a),
        Expr::Bin(op, a, b) => {
            (*op == Op::Pow && !matches!(**b, Expr::Num(_)) && reference(a, x, y, k, t) < 0.0)
                || sub(a)
                || sub(b)
        }
        Expr::Call(_, args, _) => args.iter().any(sub),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// The program's value and its three partial derivatives (x, y, k) against a dual-number
    /// evaluation of the same compiled expression, to rounding where the evaluation is well
    /// conditioned ([`well_conditioned`]: where it amplifies a relative change of its inputs
    /// a thousandfold, equally valid evaluation orders differ by more than rounding of the
    /// result, as cos((−1.5 tan t)²) does 0.02 from tan's pole, by 1.6e-11); the compiled
    /// program against the interpreted one, bit for bit, everywhere.
    #[test]
    fn symbolic_derivatives_equal_dual_numbers(
        e in expressions(true),
        x in 0.2..2.0f64, y in -1.5..1.5f64, k in 0.3..1.7f64, t in 0.0..2.0f64,
    ) {
        let text = e.to_string();
        // A constant that is not a finite number (log(0), x / 0) is refused by the reader.
        let parsed = parse(&text);
        prop_assume!(!parsed.as_ref().is_err_and(|err| {
            err.message.contains("is not a finite number") || err.message.contains("a constant zero")
        }));
        // A negative base to a power that depends on the point: powf gives a value where
        // the exponent happens to be an integer (min(0, y) = 0), the dual numbers'
        // exp(b ln a) NaN. Both paths agree on where x^y is defined, not on such points.
        prop_assume!(!negative_base_to_a_variable_power(&e, x, y, k, t));
        let program = Program::compile(&parsed.unwrap(), &resolve).unwrap();
        let linearized = Linearized::new(std::slice::from_ref(&program), (2, 1, 0));
        let interpreted = linearized.interpreted();
        let (mut a, mut b) = (linearized.workspace(), interpreted.workspace());
        linearized.eval(t, &[x, y], &[k], &[], &mut a);
        interpreted.eval(t, &[x, y], &[k], &[], &mut b);
        for &r in linearized.values().iter().chain(linearized.entries()) {
            let (u, v) = (a[r as usize], b[r as usize]);
            prop_assert!(u.to_bits() == v.to_bits() || (u.is_nan() && v.is_nan()), "{text}: {u} vs {v}");
        }

        let mut gradient = [0.0; 3];
        for (&(_, column), &r) in linearized.pattern().iter().zip(linearized.entries()) {
            gradient[column as usize] = a[r as usize];
        }
        let value = a[linearized.values()[0] as usize];
        for (column, &symbolic) in gradient.iter().enumerate() {
            let seed = |c: usize, v: f64| Dual64::new(v, if c == column { 1.0 } else { 0.0 });
            let at = |t: f64, x: f64, y: f64, k: f64| {
                program.eval::<Dual64>(t, &[seed(0, x), seed(1, y)], &[seed(2, k)], &[])
            };
            let dual = at(t, x, y, k);
            // (The value too: where simplification meets a signed zero, 0·x = +0 against
            // IEEE's −0·x = −0, one path divides into +∞ and the other into −∞, as the
            // model-file docs say.)
            prop_assume!(
                value.abs() < 1e6 && dual.re.abs() < 1e6 && dual.eps.abs() < 1e6 && symbolic.abs() < 1e6
            );
            prop_assume!(well_conditioned(dual, [at(t * (1.0 + H), x, y, k), at(t, x * (1.0 + H), y, k),
                at(t, x, y * (1.0 + H), k), at(t, x, y, k * (1.0 + H))]));
            // 1e-11: equally valid evaluation orders differ by more than 1e-12 where the
            // expression amplifies rounding within the condition allowed: tan((k⁻¹)⁻¹) near
            // its pole (1.7e-12 in the value), chained powers, (k³)⁻² as k⁻⁶ or step by step
            // (1.6e-12 in the derivative).
            prop_assert!((value - dual.re).abs() <= 1e-11 * dual.re.abs().max(1.0), "{text}: {value} vs {}", dual.re);
            prop_assert!(
                (symbolic - dual.eps).abs() <= 1e-11 * dual.eps.abs().max(1.0),
                "{text}: ∂/∂{} {symbolic} vs {}", ["x", "y", "k"][column], dual.eps
            );
        }
    }
}

/// The relative change of the inputs by which [`well_conditioned`] measures the condition.
const H: f64 = 1e-8;

/// Whether a value and a derivative change by at most a thousand times the relative change
/// H of any one input (t, x, y or k): a condition number below 1e3, under which the rounding
/// of a few dozen operations stays below the comparison's 1e-11.
fn well_conditioned(at: Dual64, moved: [Dual64; 4]) -> bool {
    let bound = |a: f64| 1e3 * H * a.abs().max(1.0);
    moved
        .iter()
        .all(|m| (m.re - at.re).abs() <= bound(at.re) && (m.eps - at.eps).abs() <= bound(at.eps))
}

/// The comparisons, the logic and `if` (what an imported SBML piecewise becomes): their
/// values at and around the switch, and their derivatives, the chosen branch's, against
/// dual numbers on both sides of it.
#[test]
fn comparisons_logic_and_if() {
    let value = |text: &str, t: f64, x: f64| {
        let program = Program::compile(&parse(text).expect("parses"), &resolve).expect("compiles");
        program.eval(t, &[x, 0.0], &[0.0], &[])
    };
    for (text, expected) in [
        ("lt(t, 2)", [1.0_f64, 0.0, 0.0]),
        ("le(t, 2)", [1.0, 1.0, 0.0]),
        ("gt(t, 2)", [0.0, 0.0, 1.0]),
        ("ge(t, 2)", [0.0, 1.0, 1.0]),
        ("eq(t, 2)", [0.0, 1.0, 0.0]),
        ("ne(t, 2)", [1.0, 0.0, 1.0]),
        ("not(eq(t, 2))", [1.0, 0.0, 1.0]),
        ("and(ge(t, 2), le(t, 2))", [0.0, 1.0, 0.0]),
        ("or(lt(t, 2), gt(t, 2))", [1.0, 0.0, 1.0]),
        ("if(le(t, 2), 3 * t, -1)", [3.0, 6.0, -1.0]),
    ] {
        for (t, want) in [1.0_f64, 2.0, 3.0].into_iter().zip(expected) {
            assert_eq!(value(text, t, 0.0).to_bits(), want.to_bits(), "{text} at t = {t}");
        }
    }
    // A NaN condition takes the else branch, as a false one does.
    assert_eq!(value("if(x, 1, 2)", 0.0, f64::NAN).to_bits(), 2.0_f64.to_bits());
    let text = r#"
states = ["x", "y"]
parameters = ["k", "c"]
[equations]
x = "if(and(le(t, c), gt(x, 0.5)), -k * x^2, k * y) + if(or(lt(y, 0.3), not(eq(k, 1))), sin(y), 0)"
y = "if(ge(x * y, c), x - y, exp(-k * y))"
[initial]
x = 1.0
y = 0.5
[known]
c = 1.0
[unknowns]
k = 0.7
[data]
file = "unused.csv"
"#;
    let file = sysid_model::ModelFile::parse(text, Path::new("switch.toml")).expect("reads");
    agree(&Model { file }, 400, 7);
}

/// x^k at x = 0, where x^k (k ln x · dx/x …) is 0 · ∞: the derivatives are their limits,
/// from the closed forms ∂/∂x = k x^(k−1) and ∂/∂k = x^k ln x → 0 (for k > 0). A Hill
/// term Z^n whose Z, or its initial value, sits on a bound of 0 (Borghans' calcium model,
/// n estimated) made every step onto that bound a failed integration.
#[test]
fn a_variable_power_of_zero_has_its_limits_as_derivatives() {
    let derivatives = |text: &str, x: f64, k: f64| {
        let program = Program::compile(&parse(text).expect("parses"), &resolve).expect("compiles");
        let linearized = Linearized::new(std::slice::from_ref(&program), (2, 1, 0));
        let mut w = linearized.workspace();
        linearized.eval(0.0, &[x, 0.5], &[k], &[], &mut w);
        let mut gradient = [0.0; 3];
        for (&(_, column), &r) in linearized.pattern().iter().zip(linearized.entries()) {
            gradient[column as usize] = w[r as usize];
        }
        (w[linearized.values()[0] as usize], gradient[0], gradient[2])
    };
    // (x, k) → (x^k, ∂/∂x, ∂/∂k).
    for (x, k, want) in [
        (0.0, 3.5, (0.0, 0.0, 0.0)),
        (0.0, 1.0, (0.0, 1.0, 0.0)),
        (0.0, 0.5, (0.0, f64::INFINITY, 0.0)),
        (2.0, 3.0, (8.0, 12.0, 8.0 * 2.0_f64.ln())),
    ] {
        let got = derivatives("x^k", x, k);
        let close = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a - b).abs() <= 1e-15 * b.abs();
        assert!(
            close(got.0, want.0) && close(got.1, want.1) && close(got.2, want.2),
            "x^k at x = {x}, k = {k}: {got:?}, want {want:?}"
        );
    }
    // Below 0 the power of a variable exponent is not defined, nor are its derivatives.
    let below = derivatives("x^k", -0.5, 2.5);
    assert!(below.0.is_nan() && below.2.is_nan(), "{below:?}");
}

/// A parameter that enters only an output has sensitivities S = 0 for all t, which the
/// integration does not carry: with such a column among those asked for, the others are the
/// same, bit for bit, as without it (the same augmented system is integrated), and the
/// column is exactly zero; a parameter in the right-hand side still moves.
#[test]
fn a_parameter_outside_the_right_hand_side_is_not_integrated() {
    use sysid_model::ModelFile;
    use sysid_ode::{Integrator, Ivp, Wrt};
    const MODEL: &str = r#"states = ["x", "y"]
parameters = ["k", "s"]
[equations]
x = "-k * x * y"
y = "k * x * y - y"
[initial]
x = 1.0
y = 0.1
[outputs]
scaled = "s * y"
[unknowns]
k = 2.0
s = 3.0
"#;
    let file = ModelFile::parse(MODEL, Path::new("sir.toml")).expect("a valid model");
    let sys = Model { file }.system(Inputs::new(Vec::new()));
    let ivp = Ivp::new(&sys, 0.0, &[1.0, 0.1], &[2.0, 3.0]);
    let times = [0.5, 1.0, 4.0];
    for integrator in [Integrator::dopri5(1e-8, 1e-10), Integrator::rodas4(1e-8, 1e-10)] {
        let both = [Wrt::Parameter(1), Wrt::InitialValue(0), Wrt::Parameter(0)];
        let with = ivp.solve_sensitivities(&integrator, &both, &times).unwrap();
        let without = ivp
            .solve_sensitivities(&integrator, &[Wrt::InitialValue(0), Wrt::Parameter(0)], &times)
            .unwrap();
        assert_eq!(with.counts(), without.counts());
        for m in 0..times.len() {
            assert_eq!(with.state(m), without.state(m));
            let (s, t) = (with.sensitivity(m), without.sensitivity(m));
            for i in 0..2 {
                assert_eq!(s[(i, 0)].to_bits(), 0.0f64.to_bits());
                assert_eq!(s[(i, 1)].to_bits(), t[(i, 0)].to_bits());
                assert_eq!(s[(i, 2)].to_bits(), t[(i, 1)].to_bits());
            }
            assert!(s[(1, 2)].abs() > 1e-3, "∂y/∂k = {}", s[(1, 2)]);
        }
    }
}

/// A switch time that is an unknown: x' = if(le(t, tau), a, −k·x), x(0) = 0, so x = a·t up
/// to τ and a·τ·e^{−k(t−τ)} after. Past the switch ∂x/∂τ = a(1 + kτ)e^{−k(t−τ)}: the jump
/// (g₋ − g₊)·∂τ/∂τ = a + k·a·τ at τ, carried on by the variational equation; before it, 0.
/// Backwards from x(5) = c, before τ x = c·e^{k(5−τ)} − a(τ − t) and
/// ∂x/∂τ = −a − k·c·e^{k(5−τ)}.
#[test]
fn a_switch_time_that_is_an_unknown_has_its_sensitivity() {
    use sysid_model::ModelFile;
    use sysid_ode::{Integrator, Ivp, Wrt};
    const MODEL: &str = r#"states = ["x"]
parameters = ["a", "k", "tau"]
[equations]
x = "if(le(t, tau), a, -k * x)"
[initial]
x = 0.0
[unknowns]
a = 2.0
k = 0.5
tau = 1.5
"#;
    let file = ModelFile::parse(MODEL, Path::new("switch.toml")).expect("a valid model");
    let sys = Model { file }.system(Inputs::new(Vec::new()));
    let (a, k, tau) = (2.0, 0.5, 1.5);
    let p = [a, k, tau];
    let wrt = [Wrt::Parameter(2), Wrt::Parameter(0), Wrt::Parameter(1)];
    let times = [0.5, 2.0, 4.0];
    for integrator in [Integrator::dopri5(1e-11, 1e-13), Integrator::rodas5p(1e-11, 1e-13)] {
        let sol = Ivp::new(&sys, 0.0, &[0.0], &p).solve_sensitivities(&integrator, &wrt, &times);
        let sol = sol.unwrap();
        for (m, &t) in times.iter().enumerate() {
            let decay = (-k * (t - tau)).exp();
            let (x, dtau, da, dk) = match t < tau {
                true => (a * t, 0.0, t, 0.0),
                false => (
                    a * tau * decay,
                    a * (1.0 + k * tau) * decay,
                    tau * decay,
                    -a * tau * (t - tau) * decay,
                ),
            };
            let s = sol.sensitivity(m);
            for (got, want) in
                [(sol.state(m)[0], x), (s[(0, 0)], dtau), (s[(0, 1)], da), (s[(0, 2)], dk)]
            {
                assert!((got - want).abs() < 1e-8, "t = {t}: {got} vs {want}");
            }
        }
        // Backwards across the switch from x(5) = c.
        let c = 0.7;
        let back = Ivp::new(&sys, 5.0, &[c], &p).solve_sensitivities(&integrator, &wrt, &[0.5]);
        let back = back.unwrap();
        let grown = c * (k * (5.0 - tau)).exp();
        assert!((back.state(0)[0] - (grown - a * (tau - 0.5))).abs() < 1e-8);
        let dtau = back.sensitivity(0)[(0, 0)];
        assert!((dtau - (-a - k * grown)).abs() < 1e-8, "{dtau} vs {}", -a - k * grown);
    }
}

/// A program long enough that the JIT compiles it as many functions (of 256 operations
/// each), values passing between them through the work space, on two threads into two
/// modules where the machine has two cores (at least 16 functions): 36 states, each coupled
/// to the 8 after it by a saturating, oscillating term. Its compiled values and Jacobian
/// equal the interpreted ones bit for bit, and the dual numbers' to rounding.
#[test]
fn a_long_program_compiled_in_segments_is_the_interpreted_one() {
    let n = 36;
    let mut text = String::from("states = [");
    text += &(1..=n).map(|i| format!("\"x{i}\"")).collect::<Vec<_>>().join(", ");
    text += "]\nparameters = [";
    text += &(1..=n).map(|i| format!("\"k{i}\"")).collect::<Vec<_>>().join(", ");
    text += "]\n[equations]\n";
    for i in 1..=n {
        let terms: Vec<String> = (1..=8)
            .map(|d| (i + d - 1) % n + 1)
            .map(|j| format!("k{j} * x{j} * sin(x{i} - x{j}) / (1 + x{i}^2 + k{i} * x{j})"))
            .collect();
        text += &format!("x{i} = \"-k{i} * x{i} * exp(-x{i}) + {}\"\n", terms.join(" + "));
    }
    text += "[initial]\n";
    for i in 1..=n {
        text += &format!("x{i} = 1.0\n");
    }
    text += "[unknowns]\n";
    for i in 1..=n {
        text += &format!("k{i} = 0.{i}\n");
    }
    text += "[data]\nfile = \"unused.csv\"\n";
    let file = sysid_model::ModelFile::parse(&text, Path::new("long.toml")).expect("reads");
    let model = Model { file };
    let system = model.system(Inputs::new(Vec::new()));
    let rhs = system.symbolic_rhs().expect("symbolic derivatives");
    let registers = rhs.workspace().len();
    assert!(registers > 17 * 256, "{registers} registers: the program spans 16 functions");
    let interpreted = rhs.interpreted();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..20 {
        let mut draw =
            |len: usize| (0..len).map(|_| rng.random_range(0.1..2.0)).collect::<Vec<f64>>();
        let (y, p, t) = (draw(n), draw(n), draw(1)[0]);
        let (mut a, mut b) = (rhs.workspace(), interpreted.workspace());
        rhs.eval(t, &y, &p, &[], &mut a);
        interpreted.eval(t, &y, &p, &[], &mut b);
        for &r in rhs.values().iter().chain(rhs.entries()) {
            let (u, v) = (a[r as usize], b[r as usize]);
            assert_eq!(u.to_bits(), v.to_bits(), "register {r}: {u} vs {v}");
        }
    }
    // The first derivatives against dual numbers too (`agree`'s first part), at one point.
    let (y, p) = (vec![0.7; n], vec![0.3; n]);
    let a = jacobians(&system, Function::Rhs, (0.5, &y, &p, &[]));
    let b = jacobians(&system.with_dual_numbers(), Function::Rhs, (0.5, &y, &p, &[]));
    for (x, z) in a.0.iter().chain(&a.1).zip(b.0.iter().chain(&b.1)) {
        assert!(rounding(*x, *z), "{x} vs {z}");
    }
}
