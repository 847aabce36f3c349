//! Reading a document's values with their positions: numbers, strings, tables, names and
//! expressions, each failing with a message located in the file.

use std::path::Path;

use super::Expression;
use super::document::{Key, Node, Table, Value};
use crate::error::{ModelError, char_offset};
use crate::expr::{self, Program, Slot};

/// Reserved words: time and the function names.
const RESERVED: &[&str] =
    &["t", "exp", "log", "sqrt", "sin", "cos", "tan", "tanh", "abs", "min", "max"];

/// What the positions of a document refer to.
#[derive(Clone, Copy)]
pub(super) enum Positions<'a> {
    /// Byte offsets into the file's text.
    Text(&'a str),
    /// Indices into the origins of a built document: where each key and value was written.
    Origins(&'a [ModelError]),
}

impl Positions<'_> {
    /// An error at position `at` of the document called `file`.
    pub(crate) fn err(self, file: &str, at: usize, message: impl Into<String>) -> ModelError {
        match self {
            Positions::Text(text) => ModelError::at(file, text, at, message),
            Positions::Origins(origins) => match origins.get(at) {
                Some(o) => ModelError {
                    file: o.file.clone(),
                    line: o.line,
                    column: o.column,
                    message: format!("{}{}", o.message, message.into()),
                },
                None => ModelError::file(file, message),
            },
        }
    }
}

/// A key of a table and its value.
pub(super) type Entry<'a> = (&'a Key, &'a Node);

/// The document being read: its file's name and what its positions refer to, to locate
/// every error.
pub(super) struct Reader<'a> {
    file: String,
    positions: Positions<'a>,
}

impl<'a> Reader<'a> {
    /// A reader of a document at `path` whose positions are `positions`.
    pub(super) fn new(path: &Path, positions: Positions<'a>) -> Self {
        Self { file: path.display().to_string(), positions }
    }

    /// An error about the whole file, with no position.
    pub(super) fn file_err(&self, message: impl Into<String>) -> ModelError {
        ModelError::file(&self.file, message)
    }

    /// An error at a position of the document.
    pub(super) fn err(&self, at: usize, message: impl Into<String>) -> ModelError {
        self.positions.err(&self.file, at, message)
    }

    /// A finite number.
    pub(super) fn number(&self, value: &Node, what: &str) -> Result<f64, ModelError> {
        let Value::Number(v) = value.value else {
            return Err(self.err(value.at, format!("{what} must be a number")));
        };
        if !v.is_finite() {
            return Err(self.err(value.at, format!("{what} must be a finite number, got {v}")));
        }
        Ok(v)
    }

    /// A string.
    pub(super) fn string<'v>(&self, value: &'v Node, what: &str) -> Result<&'v str, ModelError> {
        match &value.value {
            Value::String(s) => Ok(s),
            _ => Err(self.err(value.at, format!("{what} must be a string"))),
        }
    }

    /// A table.
    pub(super) fn table<'v>(&self, value: &'v Node, what: &str) -> Result<&'v Table, ModelError> {
        match &value.value {
            Value::Table(t) => Ok(t),
            _ => Err(self.err(value.at, format!("{what} must be a table"))),
        }
    }

    /// A list of names: strings, each a valid identifier.
    pub(super) fn names(
        &self,
        value: &Node,
        what: &str,
    ) -> Result<Vec<(String, usize)>, ModelError> {
        let Value::Array(items) = &value.value else {
            return Err(self
                .err(value.at, format!("`{what}` must be a list of names, like [\"x\", \"y\"]")));
        };
        items
            .iter()
            .map(|item| {
                let name = self.string(item, &format!("each entry of `{what}`"))?;
                self.identifier(name, item.at)?;
                Ok((name.to_string(), item.at))
            })
            .collect()
    }

    /// Checks a name: letters, digits and _, not starting with a digit, not reserved.
    pub(super) fn identifier(&self, name: &str, at: usize) -> Result<(), ModelError> {
        let mut chars = name.chars();
        let valid = chars.next().is_some_and(|c| c.is_alphabetic() || c == '_')
            && chars.all(|c| c.is_alphanumeric() || c == '_');
        if !valid {
            return Err(self.err(at, format!("`{name}` is not a valid name (letters, digits and _, not starting with a digit)")));
        }
        if RESERVED.contains(&name) {
            return Err(self.err(at, format!("`{name}` is reserved (the time or a function)")));
        }
        Ok(())
    }

    /// Compiles an expression with the names it uses, locating its errors in the file.
    pub(super) fn expression_with_names(
        &self,
        value: &Node,
        what: &str,
        resolve: &dyn Fn(&str) -> Option<Slot>,
        names: &str,
    ) -> Result<Expression, ModelError> {
        let parsed = self.parsed(value, what, names)?;
        let program = Program::compile(&parsed, resolve)
            .map_err(|e| self.expression_err(value, what, names, e))?;
        let text = match &value.value {
            Value::String(text) => text.clone(),
            _ => parsed.text(),
        };
        let bare = match &parsed {
            expr::Expr::Name(name, _) => Some(name.clone()),
            _ => None,
        };
        Ok(Expression { uses: parsed.names(), text, program, at: value.at, bare })
    }

    /// Compiles an expression, locating its errors in the file.
    pub(super) fn expression(
        &self,
        value: &Node,
        what: &str,
        resolve: &dyn Fn(&str) -> Option<Slot>,
        names: &str,
    ) -> Result<Program, ModelError> {
        self.compiled(value, what, resolve, names, Ok)
    }

    /// Compiles an event's trigger, a comparison `lt(a, b)`, `le`, `gt` or `ge`, as its
    /// condition: a − b for lt and le, b − a for gt and ge, which falls through zero where
    /// the trigger turns true.
    pub(super) fn trigger(
        &self,
        value: &Node,
        what: &str,
        resolve: &dyn Fn(&str) -> Option<Slot>,
        names: &str,
    ) -> Result<Program, ModelError> {
        use expr::{Expr, Func, Op};
        self.compiled(value, what, resolve, names, |parsed| match parsed {
            Expr::Call(f @ (Func::Lt | Func::Le | Func::Gt | Func::Ge), mut args, _)
                if args.len() == 2 =>
            {
                let (b, a) = (Box::new(args.remove(1)), Box::new(args.remove(0)));
                Ok(match f {
                    Func::Lt | Func::Le => Expr::Bin(Op::Sub, a, b),
                    _ => Expr::Bin(Op::Sub, b, a),
                })
            }
            _ => Err(format!(
                "{what} must be a comparison, lt(a, b), le(a, b), gt(a, b) or ge(a, b): the event fires where it turns true"
            )),
        })
    }

    /// The expression a value holds, a string parsed or a tree as built, rewritten by
    /// `rewrite` (an error there is located at the value) and compiled, locating its errors
    /// in the file.
    fn compiled(
        &self,
        value: &Node,
        what: &str,
        resolve: &dyn Fn(&str) -> Option<Slot>,
        names: &str,
        rewrite: impl FnOnce(expr::Expr) -> Result<expr::Expr, String>,
    ) -> Result<Program, ModelError> {
        let parsed = self.parsed(value, what, names)?;
        let parsed = rewrite(parsed).map_err(|m| self.err(value.at, m))?;
        Program::compile(&parsed, resolve).map_err(|e| self.expression_err(value, what, names, e))
    }

    /// The expression of a value: a string parsed, or a built tree.
    fn parsed(&self, value: &Node, what: &str, names: &str) -> Result<expr::Expr, ModelError> {
        match &value.value {
            Value::Expr(e) => match e.check() {
                Ok(()) => Ok(e.clone()),
                Err(error) => Err(self.expression_err(value, what, names, error)),
            },
            Value::String(text) => {
                expr::parse(text).map_err(|e| self.expression_err(value, what, names, e))
            }
            _ => Err(self.err(value.at, format!("{what} must be a string"))),
        }
    }

    /// The error `e` of the expression `value` holds: at its character in a string of the
    /// text, at the value's origin in a built document.
    fn expression_err(
        &self,
        value: &Node,
        what: &str,
        names: &str,
        e: expr::ExprError,
    ) -> ModelError {
        let mut message = format!("{what}: {}", e.message);
        if e.message.starts_with("unknown name") {
            message += &format!(" (names: {names})");
        }
        match (self.positions, &value.value) {
            (Positions::Text(text), Value::String(_)) => {
                let start = value.at;
                let quote =
                    if text[start..].starts_with("\"\"\"") || text[start..].starts_with("'''") {
                        3
                    } else {
                        1
                    };
                self.err(char_offset(text, start + quote, e.position), message)
            }
            _ => self.err(value.at, message),
        }
    }
}
