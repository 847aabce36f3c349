//! The mathematics of an imported problem: one tree for SBML's MathML and PEtab's formulas,
//! substituted (assignment rules, function definitions, observable parameters) and written
//! out in the model file's expression language.

use std::fmt::Write as _;

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
    fn function(self) -> &'static str {
        match self {
            Rel::Lt => "lt",
            Rel::Le => "le",
            Rel::Gt => "gt",
            Rel::Ge => "ge",
            Rel::Eq => "eq",
            Rel::Ne => "ne",
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
/// writes must also pass the model file's own limit, [`MAX_DEPTH`] levels of its syntax.)
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
        let mut out = String::new();
        self.write(&mut out, 0, name);
        out
    }

    fn precedence(&self) -> u8 {
        match self {
            Math::Add(v) | Math::Mul(v) if v.len() == 1 => v[0].precedence(),
            Math::Add(_) | Math::Sub(..) => 1,
            Math::Mul(_) | Math::Div(..) => 2,
            Math::Neg(_) => 3,
            Math::Num(v) if *v < 0.0 || v.is_sign_negative() => 3,
            Math::Pow(..) => 4,
            _ => 5,
        }
    }

    fn write(&self, out: &mut String, min: u8, name: &dyn Fn(&str) -> String) {
        let open = self.precedence() < min;
        if open {
            out.push('(');
        }
        let list = |out: &mut String, v: &[Math], sep: &str, level: u8| {
            for (i, a) in v.iter().enumerate() {
                if i > 0 {
                    out.push_str(sep);
                }
                a.write(out, level, name);
            }
        };
        let call = |out: &mut String, f: &str, v: &[Math]| {
            out.push_str(f);
            out.push('(');
            list(out, v, ", ", 0);
            out.push(')');
        };
        match self {
            Math::Num(v) => {
                let _ = write!(out, "{v:e}");
            }
            Math::Name(n) => out.push_str(&name(n)),
            Math::Time => out.push('t'),
            Math::Neg(a) => {
                out.push('-');
                a.write(out, 3, name);
            }
            Math::Add(v) if v.is_empty() => out.push('0'),
            Math::Mul(v) if v.is_empty() => out.push('1'),
            Math::Add(v) => list(out, v, " + ", 1),
            Math::Mul(v) => list(out, v, " * ", 2),
            Math::Sub(a, b) => {
                a.write(out, 1, name);
                out.push_str(" - ");
                b.write(out, 2, name);
            }
            Math::Div(a, b) => {
                a.write(out, 2, name);
                out.push_str(" / ");
                b.write(out, 3, name);
            }
            Math::Pow(a, b) => {
                a.write(out, 5, name);
                out.push('^');
                b.write(out, 3, name);
            }
            Math::Call(f, v) => call(out, f, v),
            Math::Compare(r, a, b) => call(out, r.function(), &[(**a).clone(), (**b).clone()]),
            Math::And(v) => fold(out, "and", v, name),
            Math::Or(v) => fold(out, "or", v, name),
            Math::Not(a) => call(out, "not", std::slice::from_ref(a)),
            Math::Piecewise(pieces, otherwise) => {
                // if(c1, v1, if(c2, v2, otherwise)). SBML leaves a piecewise without
                // `otherwise` undefined where no condition holds; there it takes the last
                // piece's value (the same wherever the pieces cover every case, as the
                // tools that write them do: Alkan's `gt` and `leq` of one level).
                let (pieces, last) = match (otherwise, pieces.split_last()) {
                    (Some(o), _) => (&pieces[..], (**o).clone()),
                    (None, Some(((value, _), before))) => (before, value.clone()),
                    (None, None) => (&pieces[..], Math::Num(f64::NAN)),
                };
                let nested = pieces.iter().rev().fold(last, |rest, (value, condition)| {
                    Math::Call("if", vec![condition.clone(), value.clone(), rest])
                });
                nested.write(out, 0, name);
            }
        }
        if open {
            out.push(')');
        }
    }
}

/// and(a, and(b, c)) for a logical operator of several arguments (1 for none: `and`; 0:
/// `or`).
fn fold(out: &mut String, f: &'static str, v: &[Math], name: &dyn Fn(&str) -> String) {
    match v {
        [] => out.push_str(if f == "and" { "1" } else { "0" }),
        [one] => Math::Call("ne", vec![one.clone(), Math::Num(0.0)]).write(out, 0, name),
        [first, rest @ ..] => {
            let tail = if rest.len() == 1 { rest[0].clone() } else { fold_math(f, rest) };
            Math::Call(f, vec![first.clone(), tail]).write(out, 0, name);
        }
    }
}

fn fold_math(f: &'static str, v: &[Math]) -> Math {
    match f {
        "and" => Math::And(v.to_vec()),
        _ => Math::Or(v.to_vec()),
    }
}

/// A formula that cannot be read: what, at which character (0-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FormulaError {
    /// 0-based character position in the formula.
    pub position: usize,
    /// What is wrong.
    pub message: String,
}

/// Reads a PEtab formula (observable, noise): numbers, identifiers, `+ - * / ^ **`,
/// parentheses and the functions `exp`, `log` (natural, or `log(x, base)`), `ln`,
/// `log10`, `log2`, `sqrt`, `abs`, `pow`, `sin`, `cos`, `tan`, `tanh`, `min`, `max`; `t` and
/// `time` are the time.
pub fn parse_formula(text: &str) -> Result<Math, FormulaError> {
    let tokens = lex(text)?;
    let mut p = Parser { tokens, at: 0, end: text.chars().count(), depth: 0 };
    let e = p.sum()?;
    match p.peek() {
        None => Ok(e),
        Some((_, at)) => Err(FormulaError { position: at, message: "unexpected text".into() }),
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Num(f64),
    Name(String),
    Op(char),
    Pow,
    Open,
    Close,
    Comma,
}

fn lex(text: &str) -> Result<Vec<(Token, usize)>, FormulaError> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let start = i;
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && chars.get(i + 1).is_some_and(char::is_ascii_digit)) {
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                i += 1;
            }
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    i = j;
                    while i < chars.len() && chars[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let s: String = chars[start..i].iter().collect();
            let v: f64 = s.parse().map_err(|_| FormulaError {
                position: start,
                message: format!("`{s}` is not a number"),
            })?;
            out.push((Token::Num(v), start));
            continue;
        }
        if c.is_alphabetic() || c == '_' {
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            out.push((Token::Name(chars[start..i].iter().collect()), start));
            continue;
        }
        let token = match c {
            '*' if chars.get(i + 1) == Some(&'*') => {
                i += 1;
                Token::Pow
            }
            '^' => Token::Pow,
            '+' | '-' | '*' | '/' => Token::Op(c),
            '(' => Token::Open,
            ')' => Token::Close,
            ',' => Token::Comma,
            _ => {
                return Err(FormulaError {
                    position: start,
                    message: format!("unexpected character `{c}`"),
                });
            }
        };
        i += 1;
        out.push((token, start));
    }
    Ok(out)
}

struct Parser {
    tokens: Vec<(Token, usize)>,
    at: usize,
    end: usize,
    /// How deeply the expression being read nests (parentheses, signs, exponents, calls).
    depth: usize,
}

/// How deeply a formula may nest: as deep as a model file's expressions
/// ([`sysid_model::expr::MAX_DEPTH`]), which a deeper one could not be written as.
pub const MAX_DEPTH: usize = sysid_model::expr::MAX_DEPTH;

impl Parser {
    fn peek(&self) -> Option<(Token, usize)> {
        self.tokens.get(self.at).cloned()
    }

    fn here(&self) -> usize {
        self.tokens.get(self.at).map_or(self.end, |t| t.1)
    }

    fn error(&self, message: &str) -> FormulaError {
        let what = match self.peek() {
            None => "the end".to_string(),
            Some((Token::Num(v), _)) => format!("`{v}`"),
            Some((Token::Name(n), _)) => format!("`{n}`"),
            Some((Token::Op(c), _)) => format!("`{c}`"),
            Some((Token::Pow, _)) => "`^`".into(),
            Some((Token::Open, _)) => "`(`".into(),
            Some((Token::Close, _)) => "`)`".into(),
            Some((Token::Comma, _)) => "`,`".into(),
        };
        FormulaError { position: self.here(), message: format!("{message}, found {what}") }
    }

    fn sum(&mut self) -> Result<Math, FormulaError> {
        let mut e = self.product()?;
        while let Some((Token::Op(c @ ('+' | '-')), _)) = self.peek() {
            self.at += 1;
            let b = self.product()?;
            e = if c == '+' {
                match e {
                    Math::Add(mut v) => {
                        v.push(b);
                        Math::Add(v)
                    }
                    a => Math::Add(vec![a, b]),
                }
            } else {
                Math::Sub(Box::new(e), Box::new(b))
            };
        }
        Ok(e)
    }

    fn product(&mut self) -> Result<Math, FormulaError> {
        let mut e = self.unary()?;
        while let Some((Token::Op(c @ ('*' | '/')), _)) = self.peek() {
            self.at += 1;
            let b = self.unary()?;
            e = if c == '*' {
                match e {
                    Math::Mul(mut v) => {
                        v.push(b);
                        Math::Mul(v)
                    }
                    a => Math::Mul(vec![a, b]),
                }
            } else {
                Math::Div(Box::new(e), Box::new(b))
            };
        }
        Ok(e)
    }

    /// Every nesting passes through here: a parenthesis or a call's argument (via
    /// [`sum`](Self::sum)), a sign, an exponent. Refused beyond [`MAX_DEPTH`], where the
    /// recursion would otherwise run out of stack.
    fn unary(&mut self) -> Result<Math, FormulaError> {
        if self.depth >= MAX_DEPTH {
            return Err(FormulaError {
                position: self.here(),
                message: format!(
                    "the formula nests more than {MAX_DEPTH} levels deep (parentheses, signs, powers and function calls)"
                ),
            });
        }
        self.depth += 1;
        let e = self.signed();
        self.depth -= 1;
        e
    }

    fn signed(&mut self) -> Result<Math, FormulaError> {
        match self.peek() {
            Some((Token::Op('-'), _)) => {
                self.at += 1;
                Ok(Math::Neg(Box::new(self.unary()?)))
            }
            Some((Token::Op('+'), _)) => {
                self.at += 1;
                self.unary()
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<Math, FormulaError> {
        let base = self.primary()?;
        if let Some((Token::Pow, _)) = self.peek() {
            self.at += 1;
            let exponent = self.unary()?;
            return Ok(Math::Pow(Box::new(base), Box::new(exponent)));
        }
        Ok(base)
    }

    fn primary(&mut self) -> Result<Math, FormulaError> {
        match self.peek() {
            Some((Token::Num(v), _)) => {
                self.at += 1;
                Ok(Math::Num(v))
            }
            Some((Token::Open, _)) => {
                self.at += 1;
                let e = self.sum()?;
                self.expect_close()?;
                Ok(e)
            }
            Some((Token::Name(n), at)) => {
                self.at += 1;
                if let Some((Token::Open, _)) = self.peek() {
                    self.at += 1;
                    let mut args = vec![self.sum()?];
                    while let Some((Token::Comma, _)) = self.peek() {
                        self.at += 1;
                        args.push(self.sum()?);
                    }
                    self.expect_close()?;
                    return function(&n, args)
                        .map_err(|message| FormulaError { position: at, message });
                }
                Ok(match n.as_str() {
                    "t" | "time" => Math::Time,
                    "pi" => Math::Num(std::f64::consts::PI),
                    _ => Math::Name(n),
                })
            }
            _ => Err(self.error("expected a number, a name or `(`")),
        }
    }

    fn expect_close(&mut self) -> Result<(), FormulaError> {
        match self.peek() {
            Some((Token::Close, _)) => {
                self.at += 1;
                Ok(())
            }
            _ => Err(self.error("expected `)`")),
        }
    }
}

/// A PEtab function applied to `args`, as the model file's language has it.
fn function(name: &str, mut args: Vec<Math>) -> Result<Math, String> {
    let arity = |n: usize| -> Result<(), String> {
        match args.len() == n {
            true => Ok(()),
            false => Err(format!("`{name}` takes {n} argument(s), got {}", args.len())),
        }
    };
    let log_of = |x: Math, base: f64| {
        Math::Div(Box::new(Math::Call("log", vec![x])), Box::new(Math::Num(base.ln())))
    };
    Ok(match name {
        "ln" => {
            arity(1)?;
            Math::Call("log", args)
        }
        "log" if args.len() == 2 => {
            let base = args.pop().expect("two");
            let x = args.pop().expect("two");
            Math::Div(Box::new(Math::Call("log", vec![x])), Box::new(Math::Call("log", vec![base])))
        }
        "log10" => {
            arity(1)?;
            log_of(args.remove(0), 10.0)
        }
        "log2" => {
            arity(1)?;
            log_of(args.remove(0), 2.0)
        }
        "pow" => {
            arity(2)?;
            let b = args.pop().expect("two");
            Math::Pow(Box::new(args.pop().expect("two")), Box::new(b))
        }
        "min" | "max" => {
            arity(2)?;
            Math::Call(if name == "min" { "min" } else { "max" }, args)
        }
        _ => match UNARY.iter().find(|f| **f == name) {
            Some(f) => {
                arity(1)?;
                Math::Call(f, args)
            }
            None => {
                return Err(format!(
                    "unknown function `{name}` (functions: exp, log, ln, log10, log2, sqrt, abs, pow, sin, cos, tan, tanh, min, max)"
                ));
            }
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn show(text: &str) -> String {
        parse_formula(text).expect("parses").render(&|n| n.to_string())
    }

    #[test]
    fn formulas_render_with_the_precedence_they_were_read_with() {
        assert_eq!(show("a - (b + c)"), "a - (b + c)");
        assert_eq!(show("a / (b * c)"), "a / (b * c)");
        assert_eq!(show("(a / b) * c"), "a / b * c");
        assert_eq!(show("-x**2"), "-x^2e0");
        assert_eq!(show("(-x)^2"), "(-x)^2e0");
        assert_eq!(show("a^b^c"), "a^b^c");
        assert_eq!(show("(a^b)^c"), "(a^b)^c");
        assert_eq!(show("2 * -b"), "2e0 * -b");
        assert_eq!(show("log10(x)"), format!("log(x) / {:e}", 10f64.ln()));
        assert_eq!(show("1e-3 * time"), "1e-3 * t");
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
        assert_eq!(parse_formula("a $ b").unwrap_err().position, 2);
        assert!(parse_formula("(a + b").is_err());
    }
}
