//! A model file's document: tables, arrays, numbers, strings, booleans and expressions, each
//! key and value with its position. Read from TOML text ([`Document::parse`]) or built by
//! another program (the PEtab importer builds one from a problem's tables and SBML, its
//! expressions as trees), checked by the same reader ([`crate::ModelFile::from_document`]),
//! and written as TOML ([`Document::to_toml`]).
//!
//! A position is a byte offset into the text for a parsed document, and an index into the
//! document's [`origins`](Document::origins) for a built one: where in the files it was
//! made from each key and value was written.

use std::borrow::Cow;
use std::fmt::Write as _;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::error::ModelError;
use crate::expr::Expr;

/// A value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A number (a TOML integer or float).
    Number(f64),
    /// A string: a name, a path, a keyword, or an expression as text.
    String(String),
    /// An expression, built as a tree.
    Expr(Expr),
    /// true or false.
    Bool(bool),
    /// A list.
    Array(Vec<Node>),
    /// A table.
    Table(Table),
    /// A value of a kind the model file has no use for (a TOML date), by its kind's name.
    Other(&'static str),
}

/// A value and its position.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// The value.
    pub value: Value,
    /// Its position: a byte offset into the text, or an index into the origins.
    pub at: usize,
}

/// A key and its position.
#[derive(Clone, Debug, PartialEq)]
pub struct Key {
    /// The key.
    pub name: String,
    /// Its position.
    pub at: usize,
}

/// A table: its keys and values in the order written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    entries: Vec<(Key, Node)>,
}

impl Table {
    /// An empty table.
    pub fn new() -> Self {
        Self::default()
    }

    /// The value of `key`, if the table has it.
    pub fn get(&self, key: &str) -> Option<&Node> {
        self.entries.iter().find(|(k, _)| k.name == key).map(|(_, v)| v)
    }

    /// The value of `key`, to change it, if the table has it.
    pub fn get_mut(&mut self, key: &str) -> Option<&mut Node> {
        self.entries.iter_mut().find(|(k, _)| k.name == key).map(|(_, v)| v)
    }

    /// The keys and values, in order.
    pub fn iter(&self) -> impl Iterator<Item = (&Key, &Node)> {
        self.entries.iter().map(|(k, v)| (k, v))
    }

    /// Number of keys.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether it has no keys.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Appends `key = value`, the key at position `at`.
    pub fn insert(&mut self, key: impl Into<String>, at: usize, value: Node) {
        self.entries.push((Key { name: key.into(), at }, value));
    }

    /// Appends `key = value` with the key and the value at one position.
    pub fn push(&mut self, key: impl Into<String>, value: Value, at: usize) {
        self.insert(key, at, Node { value, at });
    }
}

impl Node {
    /// `value` at `at`.
    pub fn new(value: Value, at: usize) -> Self {
        Self { value, at }
    }
}

/// A document: its top-level table and what its positions refer to.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Document {
    /// The top-level table.
    pub root: Table,
    /// Empty for a document read from text (positions are byte offsets into it); for a
    /// built one, where each position was written, as an error there begins (its file, line
    /// and column, and a message put before the error's own).
    pub origins: Vec<ModelError>,
}

impl Document {
    /// A built document whose position 0 is `origin`: where a key or value was written when
    /// its builder gives no better place.
    pub fn built(origin: ModelError) -> Self {
        Self { root: Table::new(), origins: vec![origin] }
    }

    /// A new position of a built document: `origin`.
    pub fn origin(&mut self, origin: ModelError) -> usize {
        self.origins.push(origin);
        self.origins.len() - 1
    }

    /// Parses TOML text, each key and value at its byte offset; a syntax error is returned
    /// with its offset.
    pub fn parse(text: &str) -> Result<Self, (usize, String)> {
        let table = DeTable::parse(text).map_err(|e| {
            (e.span().map_or(0, |s| s.start), format!("TOML syntax error: {}", e.message().trim()))
        })?;
        Ok(Self { root: from_toml_table(table.get_ref()), origins: Vec::new() })
    }

    /// The document as TOML text: the top level's plain keys first, then each table as a
    /// `[section]` and each array of tables as `[[section]]` entries, deeper tables inline.
    /// Reading the text gives the same document, but for its positions and its expressions,
    /// which come back as strings of [`Expr::text`].
    pub fn to_toml(&self) -> String {
        let mut out = String::new();
        let sections = |v: &Value| match v {
            Value::Table(_) => true,
            Value::Array(items) => {
                !items.is_empty() && items.iter().all(|i| matches!(i.value, Value::Table(_)))
            }
            _ => false,
        };
        for (k, v) in self.root.iter().filter(|(_, v)| !sections(&v.value)) {
            let _ = writeln!(out, "{} = {}", key(&k.name), inline(&v.value));
        }
        for (k, v) in self.root.iter().filter(|(_, v)| sections(&v.value)) {
            match &v.value {
                Value::Table(t) => {
                    let _ = writeln!(out, "\n[{}]", key(&k.name));
                    for (k, v) in t.iter() {
                        let _ = writeln!(out, "{} = {}", key(&k.name), inline(&v.value));
                    }
                }
                Value::Array(items) => {
                    for item in items {
                        let _ = writeln!(out, "\n[[{}]]", key(&k.name));
                        if let Value::Table(t) = &item.value {
                            for (k, v) in t.iter() {
                                let _ = writeln!(out, "{} = {}", key(&k.name), inline(&v.value));
                            }
                        }
                    }
                }
                _ => unreachable!("sections are tables and arrays of tables"),
            }
        }
        out
    }
}

/// A key as TOML writes it: bare where it can be, quoted otherwise.
fn key(name: &str) -> Cow<'_, str> {
    let bare =
        !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare { Cow::Borrowed(name) } else { Cow::Owned(quoted(name)) }
}

/// A TOML basic string.
fn quoted(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A value written on one line.
fn inline(v: &Value) -> String {
    match v {
        Value::Number(x) => format!("{x:e}"),
        Value::String(s) => quoted(s),
        Value::Expr(e) => quoted(&e.text()),
        Value::Bool(b) => b.to_string(),
        Value::Array(items) => {
            let items: Vec<String> = items.iter().map(|i| inline(&i.value)).collect();
            format!("[{}]", items.join(", "))
        }
        Value::Table(t) if t.is_empty() => "{}".into(),
        Value::Table(t) => {
            let entries: Vec<String> =
                t.iter().map(|(k, v)| format!("{} = {}", key(&k.name), inline(&v.value))).collect();
            format!("{{ {} }}", entries.join(", "))
        }
        Value::Other(kind) => unreachable!("a {kind} is only read, never built"),
    }
}

fn from_toml_table(t: &DeTable<'_>) -> Table {
    let mut table = Table::new();
    for (k, v) in t.iter() {
        table.insert(k.get_ref().to_string(), k.span().start, from_toml(v));
    }
    table
}

fn from_toml(v: &Spanned<DeValue<'_>>) -> Node {
    let value = match v.get_ref() {
        DeValue::Integer(i) => {
            let digits: String = i.as_str().chars().filter(|c| *c != '_').collect();
            match i64::from_str_radix(&digits, i.radix()) {
                Ok(v) => Value::Number(v as f64),
                Err(_) => Value::Other("integer beyond 64 bits"),
            }
        }
        DeValue::Float(f) => {
            Value::Number(f.as_str().replace('_', "").parse::<f64>().unwrap_or(f64::NAN))
        }
        DeValue::String(s) => Value::String(s.to_string()),
        DeValue::Boolean(b) => Value::Bool(*b),
        DeValue::Datetime(_) => Value::Other("date"),
        DeValue::Array(items) => Value::Array(items.iter().map(from_toml).collect()),
        DeValue::Table(t) => Value::Table(from_toml_table(t)),
    };
    Node { value, at: v.span().start }
}
