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
