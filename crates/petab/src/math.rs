//! The mathematics of an imported problem: one tree for SBML's MathML and PEtab's formulas,
//! substituted (assignment rules, function definitions, observable parameters) and made into
//! the model file's expressions ([`Math::expr`]). PEtab's formulas are read by the model
//! file's own parser ([`parse_formula`]).

use sysid_model::expr::{Expr, ExprError, Func, Op, Syntax, parse_in};

/// A relational operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rel {
    /// <
    Lt,
    /// ≤
    Le,
    /// >
    Gt,
    /// ≥
    Ge,
    /// =
    Eq,
    /// ≠
    Ne,
}

impl Rel {
    /// The model file's function of this comparison (1 when it holds, else 0).
    fn function(self) -> Func {
        match self {
            Rel::Lt => Func::Lt,
            Rel::Le => Func::Le,
            Rel::Gt => Func::Gt,
            Rel::Ge => Func::Ge,
            Rel::Eq => Func::Eq,
            Rel::Ne => Func::Ne,
        }
    }
}

/// An expression.
#[derive(Clone, Debug, PartialEq)]
pub enum Math {
    /// A number.
    Num(f64),
    /// An identifier of the SBML model or the PEtab tables.
    Name(String),
    /// The time.
    Time,
    /// −a.
    Neg(Box<Math>),
    /// a + b + ….
    Add(Vec<Math>),
    /// a − b.
    Sub(Box<Math>, Box<Math>),
    /// a · b · ….
    Mul(Vec<Math>),
    /// a / b.
    Div(Box<Math>, Box<Math>),
    /// a ^ b.
    Pow(Box<Math>, Box<Math>),
    /// A function of the model file's language (`exp`, `log`, `sqrt`, `sin`, `cos`, `tan`,
    /// `tanh`, `abs`, `min`, `max`) applied to its arguments.
    Call(&'static str, Vec<Math>),
    /// A comparison, 1 when it holds, else 0.
    Compare(Rel, Box<Math>, Box<Math>),
    /// Logical and (1 or 0).
    And(Vec<Math>),
    /// Logical or (1 or 0).
    Or(Vec<Math>),
    /// Logical not (1 or 0).
    Not(Box<Math>),
    /// The value of the first piece whose condition holds, else `otherwise` (without one,
    /// the last piece's value: see `write`).
    Piecewise(Vec<(Math, Math)>, Option<Box<Math>>),
}

/// The deepest expression the importer composes (function definitions inlined, rules put
/// into each other): every tree it walks stays within the stack at this depth. (What it
/// writes must also pass the model file's own limit, [`sysid_model::expr::MAX_DEPTH`] levels
/// of its syntax.)
pub const MAX_COMPOSED_DEPTH: usize = 2_000;

/// The most nodes an expression the importer composes may have: rules that each use the
/// previous one twice would otherwise double it with every rule.
pub const MAX_COMPOSED_SIZE: usize = 1_000_000;

/// Checks the measure of a composed expression ([`Math::measure_with`]); the error says what
/// is exceeded.
pub fn check_composed((depth, size): (usize, usize)) -> Result<(), String> {
    if depth > MAX_COMPOSED_DEPTH {
        return Err(format!(
            "nests {depth} levels deep once its functions and rules are put in place (at most {MAX_COMPOSED_DEPTH})"
        ));
    }
    if size > MAX_COMPOSED_SIZE {
        return Err(format!(
            "grows to {size} terms once its functions and rules are put in place (at most {MAX_COMPOSED_SIZE})"
        ));
    }
    Ok(())
}

/// The functions of the model file's language with one argument.
pub const UNARY: &[&str] = &["exp", "log", "sqrt", "sin", "cos", "tan", "tanh", "abs"];

impl Math {
    /// The identifiers it uses, each once, in order of first use.
    pub fn names(&self) -> Vec<String> {
        let mut out = Vec::new();
        self.visit(&mut |m| {
            if let Math::Name(n) = m
                && !out.contains(n)
            {
                out.push(n.clone());
            }
        });
        out
    }

    pub(crate) fn visit(&self, f: &mut dyn FnMut(&Math)) {
        f(self);
        match self {
            Math::Num(_) | Math::Name(_) | Math::Time => {}
            Math::Neg(a) | Math::Not(a) => a.visit(f),
            Math::Sub(a, b) | Math::Div(a, b) | Math::Pow(a, b) | Math::Compare(_, a, b) => {
                a.visit(f);
                b.visit(f);
            }
            Math::Add(v) | Math::Mul(v) | Math::Call(_, v) | Math::And(v) | Math::Or(v) => {
                v.iter().for_each(|a| a.visit(f));
            }
            Math::Piecewise(pieces, otherwise) => {
                for (value, condition) in pieces {
                    value.visit(f);
                    condition.visit(f);
                }
                if let Some(o) = otherwise {
                    o.visit(f);
                }
            }
        }
    }

    /// The depth (a number or a name is 0 deep) and the number of nodes of the expression
    /// that [`substitute`](Self::substitute) would make with replacements of the depths and
    /// sizes `with` gives, computed without making it.
    pub fn measure_with(&self, with: &dyn Fn(&str) -> Option<(usize, usize)>) -> (usize, usize) {
        let mut children: Vec<(usize, usize)> = Vec::new();
        match self {
            Math::Name(n) => return with(n).unwrap_or((0, 1)),
            Math::Num(_) | Math::Time => return (0, 1),
            Math::Neg(a) | Math::Not(a) => children.push(a.measure_with(with)),
            Math::Sub(a, b) | Math::Div(a, b) | Math::Pow(a, b) | Math::Compare(_, a, b) => {
                children.extend([a.measure_with(with), b.measure_with(with)]);
            }
            Math::Add(v) | Math::Mul(v) | Math::Call(_, v) | Math::And(v) | Math::Or(v) => {
                children.extend(v.iter().map(|a| a.measure_with(with)));
            }
            Math::Piecewise(pieces, otherwise) => {
                for (value, condition) in pieces {
                    children.extend([value.measure_with(with), condition.measure_with(with)]);
                }
                children.extend(otherwise.iter().map(|o| o.measure_with(with)));
            }
        }
        let depth = children.iter().map(|c| c.0).max().unwrap_or(0) + 1;
        let size = children.iter().fold(1usize, |n, c| n.saturating_add(c.1));
        (depth, size)
    }

    /// The depth and the number of nodes ([`measure_with`](Self::measure_with)).
    pub fn measure(&self) -> (usize, usize) {
        self.measure_with(&|_| None)
    }

    /// The expression with every name for which `with` gives an expression replaced by it.
    pub fn substitute(&self, with: &dyn Fn(&str) -> Option<Math>) -> Math {
        let s = |a: &Math| Box::new(a.substitute(with));
        let all = |v: &[Math]| v.iter().map(|a| a.substitute(with)).collect();
        match self {
            Math::Name(n) => with(n).unwrap_or_else(|| self.clone()),
            Math::Num(_) | Math::Time => self.clone(),
            Math::Neg(a) => Math::Neg(s(a)),
            Math::Not(a) => Math::Not(s(a)),
            Math::Sub(a, b) => Math::Sub(s(a), s(b)),
            Math::Div(a, b) => Math::Div(s(a), s(b)),
            Math::Pow(a, b) => Math::Pow(s(a), s(b)),
            Math::Compare(r, a, b) => Math::Compare(*r, s(a), s(b)),
            Math::Add(v) => Math::Add(all(v)),
            Math::Mul(v) => Math::Mul(all(v)),
            Math::And(v) => Math::And(all(v)),
            Math::Or(v) => Math::Or(all(v)),
            Math::Call(name, v) => Math::Call(name, all(v)),
            Math::Piecewise(pieces, otherwise) => Math::Piecewise(
                pieces.iter().map(|(v, c)| (v.substitute(with), c.substitute(with))).collect(),
                otherwise.as_ref().map(|o| s(o)),
            ),
        }
    }

    /// The value when it is a number (after folding signs).
    pub fn number(&self) -> Option<f64> {
        match self {
            Math::Num(v) => Some(*v),
            Math::Neg(a) => a.number().map(|v| -v),
            _ => None,
        }
    }

    /// The expression in the model file's language, each identifier written as `name`
    /// gives it.
    pub fn render(&self, name: &dyn Fn(&str) -> String) -> String {
        self.expr(name).text()
    }

    /// The model file's expression of it, each identifier named as `name` gives it.
    pub fn expr(&self, name: &dyn Fn(&str) -> String) -> Expr {
        let e = |a: &Math| a.expr(name);
        let boxed = |a: &Math| Box::new(a.expr(name));
        let bin = |op, a: &Math, b: &Math| Expr::Bin(op, boxed(a), boxed(b));
        let call = |f, args: Vec<Expr>| Expr::Call(f, args, 0);
        // A sum or a product is one chain read left to right, its operands' own sums
        // (products) spliced in, as the model file reads it written out: a + (b − c) is
        // (a + b) − c, a · (b / c) is (a · b) / c.
        let chain = |level| {
            let mut operands = Vec::new();
            self.operands(level, Op::Add, &mut operands);
            let ((_, first), rest) = operands.split_first().expect("one operand at least");
            rest.iter().fold(e(first), |acc, (op, b)| Expr::Bin(*op, Box::new(acc), Box::new(e(b))))
        };
        match self {
            Math::Num(v) => Expr::Num(*v),
            Math::Name(n) => Expr::Name(name(n), 0),
            Math::Time => Expr::Name("t".into(), 0),
            Math::Neg(a) => Expr::Neg(boxed(a)),
            Math::Add(v) if v.is_empty() => Expr::Num(0.0),
            Math::Mul(v) if v.is_empty() => Expr::Num(1.0),
            Math::Add(_) | Math::Sub(..) => chain(1),
            Math::Mul(_) | Math::Div(..) => chain(2),
            Math::Pow(a, b) => bin(Op::Pow, a, b),
            Math::Call(f, v) => call(function(f), v.iter().map(e).collect()),
            Math::Compare(r, a, b) => call(r.function(), vec![e(a), e(b)]),
            Math::And(v) => logical(Func::And, v, name),
            Math::Or(v) => logical(Func::Or, v, name),
            Math::Not(a) => call(Func::Not, vec![e(a)]),
            Math::Piecewise(pieces, otherwise) => {
                // if(c1, v1, if(c2, v2, otherwise)). SBML leaves a piecewise without
                // `otherwise` undefined where no condition holds; there it takes the last
                // piece's value (the same wherever the pieces cover every case, as the
                // tools that write them do: Alkan's `gt` and `leq` of one level).
                let (pieces, last) = match (otherwise, pieces.split_last()) {
                    (Some(o), _) => (&pieces[..], e(o)),
                    (None, Some(((value, _), before))) => (before, e(value)),
                    (None, None) => (&pieces[..], Expr::Num(f64::NAN)),
                };
                pieces.iter().rev().fold(last, |rest, (value, condition)| {
                    call(Func::If, vec![e(condition), e(value), rest])
                })
            }
        }
    }

    /// The operands of a chain of sums (`level` 1) or products (2) this is part of, each
    /// with the operation that joins it to those before (`op` for the first).
    fn operands<'a>(&'a self, level: u8, op: Op, out: &mut Vec<(Op, &'a Math)>) {
        let (join, inverse) = if level == 1 { (Op::Add, Op::Sub) } else { (Op::Mul, Op::Div) };
        match self {
            Math::Add(v) | Math::Mul(v) if v.len() == 1 => v[0].operands(level, op, out),
            Math::Add(v) | Math::Mul(v) if !v.is_empty() && self.level() == Some(level) => {
                for (i, a) in v.iter().enumerate() {
                    a.operands(level, if i == 0 { op } else { join }, out);
                }
            }
            Math::Sub(a, b) | Math::Div(a, b) if self.level() == Some(level) => {
                a.operands(level, op, out);
                out.push((inverse, b));
            }
            _ => out.push((op, self)),
        }
    }

    /// 1 for a sum or difference, 2 for a product or quotient.
    fn level(&self) -> Option<u8> {
        match self {
            Math::Add(_) | Math::Sub(..) => Some(1),
            Math::Mul(_) | Math::Div(..) => Some(2),
            _ => None,
        }
    }

    /// The importer's tree of a model file's expression: sums and products flattened, `t`
    /// the time.
    pub fn from_expr(e: &Expr) -> Math {
        let boxed = |a: &Expr| Box::new(Math::from_expr(a));
        // The operands of a chain of `op`, flattened: (a + b) + c is a + b + c.
        fn operands(e: &Expr, op: Op, out: &mut Vec<Math>) {
            match e {
                Expr::Bin(o, a, b) if *o == op => {
                    operands(a, op, out);
                    out.push(Math::from_expr(b));
                }
                _ => out.push(Math::from_expr(e)),
            }
        }
        match e {
            Expr::Num(v) => Math::Num(*v),
            Expr::Name(n, _) if n == "t" => Math::Time,
            Expr::Name(n, _) => Math::Name(n.clone()),
            Expr::Neg(a) => Math::Neg(boxed(a)),
            Expr::Bin(op @ (Op::Add | Op::Mul), ..) => {
                let mut v = Vec::new();
                operands(e, *op, &mut v);
                if *op == Op::Add { Math::Add(v) } else { Math::Mul(v) }
            }
            Expr::Bin(Op::Sub, a, b) => Math::Sub(boxed(a), boxed(b)),
            Expr::Bin(Op::Div, a, b) => Math::Div(boxed(a), boxed(b)),
            Expr::Bin(Op::Pow, a, b) => Math::Pow(boxed(a), boxed(b)),
            Expr::Call(f, args, _) => {
                let mut v: Vec<Math> = args.iter().map(Math::from_expr).collect();
                let compare = |r, mut v: Vec<Math>| {
                    let b = Box::new(v.pop().expect("two"));
                    Math::Compare(r, Box::new(v.pop().expect("two")), b)
                };
                match f {
                    Func::Lt => compare(Rel::Lt, v),
                    Func::Le => compare(Rel::Le, v),
                    Func::Gt => compare(Rel::Gt, v),
                    Func::Ge => compare(Rel::Ge, v),
                    Func::Eq => compare(Rel::Eq, v),
                    Func::Ne => compare(Rel::Ne, v),
                    Func::And => Math::And(v),
                    Func::Or => Math::Or(v),
                    Func::Not => Math::Not(Box::new(v.remove(0))),
                    Func::If => {
                        let otherwise = v.pop().expect("three");
                        let value = v.pop().expect("three");
                        let condition = v.pop().expect("three");
                        Math::Piecewise(vec![(value, condition)], Some(Box::new(otherwise)))
                    }
                    f => Math::Call(f.name(), v),
                }
            }
        }
    }
}

/// The model file's function of a name of [`UNARY`], `min` or `max`.
fn function(name: &str) -> Func {
    Func::from_name(name).unwrap_or_else(|| unreachable!("the importer makes no call of `{name}`"))
}

/// and(a, and(b, c)) for a logical operator of several arguments (1 for none: `and`; 0:
/// `or`; a ≠ 0 for one).
fn logical(f: Func, v: &[Math], name: &dyn Fn(&str) -> String) -> Expr {
    match v {
        [] => Expr::Num(if f == Func::And { 1.0 } else { 0.0 }),
        [one] => Expr::Call(Func::Ne, vec![one.expr(name), Expr::Num(0.0)], 0),
        [first, rest @ ..] => {
            let rest = if let [one] = rest { one.expr(name) } else { logical(f, rest, name) };
            Expr::Call(f, vec![first.expr(name), rest], 0)
        }
    }
}

/// Reads a PEtab formula (observable, noise) with the model file's parser in PEtab's
/// syntax ([`Syntax::Petab`]): numbers, identifiers, `+ - * / ^ **`, parentheses and the
/// functions `exp`, `log` (natural, or `log(x, base)`), `ln`, `log10`, `log2`, `sqrt`,
/// `abs`, `pow`, `sin`, `cos`, `tan`, `tanh`, `min`, `max` (and the model file's own); `t`
/// and `time` are the time, `pi` the number.
pub fn parse_formula(text: &str) -> Result<Math, ExprError> {
    parse_in(text, Syntax::Petab).map(|e| Math::from_expr(&e))
}

#[cfg(test)]
mod tests {
    use sysid_model::expr::{MAX_DEPTH, parse};

    use super::*;

    fn show(text: &str) -> String {
        parse_formula(text).expect("parses").render(&|n| n.to_string())
    }

    #[test]
    fn formulas_render_with_the_precedence_they_were_read_with() {
        assert_eq!(show("a - (b + c)"), "a - (b + c)");
        assert_eq!(show("a / (b * c)"), "a / (b * c)");
        assert_eq!(show("(a / b) * c"), "a / b * c");
        assert_eq!(show("-x**2"), "-x^2");
        assert_eq!(show("(-x)^2"), "(-x)^2");
        assert_eq!(show("a^b^c"), "a^b^c");
        assert_eq!(show("(a^b)^c"), "(a^b)^c");
        assert_eq!(show("2 * -b"), "2 * -b");
        assert_eq!(show("-(a * b) + -(c + d)"), "-(a * b) + -(c + d)");
        assert_eq!(show("log10(x)"), format!("log(x) / {:?}", 10f64.ln()));
        assert_eq!(
            show("log(x, 3) + ln(y) + pow(y, 2) + log2(z)"),
            format!("log(x) / log(3) + log(y) + y^2 + log(z) / {:?}", 2f64.ln())
        );
        assert_eq!(show("1e-3 * time + pi"), format!("0.001 * t + {:?}", std::f64::consts::PI));
        assert_eq!(show("2.5e-300 * k + 1e300"), "2.5e-300 * k + 1e300");
    }

    /// What the importer writes, the model file's parser reads back as the same tree: every
    /// kind of node, under every kind of parent, on either side.
    #[test]
    fn written_expressions_read_back_as_the_same_tree() {
        let x = || Math::Name("x".into());
        let y = || Math::Name("y".into());
        let b = Box::new;
        let leaves = vec![
            Math::Num(0.25),
            x(),
            Math::Time,
            Math::Neg(b(x())),
            Math::Add(vec![x(), y(), Math::Num(3.0)]),
            Math::Sub(b(x()), b(y())),
            Math::Mul(vec![x(), y()]),
            Math::Div(b(x()), b(y())),
            Math::Pow(b(x()), b(y())),
            Math::Call("exp", vec![x()]),
            Math::Compare(Rel::Le, b(x()), b(y())),
            Math::And(vec![x(), y(), x()]),
            Math::Or(vec![x()]),
            Math::Not(b(x())),
            Math::Piecewise(vec![(x(), y()), (y(), x())], Some(b(Math::Num(1.0)))),
            Math::Piecewise(vec![(x(), y())], None),
        ];
        let parents: Vec<Box<dyn Fn(Math, Math) -> Math>> = vec![
            Box::new(|a, c| Math::Add(vec![a, c])),
            Box::new(|a, c| Math::Sub(b(a), b(c))),
            Box::new(|a, c| Math::Mul(vec![a, c])),
            Box::new(|a, c| Math::Div(b(a), b(c))),
            Box::new(|a, c| Math::Pow(b(a), b(c))),
            Box::new(|a, c| Math::Neg(b(Math::Add(vec![a, c])))),
            Box::new(|a, c| Math::Call("min", vec![a, c])),
        ];
        let mut checked = 0;
        for a in &leaves {
            for c in &leaves {
                for parent in &parents {
                    let tree = parent(a.clone(), c.clone()).expr(&|n| n.to_string());
                    let text = tree.text();
                    let read = parse(&text).unwrap_or_else(|e| panic!("{text}: {e}"));
                    // Display is fully parenthesised and carries no positions.
                    assert_eq!(read.to_string(), tree.to_string(), "{text}");
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 16 * 16 * 7);
    }

    #[test]
    fn formulas_nest_at_most_max_depth_deep() {
        let nested = |n: usize| format!("{}a{}", "(".repeat(n), ")".repeat(n));
        assert!(parse_formula(&nested(MAX_DEPTH - 1)).is_ok());
        for deep in [nested(10_000), format!("{}a", "-".repeat(200_000)), "a^".repeat(5_000) + "a"]
        {
            let e = parse_formula(&deep).unwrap_err();
            assert!(e.message.contains("nests more than 200 levels"), "{}", e.message);
        }
    }

    #[test]
    fn formula_errors_say_where() {
        let e = parse_formula("a + * b").unwrap_err();
        assert_eq!(e.position, 4);
        assert_eq!(e.message, "expected a number, a name or `(`, found `*`");
        let e = parse_formula("foo(a)").unwrap_err();
        assert!(e.message.contains("unknown function `foo`"), "{}", e.message);
        assert!(e.message.contains("log10"), "{}", e.message);
        assert_eq!(parse_formula("a $ b").unwrap_err().position, 2);
        assert!(parse_formula("(a + b").is_err());
        let e = parse_formula("log10(a, b)").unwrap_err();
        assert_eq!(e.message, "log10 takes 1 argument(s), got 2");
        // The model file's syntax has none of PEtab's additions.
        assert!(parse("a ** 2").is_err());
        assert!(parse("ln(a)").unwrap_err().message.contains("unknown function `ln`"));
        assert!(parse("log(a, 2)").is_err());
    }
}
