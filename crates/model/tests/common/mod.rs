//! Random expressions of x, y (states), k (a parameter) and t, for the property tests.

use proptest::prelude::*;
use sysid_model::expr::{Expr, Func, Op, Slot};

/// The names the expressions use.
pub const NAMES: [&str; 4] = ["x", "y", "k", "t"];

/// The slots of [`NAMES`].
pub fn resolve(name: &str) -> Option<Slot> {
    match name {
        "x" => Some(Slot::State(0)),
        "y" => Some(Slot::State(1)),
        "k" => Some(Slot::Parameter(0)),
        "t" => Some(Slot::Time),
        _ => None,
    }
}

/// Random expressions with the arithmetic operators, integer powers and the smooth
/// functions; with `kinks`, also x^y, negative powers, abs, min and max.
pub fn expressions(kinks: bool) -> impl Strategy<Value = Expr> {
    let leaf = prop_oneof![
        (-3.0..3.0f64).prop_map(|v| Expr::Num((v * 4.0).round() / 4.0)),
        (0..4usize).prop_map(|i| Expr::Name(NAMES[i].to_string(), 0)),
    ];
    let (ops, powers, unary): (usize, _, usize) =
        if kinks { (5, -2..5i32, 8) } else { (4, 0..4i32, 7) };
    leaf.prop_recursive(4, 24, 2, move |inner| {
        let functions = [
            Func::Exp,
            Func::Log,
            Func::Sqrt,
            Func::Sin,
            Func::Cos,
            Func::Tan,
            Func::Tanh,
            Func::Abs,
        ];
        let operators = [Op::Add, Op::Sub, Op::Mul, Op::Div, Op::Pow];
        let extremes = (inner.clone(), inner.clone(), any::<bool>()).prop_map(|(a, b, min)| {
            Expr::Call(if min { Func::Min } else { Func::Max }, vec![a, b], 0)
        });
        let arithmetic = prop_oneof![
            inner.clone().prop_map(|a| Expr::Neg(Box::new(a))),
            (inner.clone(), inner.clone(), 0..ops).prop_map(move |(a, b, op)| Expr::Bin(
                operators[op],
                Box::new(a),
                Box::new(b)
            )),
            (inner.clone(), powers.clone()).prop_map(|(a, n)| {
                Expr::Bin(Op::Pow, Box::new(a), Box::new(Expr::Num(n as f64)))
            }),
            (inner.clone(), 0..unary).prop_map(move |(a, f)| Expr::Call(functions[f], vec![a], 0)),
        ];
        if kinks { prop_oneof![4 => arithmetic, 1 => extremes].boxed() } else { arithmetic.boxed() }
    })
}

/// The reference: a direct walk of the tree in f64.
pub fn reference(e: &Expr, x: f64, y: f64, k: f64, t: f64) -> f64 {
    let r = |e: &Expr| reference(e, x, y, k, t);
    match e {
        Expr::Num(v) => *v,
        Expr::Name(n, _) => match n.as_str() {
            "x" => x,
            "y" => y,
            "k" => k,
            _ => t,
        },
        Expr::Neg(a) => -r(a),
        Expr::Bin(op, a, b) => {
            let (a, b) = (r(a), r(b));
            match op {
                Op::Add => a + b,
                Op::Sub => a - b,
                Op::Mul => a * b,
                Op::Div => a / b,
                Op::Pow => a.powf(b),
            }
        }
        Expr::Call(f, args, _) => {
            let a = r(&args[0]);
            match f {
                Func::Exp => a.exp(),
                Func::Log => a.ln(),
                Func::Sqrt => a.sqrt(),
                Func::Sin => a.sin(),
                Func::Cos => a.cos(),
                Func::Tan => a.tan(),
                Func::Tanh => a.tanh(),
                Func::Abs => a.abs(),
                Func::Min => a.min(r(&args[1])),
                Func::Max => a.max(r(&args[1])),
                Func::If => {
                    if a != 0.0 && !a.is_nan() {
                        r(&args[1])
                    } else {
                        r(&args[2])
                    }
                }
                f => {
                    let b = args.get(1).map_or(0.0, r);
                    let truth = match f {
                        Func::Lt => a < b,
                        Func::Le => a <= b,
                        Func::Gt => a > b,
                        Func::Ge => a >= b,
                        Func::Eq => a.partial_cmp(&b) == Some(std::cmp::Ordering::Equal),
                        Func::Ne => a.partial_cmp(&b) != Some(std::cmp::Ordering::Equal),
                        Func::And => a != 0.0 && b != 0.0 && !a.is_nan() && !b.is_nan(),
                        Func::Or => (a != 0.0 && !a.is_nan()) || (b != 0.0 && !b.is_nan()),
                        Func::Not => a == 0.0,
                        _ => unreachable!("every function is listed"),
                    };
                    f64::from(u8::from(truth))
                }
            }
        }
    }
}

/// The largest factor by which a small relative change of any one subexpression's value (its
/// rounding) moves the whole expression's value, relative to the larger of that value and 1:
/// the condition of the evaluation itself, which no input-wise condition shows
/// (tan(tan(tan t)) at t = 1.362 amplifies the inner tangent's rounding 75 000 times).
/// Measured by scaling each operation's result by 1 + 1e-9 in the reference walk (numbers
/// and names are exact: an integer power's exponent is not rounded); infinite where a scaled
/// walk is not finite.
pub fn rounding_amplification(e: &Expr, x: f64, y: f64, k: f64, t: f64) -> f64 {
    const DELTA: f64 = 1e-9;
    let value = reference(e, x, y, k, t);
    let nodes = count_nodes(e);
    (0..nodes)
        .map(|target| {
            let moved = reference(&scaled(e, target, &mut 0, 1.0 + DELTA), x, y, k, t);
            let amplification = (moved - value).abs() / (DELTA * value.abs().max(1.0));
            if amplification.is_finite() { amplification } else { f64::INFINITY }
        })
        .fold(0.0, f64::max)
}

fn count_nodes(e: &Expr) -> usize {
    1 + match e {
        Expr::Num(_) | Expr::Name(..) => 0,
        Expr::Neg(a) => count_nodes(a),
        Expr::Bin(_, a, b) => count_nodes(a) + count_nodes(b),
        Expr::Call(_, args, _) => args.iter().map(count_nodes).sum(),
    }
}

/// `e` with its `target`-th subexpression (in preorder, counted by `seen`) times `factor`.
fn scaled(e: &Expr, target: usize, seen: &mut usize, factor: f64) -> Expr {
    let here = *seen;
    *seen += 1;
    let rebuilt = match e {
        Expr::Num(_) | Expr::Name(..) => e.clone(),
        Expr::Neg(a) => Expr::Neg(Box::new(scaled(a, target, seen, factor))),
        Expr::Bin(op, a, b) => {
            let a = scaled(a, target, seen, factor);
            Expr::Bin(*op, Box::new(a), Box::new(scaled(b, target, seen, factor)))
        }
        Expr::Call(f, args, at) => {
            let args = args.iter().map(|a| scaled(a, target, seen, factor)).collect();
            Expr::Call(*f, args, *at)
        }
    };
    // Numbers and names are exact; only operations round.
    let rounds = !matches!(e, Expr::Num(_) | Expr::Name(..));
    if here == target && rounds {
        Expr::Bin(Op::Mul, Box::new(rebuilt), Box::new(Expr::Num(factor)))
    } else {
        rebuilt
    }
}
