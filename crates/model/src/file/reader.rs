//! Reading TOML values with their positions: numbers, strings, tables, names and
//! expressions, each failing with a message located in the file.

use std::path::Path;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::Expression;
use crate::error::{ModelError, char_offset};
use crate::expr::{self, Program, Slot};

/// Reserved words: time and the function names.
const RESERVED: &[&str] =
    &["t", "exp", "log", "sqrt", "sin", "cos", "tan", "tanh", "abs", "min", "max"];

/// The file being read: its name and text, to locate every error.
pub(super) struct Reader<'a> {
    file: String,
    text: &'a str,
}

/// A key of a table and its value.
pub(super) type Entry<'a, 'i> = (&'a Spanned<std::borrow::Cow<'i, str>>, &'a Spanned<DeValue<'i>>);

impl<'a> Reader<'a> {
    /// A reader of `text`, naming it after `path` in errors.
    pub(super) fn new(path: &Path, text: &'a str) -> Self {
        Self { file: path.display().to_string(), text }
    }

    /// Parses the text as TOML, keeping every key's and value's position.
    pub(super) fn document(&self) -> Result<Spanned<DeTable<'a>>, ModelError> {
        DeTable::parse(self.text).map_err(|e| {
            let at = e.span().map_or(0, |s| s.start);
            self.err(at, format!("TOML syntax error: {}", e.message().trim()))
        })
    }

    /// An error about the whole file, with no position.
    pub(super) fn file_err(&self, message: impl Into<String>) -> ModelError {
        ModelError::file(&self.file, message)
    }

    /// An error at a byte offset of the file.
    pub(super) fn err(&self, offset: usize, message: impl Into<String>) -> ModelError {
        ModelError::at(&self.file, self.text, offset, message)
    }

    /// A finite number (TOML integer or float).
    pub(super) fn number(
        &self,
        value: &Spanned<DeValue<'_>>,
        what: &str,
    ) -> Result<f64, ModelError> {
        let at = value.span().start;
        let v = match value.get_ref() {
            DeValue::Integer(i) => {
                let digits: String = i.as_str().chars().filter(|c| *c != '_').collect();
                i64::from_str_radix(&digits, i.radix()).map(|v| v as f64).ok()
            }
            DeValue::Float(f) => f.as_str().replace('_', "").parse::<f64>().ok(),
            _ => None,
        };
        let v = v.ok_or_else(|| self.err(at, format!("{what} must be a number")))?;
        if !v.is_finite() {
            return Err(self.err(at, format!("{what} must be a finite number, got {v}")));
        }
        Ok(v)
    }

    /// A string.
    pub(super) fn string<'v>(
        &self,
        value: &'v Spanned<DeValue<'_>>,
        what: &str,
    ) -> Result<&'v str, ModelError> {
        match value.get_ref() {
            DeValue::String(s) => Ok(s),
            _ => Err(self.err(value.span().start, format!("{what} must be a string"))),
        }
    }

    /// A table.
    pub(super) fn table<'v, 'i>(
        &self,
        value: &'v Spanned<DeValue<'i>>,
        what: &str,
    ) -> Result<&'v DeTable<'i>, ModelError> {
        match value.get_ref() {
            DeValue::Table(t) => Ok(t),
            _ => Err(self.err(value.span().start, format!("{what} must be a table"))),
        }
    }

    /// A list of names: strings, each a valid identifier.
    pub(super) fn names(
        &self,
        value: &Spanned<DeValue<'_>>,
        what: &str,
    ) -> Result<Vec<(String, usize)>, ModelError> {
        let DeValue::Array(items) = value.get_ref() else {
            return Err(self.err(
                value.span().start,
                format!("`{what}` must be a list of names, like [\"x\", \"y\"]"),
            ));
        };
        items
            .iter()
            .map(|item| {
                let name = self.string(item, &format!("each entry of `{what}`"))?;
                self.identifier(name, item.span().start)?;
                Ok((name.to_string(), item.span().start))
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

    /// Compiles an expression string with the names it uses, locating its errors in the
    /// file.
    pub(super) fn expression_with_names(
        &self,
        value: &Spanned<DeValue<'_>>,
        what: &str,
        resolve: &dyn Fn(&str) -> Option<Slot>,
        names: &str,
    ) -> Result<Expression, ModelError> {
        let program = self.expression(value, what, resolve, names)?;
        let text = self.string(value, what)?.to_string();
        let parsed = expr::parse(&text).expect("compiled above");
        let bare = match &parsed {
            expr::Expr::Name(name, _) => Some(name.clone()),
            _ => None,
        };
        Ok(Expression { uses: parsed.names(), text, program, at: value.span().start, bare })
    }

    /// Compiles an expression string, locating its errors in the file.
    pub(super) fn expression(
        &self,
        value: &Spanned<DeValue<'_>>,
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
        value: &Spanned<DeValue<'_>>,
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

    /// Parses an expression string, rewrites it by `rewrite` (an error there is located at
    /// the string) and compiles it, locating its errors in the file.
    fn compiled(
        &self,
        value: &Spanned<DeValue<'_>>,
        what: &str,
        resolve: &dyn Fn(&str) -> Option<Slot>,
        names: &str,
        rewrite: impl FnOnce(expr::Expr) -> Result<expr::Expr, String>,
    ) -> Result<Program, ModelError> {
        let text = self.string(value, what)?;
        let start = value.span().start;
        let quote =
            if self.text[start..].starts_with("\"\"\"") || self.text[start..].starts_with("'''") {
                3
            } else {
                1
            };
        let locate = |e: expr::ExprError| {
            let mut message = format!("{what}: {}", e.message);
            if e.message.starts_with("unknown name") {
                message += &format!(" (names: {names})");
            }
            self.err(char_offset(self.text, start + quote, e.position), message)
        };
        let parsed = expr::parse(text).map_err(locate)?;
        let parsed = rewrite(parsed).map_err(|m| self.err(start, m))?;
        Program::compile(&parsed, resolve).map_err(locate)
    }
}
