//! The expression language of model files.
//!
//! Grammar (usual precedence; `^` binds tighter than unary minus and is right-associative,
//! so `-x^2` is −(x²) and `2^3^2` is 2⁹):
//!
//! ```text
//! expr    = term (("+" | "-") term)*
//! term    = unary (("*" | "/") unary)*
//! unary   = ("-" | "+") unary | power
//! power   = primary ("^" unary)?
//! primary = number | name | name "(" expr ("," expr)* ")" | "(" expr ")"
//! number  = digits ["." digits] [("e" | "E") ["+" | "-"] digits]   (also ".5", "2.")
//! ```
//!
//! Functions: exp log sqrt sin cos tan tanh abs (one argument), min max (two). Names are the
//! model's states, parameters and inputs, and `t`. An expression nests at most
//! [`MAX_DEPTH`] levels deep.
//!
//! PEtab's formulas are read by the same lexer and parser ([`parse_in`] with
//! [`Syntax::Petab`]), which also take `**` for `^`, `ln`, `log(x, base)`, `log10`, `log2`,
//! `pow(a, b)`, `pi` and `time`, and write them in the model file's terms. [`Expr::text`]
//! prints an expression back with no more parentheses than it needs, as the parser reads it.
//!
//! Expressions are parsed once and compiled into a [`Program`]: a tree in one vector, names
//! resolved to slots, constant subexpressions folded, integer powers specialised. It is
//! evaluated for any [`Scalar`], so derivatives are exact dual numbers, never differences.

use std::fmt;

use arrayvec::ArrayVec;
use sysid_ode::Scalar;

/// A parse or name error at a character position of the expression (0-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExprError {
    /// Character offset in the expression.
    pub position: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ExprError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (character {})", self.message, self.position + 1)
    }
}

/// The deepest an expression may nest: parentheses, signs, function calls and exponents
/// nest at most this deep, and so do the operations of the parsed tree (a sum or a product
/// is a chain, `a + b + c` being `(a + b) + c`: 2 deep; a chain longer than this limit is
/// parsed as a balanced tree, log₂ n deep, instead of refused). Parsing, compiling, evaluating,
/// printing and dropping an expression each recurse once per level. At 200 levels the
/// deepest of them, parsing nested calls, takes about 0.2 MiB of stack in the workspace's
/// debug build (opt-level 1) and 1.4 MiB unoptimised: inside the 2 MiB of a worker thread,
/// where studies evaluate models (and parsing runs on the main thread's 8 MiB).
pub const MAX_DEPTH: usize = 200;

/// A binary operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    /// +
    Add,
    /// −
    Sub,
    /// ×
    Mul,
    /// ÷
    Div,
    /// ^
    Pow,
}

/// The syntax a text is written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Syntax {
    /// A model file's expressions: the grammar above.
    Model,
    /// A PEtab formula (an observable's or a noise formula): the model file's grammar and
    /// functions, and also `**` for `^`; `ln(x)`; `log(x, base)`; `log10(x)`; `log2(x)`;
    /// `pow(a, b)`; `pi`, the number; and `time`, the time (`t`). They are read as the model
    /// file's expressions: `log10(x)` is `log(x) / 2.302585092994046`.
    Petab,
}

/// A function of the language.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Func {
    /// eˣ
    Exp,
    /// natural logarithm
    Log,
    /// √x
    Sqrt,
    /// sine
    Sin,
    /// cosine
    Cos,
    /// tangent
    Tan,
    /// hyperbolic tangent
    Tanh,
    /// |x|
    Abs,
    /// min(a, b)
    Min,
    /// max(a, b)
    Max,
    /// if(c, a, b): a where c ≠ 0, else b (also where c is NaN).
    If,
    /// lt(a, b): 1 if a < b, else 0.
    Lt,
    /// le(a, b): 1 if a ≤ b, else 0.
    Le,
    /// gt(a, b): 1 if a > b, else 0.
    Gt,
    /// ge(a, b): 1 if a ≥ b, else 0.
    Ge,
    /// eq(a, b): 1 if a = b, else 0.
    Eq,
    /// ne(a, b): 1 if a ≠ b, else 0.
    Ne,
    /// and(a, b): 1 if both are nonzero, else 0.
    And,
    /// or(a, b): 1 if either is nonzero, else 0.
    Or,
    /// not(a): 1 if a = 0, else 0.
    Not,
}

impl Func {
    /// The function of that name in the model file's language.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "exp" => Func::Exp,
            "log" => Func::Log,
            "sqrt" => Func::Sqrt,
            "sin" => Func::Sin,
            "cos" => Func::Cos,
            "tan" => Func::Tan,
            "tanh" => Func::Tanh,
            "abs" => Func::Abs,
            "min" => Func::Min,
            "max" => Func::Max,
            "if" => Func::If,
            "lt" => Func::Lt,
            "le" => Func::Le,
            "gt" => Func::Gt,
            "ge" => Func::Ge,
            "eq" => Func::Eq,
            "ne" => Func::Ne,
            "and" => Func::And,
            "or" => Func::Or,
            "not" => Func::Not,
            _ => return None,
        })
    }
    /// Its name in the model file's language.
    pub fn name(self) -> &'static str {
        match self {
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Tanh => "tanh",
            Func::Abs => "abs",
            Func::Min => "min",
            Func::Max => "max",
            Func::If => "if",
            Func::Lt => "lt",
            Func::Le => "le",
            Func::Gt => "gt",
            Func::Ge => "ge",
            Func::Eq => "eq",
            Func::Ne => "ne",
            Func::And => "and",
            Func::Or => "or",
            Func::Not => "not",
        }
    }

    fn arity(self) -> usize {
        match self {
            Func::If => 3,
            Func::Min
            | Func::Max
            | Func::Lt
            | Func::Le
            | Func::Gt
            | Func::Ge
            | Func::Eq
            | Func::Ne
            | Func::And
            | Func::Or => 2,
            _ => 1,
        }
    }

    /// Whether it is a function of one argument compiled to a [`Node::Func`].
    fn is_unary(self) -> bool {
        matches!(
            self,
            Func::Exp
                | Func::Log
                | Func::Sqrt
                | Func::Sin
                | Func::Cos
                | Func::Tan
                | Func::Tanh
                | Func::Abs
        )
    }
}

/// The parsed expression, before names are resolved.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// A number.
    Num(f64),
    /// A name and its position.
    Name(String, usize),
    /// Unary minus.
    Neg(Box<Expr>),
    /// A binary operation.
    Bin(Op, Box<Expr>, Box<Expr>),
    /// A function call and its position.
    Call(Func, Vec<Expr>, usize),
}

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Num(f64),
    Name(String),
    Op(char),
    Open,
    Close,
    Comma,
}

fn lex(text: &str, syntax: Syntax) -> Result<Vec<(Token, usize)>, ExprError> {
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
            let literal: String = chars[start..i].iter().collect();
            let value: f64 = literal.parse().map_err(|_| ExprError {
                position: start,
                message: format!("`{literal}` is not a number"),
            })?;
            if !value.is_finite() {
                return Err(ExprError {
                    position: start,
                    message: format!(
                        "`{literal}` is beyond the largest floating-point number (about 1.8e308)"
                    ),
                });
            }
            out.push((Token::Num(value), start));
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
            '*' if syntax == Syntax::Petab && chars.get(i + 1) == Some(&'*') => {
                i += 1;
                Token::Op('^')
            }
            '+' | '-' | '*' | '/' | '^' => Token::Op(c),
            '(' => Token::Open,
            ')' => Token::Close,
            ',' => Token::Comma,
            _ => {
                return Err(ExprError {
                    position: i,
                    message: format!("unexpected character `{c}`"),
                });
            }
        };
        out.push((token, start));
        i += 1;
    }
    Ok(out)
}

struct Parser {
    tokens: Vec<(Token, usize)>,
    at: usize,
    end: usize,
    /// How many `unary` calls are open: every recursion of the grammar passes through one,
    /// and the outermost is open around any expression, so up to `MAX_DEPTH + 1`.
    open: usize,
    syntax: Syntax,
}

/// A parsed subexpression and the depth of its tree (a name or number is 0 deep).
type Parsed = (Expr, usize);

/// An operand of a chain of sums or products after the first: its operator's position,
/// whether the operator is the inverse one (− or /), and the operand.
struct Link {
    position: usize,
    inverse: bool,
    operand: Parsed,
}

impl Parser {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.at).map(|t| &t.0)
    }
    fn position(&self) -> usize {
        self.tokens.get(self.at).map_or(self.end, |t| t.1)
    }
    fn error<T>(&self, message: impl Into<String>) -> Result<T, ExprError> {
        Err(ExprError { position: self.position(), message: message.into() })
    }
    /// The depth of a node over children `depth` deep (a name or number is 0 deep), refused
    /// beyond [`MAX_DEPTH`] at `position` (the node's operator, sign or function name).
    fn nest(&self, depth: usize, position: usize) -> Result<usize, ExprError> {
        if depth >= MAX_DEPTH {
            return Err(too_deep(position));
        }
        Ok(depth + 1)
    }

    fn found(&self) -> String {
        match self.peek() {
            None => "the end".into(),
            Some(Token::Num(v)) => format!("`{v}`"),
            Some(Token::Name(n)) => format!("`{n}`"),
            Some(Token::Op(c)) => format!("`{c}`"),
            Some(Token::Open) => "`(`".into(),
            Some(Token::Close) => "`)`".into(),
            Some(Token::Comma) => "`,`".into(),
        }
    }

    fn expr(&mut self) -> Result<Parsed, ExprError> {
        let first = self.term()?;
        let mut rest = Vec::new();
        while let Some(Token::Op(c @ ('+' | '-'))) = self.peek() {
            let inverse = *c == '-';
            let position = self.position();
            self.at += 1;
            rest.push(Link { position, inverse, operand: self.term()? });
        }
        self.chain(first, rest, Op::Add)
    }

    fn term(&mut self) -> Result<Parsed, ExprError> {
        let first = self.unary()?;
        let mut rest = Vec::new();
        while let Some(Token::Op(c @ ('*' | '/'))) = self.peek() {
            let inverse = *c == '/';
            let position = self.position();
            self.at += 1;
            rest.push(Link { position, inverse, operand: self.unary()? });
        }
        self.chain(first, rest, Op::Mul)
    }

    /// `first` joined with the `rest` by `op` (Add or Mul) and its inverse (Sub or Div):
    /// left to right as written, `(a + b) + c`, where that nests within [`MAX_DEPTH`]; a
    /// longer chain (a flat sum of 300 terms is no nesting a user wrote) as a balanced tree,
    /// log₂ n deep, whose operations group the terms in pairs (its rounding differs from
    /// the written order's in the last bits).
    fn chain(&self, first: Parsed, rest: Vec<Link>, op: Op) -> Result<Parsed, ExprError> {
        let inverse_of = |op: Op| if op == Op::Add { Op::Sub } else { Op::Div };
        let written = rest.iter().try_fold(first.1, |depth, link| {
            Some(depth.max(link.operand.1) + 1).filter(|&d| d <= MAX_DEPTH)
        });
        if written.is_some() {
            let (mut left, mut depth) = first;
            for Link { position, inverse, operand: (right, d) } in rest {
                let op = if inverse { inverse_of(op) } else { op };
                depth = self.nest(depth.max(d), position)?;
                left = checked(Expr::Bin(op, Box::new(left), Box::new(right)), position)?;
            }
            return Ok((left, depth));
        }
        // Balanced: each term with whether it is subtracted (divided by), joined in pairs;
        // a pair of two such terms is one such term (−a − b = −(a + b)).
        let mut terms: Vec<(bool, Parsed, usize)> = vec![(false, first, rest[0].position)];
        terms.extend(rest.into_iter().map(|l| (l.inverse, l.operand, l.position)));
        while terms.len() > 1 {
            let mut paired = Vec::with_capacity(terms.len().div_ceil(2));
            let mut items = terms.into_iter();
            while let Some((inv_a, (a, da), position)) = items.next() {
                let Some((inv_b, (b, db), _)) = items.next() else {
                    paired.push((inv_a, (a, da), position));
                    break;
                };
                let depth = self.nest(da.max(db), position)?;
                let (inverted, node) = match (inv_a, inv_b) {
                    (false, false) | (true, true) => (inv_a, Expr::Bin(op, a.into(), b.into())),
                    (false, true) => (false, Expr::Bin(inverse_of(op), a.into(), b.into())),
                    (true, false) => (false, Expr::Bin(inverse_of(op), b.into(), a.into())),
                };
                paired.push((inverted, (checked(node, position)?, depth), position));
            }
            terms = paired;
        }
        // The pair holding the first term, never subtracted, is never one: nor is the root.
        let (inverted, parsed, _) = terms.pop().expect("a chain has a term");
        debug_assert!(!inverted, "the first term of a chain is not inverted");
        Ok(parsed)
    }

    /// A signed operand. Every recursion of the grammar (parentheses, calls, signs,
    /// exponents) comes through here, so counting the open calls bounds the parser's own
    /// stack, also for parentheses, which add no node.
    fn unary(&mut self) -> Result<Parsed, ExprError> {
        if self.open > MAX_DEPTH {
            return Err(too_deep(self.position()));
        }
        self.open += 1;
        let parsed = match self.peek() {
            Some(Token::Op('-')) => {
                let position = self.position();
                self.at += 1;
                let (inner, depth) = self.unary()?;
                (Expr::Neg(Box::new(inner)), self.nest(depth, position)?)
            }
            Some(Token::Op('+')) => {
                self.at += 1;
                self.unary()?
            }
            _ => self.power()?,
        };
        self.open -= 1;
        Ok(parsed)
    }

    fn power(&mut self) -> Result<Parsed, ExprError> {
        let (base, depth) = self.primary()?;
        if let Some(Token::Op('^')) = self.peek() {
            let position = self.position();
            self.at += 1;
            // Right-associative, and the exponent may carry its own sign: 2^-x.
            let (exponent, d) = self.unary()?;
            let depth = self.nest(depth.max(d), position)?;
            return Ok((
                checked(Expr::Bin(Op::Pow, Box::new(base), Box::new(exponent)), position)?,
                depth,
            ));
        }
        Ok((base, depth))
    }

    // `primary` and `call` recurse once per parenthesis or call: their frames are kept
    // small (the error messages are built in functions of their own) so that the parser's
    // stack at MAX_DEPTH stays well inside a worker thread's, also unoptimised.
    fn primary(&mut self) -> Result<Parsed, ExprError> {
        let position = self.position();
        match self.peek() {
            Some(&Token::Num(v)) => {
                self.at += 1;
                Ok((Expr::Num(v), 0))
            }
            Some(Token::Name(name)) => {
                let name = name.clone();
                self.at += 1;
                if self.peek() != Some(&Token::Open) {
                    return Ok((self.name(name, position), 0));
                }
                self.call(name, position)
            }
            Some(Token::Open) => {
                self.at += 1;
                let inner = self.expr()?;
                if self.peek() != Some(&Token::Close) {
                    return Err(self.expected("`)`"));
                }
                self.at += 1;
                Ok(inner)
            }
            _ => Err(self.expected("a number, a name or `(`")),
        }
    }

    /// A name that is not called: in a PEtab formula `pi` is the number and `time` the time.
    fn name(&self, name: String, position: usize) -> Expr {
        match (self.syntax, name.as_str()) {
            (Syntax::Petab, "pi") => Expr::Num(std::f64::consts::PI),
            (Syntax::Petab, "time") => Expr::Name("t".into(), position),
            _ => Expr::Name(name, position),
        }
    }

    /// The call of function `name` (at `position`), from its `(`.
    fn call(&mut self, name: String, position: usize) -> Result<Parsed, ExprError> {
        let func = Func::from_name(&name);
        if func.is_none() && !(self.syntax == Syntax::Petab && PETAB_FUNCTIONS.contains(&&*name)) {
            return Err(unknown_function(&name, position, self.syntax));
        }
        self.at += 1;
        let (first, mut depth) = self.expr()?;
        let mut args = vec![first];
        while self.peek() == Some(&Token::Comma) {
            self.at += 1;
            let (arg, d) = self.expr()?;
            depth = depth.max(d);
            args.push(arg);
        }
        if self.peek() != Some(&Token::Close) {
            return Err(self.expected(&format!("`,` or `)` in the call of {name}")));
        }
        self.at += 1;
        let petab_log = self.syntax == Syntax::Petab && name == "log" && args.len() == 2;
        let Some(func) = func.filter(|_| !petab_log) else {
            // One of PEtab's functions, written as the model file's: two levels at most.
            let depth = self.nest(self.nest(depth, position)?, position)?;
            return Ok((checked(petab_call(&name, args, position)?, position)?, depth));
        };
        if args.len() != func.arity() {
            return Err(wrong_arity(&name, func.arity(), args.len(), position));
        }
        let depth = self.nest(depth, position)?;
        Ok((checked(Expr::Call(func, args, position), position)?, depth))
    }

    /// "expected `what`, found …" at the current token.
    #[cold]
    #[inline(never)]
    fn expected(&self, what: &str) -> ExprError {
        ExprError {
            position: self.position(),
            message: format!("expected {what}, found {}", self.found()),
        }
    }
}

/// The functions of PEtab's formulas that are not the model file's, under their names.
const PETAB_FUNCTIONS: &[&str] = &["ln", "log", "log10", "log2", "pow"];

/// PEtab's function `name` of `args` (at `position`), as the model file's expression.
#[cold]
#[inline(never)]
fn petab_call(name: &str, mut args: Vec<Expr>, position: usize) -> Result<Expr, ExprError> {
    let arity = match name {
        "log" | "pow" => 2,
        _ => 1,
    };
    if args.len() != arity {
        return Err(wrong_arity(name, arity, args.len(), position));
    }
    let log = |x: Expr| Expr::Call(Func::Log, vec![x], position);
    let divided = |a: Expr, b: Expr| Expr::Bin(Op::Div, Box::new(a), Box::new(b));
    let second = args.pop().expect("checked above");
    Ok(match name {
        "ln" => log(second),
        "log10" => divided(log(second), Expr::Num(std::f64::consts::LN_10)),
        "log2" => divided(log(second), Expr::Num(std::f64::consts::LN_2)),
        "log" => divided(log(args.pop().expect("two")), log(second)),
        _ => Expr::Bin(Op::Pow, Box::new(args.pop().expect("two")), Box::new(second)),
    })
}

#[cold]
#[inline(never)]
fn unknown_function(name: &str, position: usize, syntax: Syntax) -> ExprError {
    let petab = match syntax {
        Syntax::Model => "",
        Syntax::Petab => ", ln, log10, log2, pow; log(x, base)",
    };
    ExprError {
        position,
        message: format!(
            "unknown function `{name}` (functions: exp, log, sqrt, sin, cos, tan, tanh, abs, min, max, if, lt, le, gt, ge, eq, ne, and, or, not{petab})"
        ),
    }
}

#[cold]
#[inline(never)]
fn wrong_arity(name: &str, arity: usize, got: usize, position: usize) -> ExprError {
    ExprError { position, message: format!("{name} takes {arity} argument(s), got {got}") }
}

/// `e` (an operation or call at `position`), unless it divides by a constant zero or its
/// operands are constants whose result is not a finite number (`sqrt(-1)`, `log(0)`,
/// `1e200 * 1e200`): such an equation can never be integrated, and the reader names it where
/// it is written rather than the integrator at t0.
fn checked(e: Expr, position: usize) -> Result<Expr, ExprError> {
    check_constant(&e, position).map(|()| e)
}

/// [`checked`]'s test of `e`.
fn check_constant(e: &Expr, position: usize) -> Result<(), ExprError> {
    if let Expr::Bin(Op::Div, _, divisor) = e
        && constant(divisor) == Some(0.0)
    {
        return Err(not_finite(format!("division by a constant zero: `{e}`"), position));
    }
    match constant(e) {
        Some(v) if !v.is_finite() => {
            Err(not_finite(format!("`{e}` is not a finite number (it is {v})"), position))
        }
        _ => Ok(()),
    }
}

/// The value of an expression without names, in f64.
fn constant(e: &Expr) -> Option<f64> {
    Some(match e {
        Expr::Num(v) => *v,
        Expr::Name(..) => return None,
        Expr::Neg(a) => -constant(a)?,
        Expr::Bin(op, a, b) => {
            let (a, b) = (constant(a)?, constant(b)?);
            match op {
                Op::Add => a + b,
                Op::Sub => a - b,
                Op::Mul => a * b,
                Op::Div => a / b,
                Op::Pow => a.powf(b),
            }
        }
        Expr::Call(Func::Min, args, _) => constant(&args[0])?.min(constant(&args[1])?),
        Expr::Call(Func::Max, args, _) => constant(&args[0])?.max(constant(&args[1])?),
        Expr::Call(f, args, _) if f.is_unary() => eval_func(*f, constant(&args[0])?),
        Expr::Call(f, args, _) => {
            let values: Vec<f64> = args.iter().map(constant).collect::<Option<_>>()?;
            switch(*f, &values)
        }
    })
}

#[cold]
#[inline(never)]
fn not_finite(message: String, position: usize) -> ExprError {
    ExprError { position, message }
}

/// The error of an expression that nests deeper than [`MAX_DEPTH`], at `position`.
#[cold]
#[inline(never)]
fn too_deep(position: usize) -> ExprError {
    ExprError {
        position,
        message: format!(
            "the expression nests more than {MAX_DEPTH} levels deep (parentheses, signs, function calls and operators)"
        ),
    }
}

/// Parses an expression of a model file (at most [`MAX_DEPTH`] levels deep).
pub fn parse(text: &str) -> Result<Expr, ExprError> {
    parse_in(text, Syntax::Model)
}

/// Parses an expression written in `syntax` (at most [`MAX_DEPTH`] levels deep).
pub fn parse_in(text: &str, syntax: Syntax) -> Result<Expr, ExprError> {
    let tokens = lex(text, syntax)?;
    let end = text.chars().count();
    let mut parser = Parser { tokens, at: 0, end, open: 0, syntax };
    if parser.peek().is_none() {
        return parser.error("empty expression");
    }
    let (expr, _) = parser.expr()?;
    if parser.peek().is_some() {
        return parser.error(format!("unexpected {} after the expression", parser.found()));
    }
    Ok(expr)
}

impl Expr {
    /// Checks a tree built by a program rather than parsed, as the parser checks what it
    /// reads: every number finite, every function called with its number of arguments, no
    /// division by a constant zero nor a constant operation whose result is not a finite
    /// number, and at most [`MAX_DEPTH`] levels deep. Errors are at the positions the tree
    /// carries.
    pub fn check(&self) -> Result<(), ExprError> {
        self.check_within(MAX_DEPTH)
    }

    fn check_within(&self, depth: usize) -> Result<(), ExprError> {
        let (position, operands): (usize, Vec<&Expr>) = match self {
            Expr::Num(v) if !v.is_finite() => {
                return Err(not_finite(format!("the number {v} is not finite"), 0));
            }
            Expr::Num(_) | Expr::Name(..) => return Ok(()),
            Expr::Neg(a) => (0, vec![a]),
            Expr::Bin(_, a, b) => (0, vec![a, b]),
            Expr::Call(f, args, position) => {
                if args.len() != f.arity() {
                    return Err(wrong_arity(f.name(), f.arity(), args.len(), *position));
                }
                (*position, args.iter().collect())
            }
        };
        if depth == 0 {
            return Err(too_deep(position));
        }
        for a in operands {
            a.check_within(depth - 1)?;
        }
        check_constant(self, position)
    }

    /// The names the expression uses, each once, in the order they first appear.
    pub fn names(&self) -> Vec<String> {
        fn walk(e: &Expr, out: &mut Vec<String>) {
            match e {
                Expr::Num(_) => {}
                Expr::Name(n, _) => {
                    if !out.contains(n) {
                        out.push(n.clone());
                    }
                }
                Expr::Neg(a) => walk(a, out),
                Expr::Bin(_, a, b) => {
                    walk(a, out);
                    walk(b, out);
                }
                Expr::Call(_, args, _) => args.iter().for_each(|a| walk(a, out)),
            }
        }
        let mut out = Vec::new();
        walk(self, &mut out);
        out
    }

    /// The expression as a model file writes it, with the parentheses the parser needs to
    /// read it back as this tree and no others (`a - (b + c)`, `-x^2`, `(a^b)^c`). A number
    /// is written with the fewest digits that read back as the same f64; a negative number
    /// reads back as the negation of its magnitude.
    pub fn text(&self) -> String {
        let mut out = String::new();
        self.write(&mut out, 0);
        out
    }

    /// How tightly it binds: 1 for a sum or difference, 2 a product or quotient, 3 a negation
    /// (or a negative number), 4 a power, 5 anything else.
    fn binding(&self) -> u8 {
        match self {
            Expr::Bin(Op::Add | Op::Sub, ..) => 1,
            Expr::Bin(Op::Mul | Op::Div, ..) => 2,
            Expr::Neg(_) => 3,
            Expr::Num(v) if v.is_sign_negative() => 3,
            Expr::Bin(Op::Pow, ..) => 4,
            _ => 5,
        }
    }

    /// Writes it where an operand must bind at least as tightly as `min`.
    fn write(&self, out: &mut String, min: u8) {
        use std::fmt::Write as _;
        let open = self.binding() < min;
        if open {
            out.push('(');
        }
        match self {
            Expr::Num(v) => {
                let digits = format!("{v:?}");
                out.push_str(digits.strip_suffix(".0").unwrap_or(&digits));
            }
            Expr::Name(n, _) => out.push_str(n),
            Expr::Neg(a) => {
                out.push('-');
                a.write(out, 3);
            }
            Expr::Bin(op, a, b) => {
                // Sums and products are read left to right, so a right operand of the same
                // binding is enclosed; a power is read right to left, and its exponent may be
                // signed (2^-x).
                let (left, sign, right) = match op {
                    Op::Add => (1, " + ", 2),
                    Op::Sub => (1, " - ", 2),
                    Op::Mul => (2, " * ", 3),
                    Op::Div => (2, " / ", 3),
                    Op::Pow => (5, "^", 3),
                };
                a.write(out, left);
                out.push_str(sign);
                b.write(out, right);
            }
            Expr::Call(func, args, _) => {
                let _ = write!(out, "{}(", func.name());
                for (i, a) in args.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    a.write(out, 0);
                }
                out.push(')');
            }
        }
        if open {
            out.push(')');
        }
    }
}

/// What a name refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Slot {
    /// State i.
    State(usize),
    /// Parameter i.
    Parameter(usize),
    /// Input i.
    Input(usize),
    /// The time t.
    Time,
}

/// An argument of an operation: a value read directly (no call), or another node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Operand {
    Node(u32),
    Var(Slot),
    Const(f64),
}

/// An operation. Operations with a constant argument have scalar forms, which skip the
/// arithmetic on a dual constant's zero derivative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Node {
    Neg(Operand),
    Add(Operand, Operand),
    Sub(Operand, Operand),
    Mul(Operand, Operand),
    Div(Operand, Operand),
    /// x + c.
    AddC(Operand, f64),
    /// c − x.
    SubC(f64, Operand),
    /// c·x.
    MulC(Operand, f64),
    /// x / c.
    DivC(Operand, f64),
    /// c / x.
    CDiv(f64, Operand),
    /// x^n for an integer n.
    PowI(Operand, i32),
    /// x^c for a constant c.
    PowF(Operand, f64),
    /// x^y.
    Pow(Operand, Operand),
    Func(Func, Operand),
    Min(Operand, Operand),
    Max(Operand, Operand),
    /// c if a < b, else d: the comparisons, logic and `if`.
    Less(Operand, Operand, Operand, Operand),
}

/// Where an expression switches in time (see [`Program::time_switches`]): at
/// offset + s·p_k.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Switch {
    pub(crate) offset: f64,
    /// (k, s), if a parameter moves it.
    pub(crate) parameter: Option<(usize, f64)>,
}

impl Switch {
    /// The time at the parameters `p`.
    pub(crate) fn at(&self, p: &[f64]) -> f64 {
        self.offset + self.parameter.map_or(0.0, |(k, s)| s * p[k])
    }
}

/// a·t + c + s·p_k.
#[derive(Clone, Copy, Debug)]
struct Affine {
    t: f64,
    c: f64,
    p: Option<(usize, f64)>,
}

impl Affine {
    fn times(self, x: f64) -> Self {
        Self { t: self.t * x, c: self.c * x, p: self.p.map(|(k, s)| (k, s * x)) }
    }

    /// The sum, if it has at most one parameter.
    fn plus(self, o: Self) -> Option<Self> {
        let p = match (self.p, o.p) {
            (None, p) | (p, None) => p,
            (Some((k, s)), Some((l, r))) if k == l => Some((k, s + r)),
            _ => return None,
        };
        Some(Self { t: self.t + o.t, c: self.c + o.c, p })
    }
}

/// The value of a comparison, logical function or `if` at numbers.
#[expect(clippy::float_cmp, reason = "eq and ne are exact, as SBML's are")]
fn switch(f: Func, v: &[f64]) -> f64 {
    let truth = |b: bool| if b { 1.0 } else { 0.0 };
    match f {
        Func::If => {
            if 0.0 < v[0].abs() {
                v[1]
            } else {
                v[2]
            }
        }
        Func::Lt => truth(v[0] < v[1]),
        Func::Le => truth(v[0] <= v[1]),
        Func::Gt => truth(v[0] > v[1]),
        Func::Ge => truth(v[0] >= v[1]),
        Func::Eq => truth(v[0] == v[1]),
        Func::Ne => truth(v[0] != v[1]),
        Func::And => truth(0.0 < v[0].abs() && 0.0 < v[1].abs()),
        Func::Or => truth(0.0 < v[0].abs() || 0.0 < v[1].abs()),
        Func::Not => truth(v[0] == 0.0),
        _ => unreachable!("not a switch"),
    }
}

/// A compiled expression.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    nodes: Vec<Node>,
    root: Operand,
}

impl Program {
    /// Compiles a parsed expression; `resolve` maps a name to its slot.
    pub fn compile(expr: &Expr, resolve: &dyn Fn(&str) -> Option<Slot>) -> Result<Self, ExprError> {
        let mut program = Program { nodes: Vec::new(), root: Operand::Const(0.0) };
        program.root = program.add(expr, resolve)?;
        Ok(program)
    }

    fn node(&mut self, node: Node) -> Operand {
        self.nodes.push(node);
        Operand::Node((self.nodes.len() - 1) as u32)
    }

    /// Adds the nodes of `expr`, children first, and returns the operand of its value.
    fn add(
        &mut self,
        expr: &Expr,
        resolve: &dyn Fn(&str) -> Option<Slot>,
    ) -> Result<Operand, ExprError> {
        use Operand::Const;
        Ok(match expr {
            Expr::Num(v) => Const(*v),
            Expr::Name(name, position) => match resolve(name) {
                Some(slot) => Operand::Var(slot),
                None => {
                    return Err(ExprError {
                        position: *position,
                        message: format!("unknown name `{name}`"),
                    });
                }
            },
            Expr::Neg(a) => match self.add(a, resolve)? {
                Const(c) => Const(-c),
                a => self.node(Node::Neg(a)),
            },
            Expr::Bin(op, a, b) => {
                let a = self.add(a, resolve)?;
                let b = self.add(b, resolve)?;
                self.binary(*op, a, b)
            }
            Expr::Call(f, args, _) => self.call(*f, args, resolve)?,
        })
    }

    /// A binary operation: folded when both operands are constant, in its scalar form when
    /// one is, integer powers specialised.
    fn binary(&mut self, op: Op, a: Operand, b: Operand) -> Operand {
        use Operand::Const;
        match (op, a, b) {
            (Op::Add, Const(x), Const(y)) => Const(x + y),
            (Op::Sub, Const(x), Const(y)) => Const(x - y),
            (Op::Mul, Const(x), Const(y)) => Const(x * y),
            (Op::Div, Const(x), Const(y)) => Const(x / y),
            (Op::Pow, Const(x), Const(y)) => Const(x.powf(y)),
            (Op::Add, x, Const(c)) | (Op::Add, Const(c), x) => self.node(Node::AddC(x, c)),
            (Op::Sub, x, Const(c)) => self.node(Node::AddC(x, -c)),
            (Op::Sub, Const(c), x) => self.node(Node::SubC(c, x)),
            (Op::Mul, x, Const(c)) | (Op::Mul, Const(c), x) => self.node(Node::MulC(x, c)),
            (Op::Div, x, Const(c)) => self.node(Node::DivC(x, c)),
            (Op::Div, Const(c), x) => self.node(Node::CDiv(c, x)),
            (Op::Pow, x, Const(c)) if c.fract() == 0.0 && c.abs() <= 64.0 => {
                self.node(Node::PowI(x, c as i32))
            }
            (Op::Pow, x, Const(c)) => self.node(Node::PowF(x, c)),
            (Op::Add, x, y) => self.node(Node::Add(x, y)),
            (Op::Sub, x, y) => self.node(Node::Sub(x, y)),
            (Op::Mul, x, y) => self.node(Node::Mul(x, y)),
            (Op::Div, x, y) => self.node(Node::Div(x, y)),
            (Op::Pow, x, y) => self.node(Node::Pow(x, y)),
        }
    }

    /// A function call: folded when its arguments are constant.
    fn call(
        &mut self,
        f: Func,
        args: &[Expr],
        resolve: &dyn Fn(&str) -> Option<Slot>,
    ) -> Result<Operand, ExprError> {
        use Operand::Const;
        let a = self.add(&args[0], resolve)?;
        Ok(match f {
            Func::Min | Func::Max => {
                let b = self.add(&args[1], resolve)?;
                match (a, b) {
                    (Const(x), Const(y)) => Const(if f == Func::Min { x.min(y) } else { x.max(y) }),
                    _ if f == Func::Min => self.node(Node::Min(a, b)),
                    _ => self.node(Node::Max(a, b)),
                }
            }
            f if f.is_unary() => match a {
                Const(x) => Const(eval_func(f, x)),
                a => self.node(Node::Func(f, a)),
            },
            f => {
                let mut operands = vec![a];
                for arg in &args[1..] {
                    operands.push(self.add(arg, resolve)?);
                }
                self.switch(f, &operands)
            }
        })
    }

    /// c if a < b, else d; folded when a and b are constant.
    fn less(&mut self, a: Operand, b: Operand, c: Operand, d: Operand) -> Operand {
        match (a, b) {
            (Operand::Const(x), Operand::Const(y)) => {
                if x < y {
                    c
                } else {
                    d
                }
            }
            _ if c == d => c,
            _ => self.node(Node::Less(a, b, c, d)),
        }
    }

    /// A comparison, logical function or `if` as [`Node::Less`] nodes: each is a choice
    /// between its values by one comparison, so its derivative is the chosen value's.
    fn switch(&mut self, f: Func, v: &[Operand]) -> Operand {
        use Operand::Const;
        let (zero, one) = (Const(0.0), Const(1.0));
        // 1 where x ≠ 0 (|x| > 0), else c.
        let nonzero = |p: &mut Self, x: Operand, yes: Operand, no: Operand| {
            let magnitude = match x {
                Const(c) => Const(c.abs()),
                x => p.node(Node::Func(Func::Abs, x)),
            };
            p.less(zero, magnitude, yes, no)
        };
        match f {
            Func::If => nonzero(self, v[0], v[1], v[2]),
            Func::Lt => self.less(v[0], v[1], one, zero),
            Func::Gt => self.less(v[1], v[0], one, zero),
            Func::Le => self.less(v[1], v[0], zero, one),
            Func::Ge => self.less(v[0], v[1], zero, one),
            Func::Eq => {
                let at_most = self.less(v[1], v[0], zero, one);
                self.less(v[0], v[1], zero, at_most)
            }
            Func::Ne => {
                let above = self.less(v[1], v[0], one, zero);
                self.less(v[0], v[1], one, above)
            }
            Func::Not => {
                let at_most = self.less(zero, v[0], zero, one);
                self.less(v[0], zero, zero, at_most)
            }
            Func::And => {
                let second = nonzero(self, v[1], one, zero);
                nonzero(self, v[0], second, zero)
            }
            Func::Or => {
                let second = nonzero(self, v[1], one, zero);
                nonzero(self, v[0], one, second)
            }
            _ => unreachable!("not a switch"),
        }
    }

    /// Evaluates at (t, y, α, u) for any scalar.
    ///
    /// The nodes are stored children first, so one pass in order computes them all, each
    /// reading its children's values from the slots before it: no recursion and no
    /// allocation (the slots live on the stack). Larger expressions than the slots hold are
    /// evaluated recursively.
    pub fn eval<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64]) -> T {
        if self.nodes.len() > SLOTS {
            return self.get(self.root, t, y, p, u);
        }
        let mut slots: ArrayVec<T, SLOTS> = ArrayVec::new();
        for node in &self.nodes {
            let value = compute(*node, |o| operand(o, &slots, t, y, p, u));
            slots.push(value);
        }
        operand(self.root, &slots, t, y, p, u)
    }

    /// Where the expression switches in time: every comparison of an affine function of
    /// `t`, a number and at most one parameter with zero (`le(t, t_end)`, `lt(t - t_on, 0)`,
    /// an `if` on them).
    pub(crate) fn time_switches(&self) -> Vec<Switch> {
        let mut out = Vec::new();
        for node in &self.nodes {
            if let Node::Less(a, b, _, _) = *node
                && let (Some(a), Some(b)) = (self.affine(a), self.affine(b))
                && let Some(d) = a.plus(b.times(-1.0))
                && d.t != 0.0
            {
                // d.t·t + d.c + s·p = 0.
                out.push(Switch { offset: -d.c / d.t, parameter: d.p.map(|(k, s)| (k, -s / d.t)) });
            }
        }
        out
    }

    /// The operand as a·t + c + s·p_k, if it is one.
    fn affine(&self, o: Operand) -> Option<Affine> {
        let constant = |c: f64| Affine { t: 0.0, c, p: None };
        match o {
            Operand::Const(c) => Some(constant(c)),
            Operand::Var(Slot::Time) => Some(Affine { t: 1.0, c: 0.0, p: None }),
            Operand::Var(Slot::Parameter(k)) => Some(Affine { t: 0.0, c: 0.0, p: Some((k, 1.0)) }),
            Operand::Var(_) => None,
            Operand::Node(i) => match self.nodes[i as usize] {
                Node::Add(a, b) => self.affine(a)?.plus(self.affine(b)?),
                Node::Sub(a, b) => self.affine(a)?.plus(self.affine(b)?.times(-1.0)),
                Node::AddC(a, c) => self.affine(a)?.plus(constant(c)),
                Node::SubC(c, a) => constant(c).plus(self.affine(a)?.times(-1.0)),
                Node::Neg(a) => Some(self.affine(a)?.times(-1.0)),
                Node::MulC(a, c) => Some(self.affine(a)?.times(c)),
                _ => None,
            },
        }
    }

    /// The operations, children first.
    pub(crate) fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// The operand of the value.
    pub(crate) fn root(&self) -> Operand {
        self.root
    }

    /// Whether the value is a constant (does not depend on t, states, parameters or inputs).
    pub fn is_constant(&self) -> bool {
        matches!(self.root, Operand::Const(_))
    }

    #[inline]
    fn get<T: Scalar>(&self, o: Operand, t: f64, y: &[T], p: &[T], u: &[f64]) -> T {
        match o {
            Operand::Node(i) => self.eval_node(i, t, y, p, u),
            Operand::Var(Slot::State(k)) => y[k],
            Operand::Var(Slot::Parameter(k)) => p[k],
            Operand::Var(Slot::Input(k)) => T::from(u[k]),
            Operand::Var(Slot::Time) => T::from(t),
            Operand::Const(c) => T::from(c),
        }
    }

    /// The recursive evaluation of node i, for expressions larger than the slots.
    fn eval_node<T: Scalar>(&self, i: u32, t: f64, y: &[T], p: &[T], u: &[f64]) -> T {
        compute(self.nodes[i as usize], |o| self.get(o, t, y, p, u))
    }
}

/// Slots for intermediate values in [`Program::eval`]; an equation of a model rarely needs
/// more than a few dozen.
const SLOTS: usize = 64;

/// The value of an operand, with node values from `slots`.
#[inline(always)]
fn operand<T: Scalar>(o: Operand, slots: &[T], t: f64, y: &[T], p: &[T], u: &[f64]) -> T {
    match o {
        Operand::Node(i) => slots[i as usize],
        Operand::Var(Slot::State(k)) => y[k],
        Operand::Var(Slot::Parameter(k)) => p[k],
        Operand::Var(Slot::Input(k)) => T::from(u[k]),
        Operand::Var(Slot::Time) => T::from(t),
        Operand::Const(c) => T::from(c),
    }
}

/// x^c for a constant c that is not an integer. num-dual's powf computes x^c as
/// x^(c−3)·x³, which is ∞·0 = NaN at x = 0 for any 0 < c < 3, in the value as well. There
/// the value is 0; with c > 1 every first derivative c·x^(c−1)·dx is 0 (a Hill term x^2.75
/// of a species that starts at 0), as in the compiled derivatives; with 0 < c < 1 it is
/// infinite, c·0^(c−1)·dx, and √x gives the same value there with a derivative that is not
/// a number (num-dual's √x at 0): a rate k^0.5 of a parameter on its bound 0 has its value.
#[inline(always)]
fn power<T: Scalar>(x: T, c: f64) -> T {
    match x.re() == 0.0 {
        true if c > 1.0 => x * 0.0 + 0.0,
        true if c > 0.0 && c < 1.0 => x.sqrt(),
        _ => x.powf(c),
    }
}

/// tanh x. num-dual's is sinh x / cosh x, ∞/∞ = NaN beyond |x| ≈ 710, where tanh is ±1
/// and its derivative 1 − tanh² is 0 (a steep switch tanh(k·(x − x₀)), or tanh of a term
/// with a pole). Past |x| = 20, where tanh x rounds to ±1, it is (1 − u)/(1 + u) with
/// u = e^(−2|x|), times the sign of x, whose value and derivative 4u/(1 + u)² stay finite;
/// below, where that form loses digits, num-dual's.
#[inline(always)]
fn tanh<T: Scalar>(x: T) -> T {
    let re = x.re();
    if re.abs() <= 20.0 {
        return x.tanh();
    }
    let sign = re.signum();
    let u = (x * (-2.0 * sign)).exp();
    (-u + 1.0) / (u + 1.0) * sign
}

/// One operation on its operands' values.
#[inline(always)]
fn compute<T: Scalar>(node: Node, get: impl Fn(Operand) -> T) -> T {
    match node {
        Node::Neg(a) => -get(a),
        Node::Add(a, b) => get(a) + get(b),
        Node::Sub(a, b) => get(a) - get(b),
        Node::Mul(a, b) => get(a) * get(b),
        Node::Div(a, b) => get(a) / get(b),
        Node::AddC(a, c) => get(a) + c,
        Node::SubC(c, a) => -get(a) + c,
        Node::MulC(a, c) => get(a) * c,
        Node::DivC(a, c) => get(a) / c,
        Node::CDiv(c, a) => get(a).recip() * c,
        Node::PowI(a, n) => get(a).powi(n),
        Node::PowF(a, c) => power(get(a), c),
        Node::Pow(a, b) => get(a).powd(get(b)),
        Node::Func(f, a) => {
            let x = get(a);
            match f {
                Func::Exp => x.exp(),
                Func::Log => x.ln(),
                Func::Sqrt => x.sqrt(),
                Func::Sin => x.sin(),
                Func::Cos => x.cos(),
                Func::Tan => x.tan(),
                Func::Tanh => tanh(x),
                Func::Abs => x.abs(),
                _ => unreachable!("compiled to nodes of their own"),
            }
        }
        Node::Min(a, b) => {
            let (x, y) = (get(a), get(b));
            if y.re() < x.re() { y } else { x }
        }
        Node::Max(a, b) => {
            let (x, y) = (get(a), get(b));
            if y.re() > x.re() { y } else { x }
        }
        Node::Less(a, b, c, d) => {
            if get(a).re() < get(b).re() {
                get(c)
            } else {
                get(d)
            }
        }
    }
}

pub(crate) fn eval_func(f: Func, x: f64) -> f64 {
    match f {
        Func::Exp => x.exp(),
        Func::Log => x.ln(),
        Func::Sqrt => x.sqrt(),
        Func::Sin => x.sin(),
        Func::Cos => x.cos(),
        Func::Tan => x.tan(),
        Func::Tanh => x.tanh(),
        Func::Abs => x.abs(),
        _ => unreachable!("functions of several arguments are folded on their own"),
    }
}

impl fmt::Display for Expr {
    /// Fully parenthesised, for round trips in tests.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            // A negative number is parenthesised: -1 ^ 2 reads as -(1²).
            Expr::Num(v) if v.is_sign_negative() => write!(f, "({v:?})"),
            Expr::Num(v) => write!(f, "{v:?}"),
            Expr::Name(n, _) => write!(f, "{n}"),
            Expr::Neg(a) => write!(f, "(-{a})"),
            Expr::Bin(op, a, b) => {
                let c = match op {
                    Op::Add => '+',
                    Op::Sub => '-',
                    Op::Mul => '*',
                    Op::Div => '/',
                    Op::Pow => '^',
                };
                write!(f, "({a} {c} {b})")
            }
            Expr::Call(func, args, _) => {
                let args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
                write!(f, "{}({})", func.name(), args.join(", "))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_ode::testing::assert_close;

    /// A fractional power of 0 through the dual numbers: the value 0, as powf and the
    /// compiled program have it (num-dual's powf gave NaN); the derivative 0 above 1, and
    /// below 1, where c·0^(c−1) is infinite, not a number.
    #[test]
    fn a_fractional_power_of_zero_is_zero_through_the_dual_numbers() {
        use num_dual::Dual64;
        let resolve = |name: &str| (name == "x").then_some(Slot::State(0));
        for (text, derivative) in [("x^0.75", f64::NAN), ("x^0.5", f64::NAN), ("x^2.75", 0.0)] {
            let program = Program::compile(&parse(text).unwrap(), &resolve).unwrap();
            let at = program.eval::<Dual64>(0.0, &[Dual64::new(0.0, 1.0)], &[], &[]);
            let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
            assert!(same(at.re, 0.0) && same(at.eps, derivative), "{text}: {at}");
            assert!(same(program.eval::<f64>(0.0, &[0.0], &[], &[]), 0.0), "{text}");
        }
    }

    fn value(text: &str) -> f64 {
        let resolve = |name: &str| match name {
            "x" => Some(Slot::State(0)),
            "k" => Some(Slot::Parameter(0)),
            "u" => Some(Slot::Input(0)),
            "t" => Some(Slot::Time),
            _ => None,
        };
        let program = Program::compile(&parse(text).unwrap(), &resolve).unwrap();
        program.eval(0.5, &[2.0], &[3.0], &[-1.0])
    }

    /// Sums and products longer than the depth limit are balanced trees of the same value
    /// (integers here, exact in any order), with every sign and inverse where it was
    /// written; chains within the limit keep their written order (the tree's shape).
    #[test]
    fn chains_longer_than_the_depth_limit_are_balanced() {
        let n = 1001;
        let alternating: String =
            (1..=n).map(|i| format!("{}{i}", if i % 2 == 0 { " - " } else { " + " })).collect();
        // 1 − 2 + 3 − … + 1001 = 501.
        assert_close(value(&alternating), 501.0, 0.0);
        assert_close(value(&format!("-x{}", " - x".repeat(n - 1))), -2.0 * n as f64, 0.0);
        assert_close(value(&format!("x{}", " - k + x".repeat(300))), 2.0 - 300.0, 0.0);
        // x·x/x·x/… with 300 of each: x = 2.
        assert_close(value(&format!("x{}", " * x / x".repeat(300))), 2.0, 0.0);
        assert_close(value(&format!("1{}", " / x".repeat(10))), 1.0 / 1024.0, 0.0);
        assert_close(value(&format!("1{}", " / k / x * k".repeat(100))), 0.5f64.powi(100), 0.0);
        // log₂ 1001 ≈ 10 levels: inside 185 parentheses it still parses.
        let wrapped = format!("{}x{}{}", "(".repeat(185), " + x".repeat(n - 1), ")".repeat(185));
        assert_close(value(&wrapped), 2.0 * n as f64, 0.0);
        // Within the limit, the written order: ((x + x) + x)…
        let Expr::Bin(Op::Add, left, _) = parse(&format!("x{}", " + x".repeat(199))).unwrap()
        else {
            panic!("a sum")
        };
        assert!(matches!(*left, Expr::Bin(Op::Add, ..)));
    }

    #[test]
    fn precedence_and_associativity() {
        assert_close(value("1 + 2 * 3"), 7.0, 0.0);
        assert_close(value("2 ^ 3 ^ 2"), 512.0, 0.0);
        assert_close(value("-x ^ 2"), -4.0, 0.0);
        assert_close(value("(-x) ^ 2"), 4.0, 0.0);
        assert_close(value("2 ^ -1"), 0.5, 0.0);
        assert_close(value("10 / 4 / 5"), 0.5, 0.0);
        assert_close(value("8 - 3 - 2"), 3.0, 0.0);
        assert_close(value("--x"), 2.0, 0.0);
        assert_close(value("1.5e3 + .5 + 2. + 1E-3"), 1502.501, 1e-15);
        assert_close(value("k * x^2 - u / t"), 14.0, 1e-15);
        assert_close(value("max(x, k) + min(x, k) + abs(u)"), 6.0, 0.0);
        assert_close(
            value("exp(log(x)) + sqrt(k^2) + tanh(0) + sin(0) + cos(0) + tan(0)"),
            6.0,
            1e-15,
        );
        assert_close(value("x ^ 0.5"), 2f64.sqrt(), 1e-15);
        assert_close(value("x ^ k"), 8.0, 1e-15);
    }

    #[test]
    fn errors_point_at_the_character() {
        let err = |text: &str| parse(text).unwrap_err();
        assert_eq!(err("1 +").position, 3);
        assert_eq!(err("1 + * 2").message, "expected a number, a name or `(`, found `*`");
        assert_eq!(err("(x + 1").message, "expected `)`, found the end");
        assert_eq!(err("x + 1)").message, "unexpected `)` after the expression");
        assert_eq!(err("x # 2").position, 2);
        assert!(err("foo(x)").message.starts_with("unknown function `foo`"));
        assert_eq!(err("min(x)").message, "min takes 2 argument(s), got 1");
        assert_eq!(err("   ").message, "empty expression");
        assert_eq!(err("1.2.3").message, "`1.2.3` is not a number");
        let resolve = |_: &str| None;
        let unknown = Program::compile(&parse("2 * kk").unwrap(), &resolve).unwrap_err();
        assert_eq!((unknown.position, unknown.message.as_str()), (4, "unknown name `kk`"));
    }

    #[test]
    fn expressions_beyond_the_slots_evaluate_recursively() {
        // Σ_{i=1}^{50} x^2 / i: 150 nodes, more than the 64 slots.
        let text: Vec<String> = (1..=50).map(|i| format!("x^2 / {i}")).collect();
        let harmonic: f64 = (1..=50).map(|i| 1.0 / i as f64).sum();
        assert_close(value(&text.join(" + ")), 4.0 * harmonic, 1e-14);
        let short: Vec<String> = (1..=10).map(|i| format!("x^2 / {i}")).collect();
        let h10: f64 = (1..=10).map(|i| 1.0 / i as f64).sum();
        assert_close(value(&short.join(" + ")), 4.0 * h10, 1e-14);
    }

    #[test]
    fn constants_are_folded() {
        let resolve = |_: &str| None;
        let program = Program::compile(&parse("2 * (3 + 4) - exp(0)").unwrap(), &resolve).unwrap();
        assert!(program.is_constant());
        assert_close(program.eval::<f64>(0.0, &[], &[], &[]), 13.0, 0.0);
    }
}
