//! The SBML subset the benchmark problems use, read with roxmltree: compartments, species,
//! parameters, reactions with kinetic laws and local parameters, rate and assignment rules,
//! initial assignments, function definitions and events without delays, their MathML as
//! [`Math`]. Anything else that changes the dynamics (algebraic rules, delays, fast
//! reactions, rules on compartments) is refused naming the construct and the element's id;
//! the importer refuses the events it cannot write as switches in time.

use std::collections::HashMap;

use roxmltree::{Document, Node};
use sysid_model::ModelError;

use crate::math::{Math, Rel};

/// A species.
#[derive(Clone, Debug)]
pub struct Species {
    /// Its id.
    pub id: String,
    /// Its compartment's id.
    pub compartment: String,
    /// `initialConcentration` or `initialAmount`, as given.
    pub initial: Option<Initial>,
    /// `hasOnlySubstanceUnits`: its symbol is an amount, not a concentration.
    pub amount: bool,
    /// `boundaryCondition` or `constant`: reactions do not change it.
    pub fixed: bool,
}

/// A species' initial quantity as the SBML gives it.
#[derive(Clone, Copy, Debug)]
pub enum Initial {
    /// `initialConcentration`.
    Concentration(f64),
    /// `initialAmount`.
    Amount(f64),
}

/// A reaction: stoichiometries and its rate (an amount per time), local parameters
/// substituted.
#[derive(Clone, Debug)]
pub struct Reaction {
    /// Its id.
    pub id: String,
    /// (species, stoichiometry) consumed.
    pub reactants: Vec<(String, f64)>,
    /// (species, stoichiometry) produced.
    pub products: Vec<(String, f64)>,
    /// The kinetic law.
    pub rate: Math,
}

/// An event: when its trigger becomes true, each assignment sets its variable.
#[derive(Clone, Debug)]
pub struct Event {
    /// Its id.
    pub id: String,
    /// The trigger's condition.
    pub trigger: Math,
    /// Whether the trigger counts as true before the start, so that a trigger already true
    /// at the start does not fire (SBML Level 3's `initialValue`; Level 2's events behave
    /// as with `true`).
    pub initially_true: bool,
    /// (variable, value) of each event assignment.
    pub assignments: Vec<(String, Math)>,
    /// Line and column of the `<event>` element, for errors.
    pub at: (usize, usize),
}

/// An SBML model, read.
#[derive(Clone, Debug, Default)]
pub struct Sbml {
    /// (id, size) of each compartment (size 1 when not given).
    pub compartments: Vec<(String, f64)>,
    /// The compartments whose element gives no size (nor `volume`): taken as size 1.
    pub sizeless: Vec<String>,
    /// The species.
    pub species: Vec<Species>,
    /// (id, value) of each global parameter (NaN when not given).
    pub parameters: Vec<(String, f64)>,
    /// Initial assignments: (symbol, expression).
    pub initial_assignments: Vec<(String, Math)>,
    /// Assignment rules: (variable, expression), substituted wherever the variable is used.
    pub assignment_rules: Vec<(String, Math)>,
    /// Rate rules: (variable, its time derivative).
    pub rate_rules: Vec<(String, Math)>,
    /// The reactions.
    pub reactions: Vec<Reaction>,
    /// The events.
    pub events: Vec<Event>,
    /// Line and column of the element that declares each id (compartments, species,
    /// parameters, reactions, events, function definitions), for errors found later.
    pub positions: HashMap<String, (usize, usize)>,
}

struct Reader<'a> {
    doc: &'a Document<'a>,
    file: &'a str,
    functions: HashMap<String, (Vec<String>, Math)>,
    /// How deeply the MathML being read nests.
    depth: std::cell::Cell<usize>,
    /// Where each line of the text starts (a byte offset): positions are found by a binary
    /// search, not by counting from the start of the file for every element.
    line_starts: Vec<usize>,
}

/// How deeply MathML may nest: as deep as a model file's expressions, which a deeper one
/// could not be written as (and the reader's recursion stays within its stack).
pub const MAX_DEPTH: usize = sysid_model::expr::MAX_DEPTH;

impl Reader<'_> {
    fn err(&self, node: Node<'_, '_>, message: impl Into<String>) -> ModelError {
        let (line, column) = self.position(node);
        ModelError {
            file: self.file.to_string(),
            line: Some(line),
            column: Some(column),
            message: message.into(),
        }
    }

    /// The line and column where `node` starts.
    fn position(&self, node: Node<'_, '_>) -> (usize, usize) {
        let at = node.range().start;
        let line = self.line_starts.partition_point(|&start| start <= at);
        let start = self.line_starts[line - 1];
        let text = self.doc.input_text();
        (line, text.get(start..at).map_or(0, |s| s.chars().count()) + 1)
    }

    /// Refuses an id declared twice (SBML's ids are one namespace), and records where each
    /// is declared.
    fn declare(&self, node: Node<'_, '_>, kind: &str, sbml: &mut Sbml) -> Result<(), ModelError> {
        let id = id(node);
        let at = self.position(node);
        if let Some(&(line, column)) = sbml.positions.get(id) {
            return Err(self.err(
                node,
                format!("{kind} `{id}` is declared a second time (first at line {line}, column {column}): every id is declared once"),
            ));
        }
        sbml.positions.insert(id.to_string(), at);
        Ok(())
    }

    fn number(&self, node: Node<'_, '_>, attribute: &str) -> Result<Option<f64>, ModelError> {
        match node.attribute(attribute) {
            None => Ok(None),
            Some(s) => s.trim().parse::<f64>().map(Some).map_err(|_| {
                self.err(node, format!("`{attribute}` of `{}`: `{s}` is not a number", id(node)))
            }),
        }
    }

    fn flag(node: Node<'_, '_>, attribute: &str) -> bool {
        node.attribute(attribute).is_some_and(|v| v.trim() == "true" || v.trim() == "1")
    }

    /// The expression of a `<math>` element.
    fn math_of(&self, parent: Node<'_, '_>) -> Result<Math, ModelError> {
        let math = child(parent, "math")
            .ok_or_else(|| self.err(parent, format!("`{}` has no <math>", id(parent))))?;
        let body = elements(math).next().ok_or_else(|| self.err(math, "an empty <math>"))?;
        self.math(body)
    }

    fn math(&self, node: Node<'_, '_>) -> Result<Math, ModelError> {
        let depth = self.depth.get();
        if depth >= MAX_DEPTH {
            return Err(self.err(
                node,
                format!("the MathML nests more than {MAX_DEPTH} levels deep (<apply>, <piecewise>, <semantics>)"),
            ));
        }
        self.depth.set(depth + 1);
        let m = self.math_element(node);
        self.depth.set(depth);
        m
    }

    fn math_element(&self, node: Node<'_, '_>) -> Result<Math, ModelError> {
        let text = || node.text().unwrap_or_default().trim().to_string();
        Ok(match node.tag_name().name() {
            "ci" => Math::Name(text()),
            "cn" => self.cn(node)?,
            "csymbol" => {
                let url = node.attribute("definitionURL").unwrap_or_default();
                if url.ends_with("/time") {
                    Math::Time
                } else if url.ends_with("/avogadro") {
                    Math::Num(6.022_140_76e23)
                } else {
                    let what = url.rsplit('/').next().unwrap_or(url);
                    return Err(self.err(node, format!("`{what}` (csymbol) is not supported")));
                }
            }
            "true" => Math::Num(1.0),
            "false" => Math::Num(0.0),
            "pi" => Math::Num(std::f64::consts::PI),
            "exponentiale" => Math::Num(std::f64::consts::E),
            "semantics" => {
                let first =
                    elements(node).next().ok_or_else(|| self.err(node, "empty <semantics>"))?;
                self.math(first)?
            }
            "piecewise" => {
                let mut pieces = Vec::new();
                let mut otherwise = None;
                for part in elements(node) {
                    let args: Vec<Node<'_, '_>> = elements(part).collect();
                    match (part.tag_name().name(), args.as_slice()) {
                        ("piece", [value, condition]) => {
                            pieces.push((self.math(*value)?, self.math(*condition)?));
                        }
                        ("otherwise", [value]) => otherwise = Some(Box::new(self.math(*value)?)),
                        (other, _) => {
                            return Err(
                                self.err(part, format!("a malformed <{other}> in <piecewise>"))
                            );
                        }
                    }
                }
                if pieces.is_empty() && otherwise.is_none() {
                    return Err(self.err(node, "a <piecewise> with neither a piece nor otherwise"));
                }
                Math::Piecewise(pieces, otherwise)
            }
            "apply" => self.apply(node)?,
            other => return Err(self.err(node, format!("MathML <{other}> is not supported"))),
        })
    }

    fn cn(&self, node: Node<'_, '_>) -> Result<Math, ModelError> {
        let parts: Vec<String> = node
            .children()
            .filter(|n| n.is_text())
            .map(|n| n.text().unwrap_or_default().trim().to_string())
            .filter(|s| !s.is_empty())
            .collect();
        let parse = |s: &str| {
            s.parse::<f64>().map_err(|_| self.err(node, format!("<cn> `{s}` is not a number")))
        };
        let kind = node.attribute("type").unwrap_or("real");
        Ok(Math::Num(match (kind, parts.as_slice()) {
            ("e-notation", [mantissa, exponent]) => parse(&format!("{mantissa}e{exponent}"))?,
            ("rational", [n, d]) => parse(n)? / parse(d)?,
            ("real" | "integer" | "double", [one]) => parse(one)?,
            _ => return Err(self.err(node, format!("a <cn> of type `{kind}` that cannot be read"))),
        }))
    }

    fn apply(&self, node: Node<'_, '_>) -> Result<Math, ModelError> {
        let mut children = elements(node);
        let op = children.next().ok_or_else(|| self.err(node, "an empty <apply>"))?;
        let rest: Vec<Node<'_, '_>> = children.collect();
        // An <apply> around one expression and no operator is that expression, as libSBML
        // reads it (Beer's kinetic laws wrap a product in a second <apply>).
        if rest.is_empty() && matches!(op.tag_name().name(), "apply" | "cn" | "piecewise") {
            return self.math(op);
        }
        // Qualifiers (<degree>, <logbase>) apart from the arguments.
        let qualifier = |name: &str| -> Result<Option<Math>, ModelError> {
            match rest.iter().find(|n| n.tag_name().name() == name) {
                None => Ok(None),
                Some(q) => {
                    let inner =
                        elements(*q).next().ok_or_else(|| self.err(*q, "empty qualifier"))?;
                    Ok(Some(self.math(inner)?))
                }
            }
        };
        let args: Vec<Math> = rest
            .iter()
            .filter(|n| !matches!(n.tag_name().name(), "degree" | "logbase"))
            .map(|n| self.math(*n))
            .collect::<Result<_, _>>()?;
        let name = op.tag_name().name();
        let count = args.len();
        let arity = |n: usize| -> Result<(), ModelError> {
            match count == n {
                true => Ok(()),
                false => Err(self.err(op, format!("<{name}> with {count} arguments (needs {n})"))),
            }
        };
        let mut args = args;
        let one = |args: &mut Vec<Math>| Box::new(args.remove(0));
        Ok(match name {
            "plus" => match args.len() {
                0 => Math::Num(0.0),
                1 => args.remove(0),
                _ => Math::Add(args),
            },
            "times" => match args.len() {
                0 => Math::Num(1.0),
                1 => args.remove(0),
                _ => Math::Mul(args),
            },
            "minus" => match args.len() {
                1 => Math::Neg(one(&mut args)),
                _ => {
                    arity(2)?;
                    let a = one(&mut args);
                    Math::Sub(a, one(&mut args))
                }
            },
            "divide" => {
                arity(2)?;
                let a = one(&mut args);
                Math::Div(a, one(&mut args))
            }
            "power" => {
                arity(2)?;
                let a = one(&mut args);
                Math::Pow(a, one(&mut args))
            }
            "root" => {
                arity(1)?;
                match qualifier("degree")? {
                    None => Math::Call("sqrt", args),
                    Some(n) => Math::Pow(
                        one(&mut args),
                        Box::new(Math::Div(Box::new(Math::Num(1.0)), Box::new(n))),
                    ),
                }
            }
            "exp" | "abs" | "sin" | "cos" | "tan" | "tanh" => {
                arity(1)?;
                let f = crate::math::UNARY.iter().find(|f| **f == name).expect("listed");
                Math::Call(f, args)
            }
            "ln" => {
                arity(1)?;
                Math::Call("log", args)
            }
            "log" => {
                arity(1)?;
                let base = qualifier("logbase")?.unwrap_or(Math::Num(10.0));
                Math::Div(
                    Box::new(Math::Call("log", args)),
                    Box::new(Math::Call("log", vec![base])),
                )
            }
            "min" | "max" if args.len() >= 2 => {
                let f = if name == "min" { "min" } else { "max" };
                let mut it = args.into_iter();
                let first = it.next().expect("two");
                it.fold(first, |a, b| Math::Call(f, vec![a, b]))
            }
            "eq" | "neq" | "lt" | "leq" | "gt" | "geq" => {
                arity(2)?;
                let rel = match name {
                    "eq" => Rel::Eq,
                    "neq" => Rel::Ne,
                    "lt" => Rel::Lt,
                    "leq" => Rel::Le,
                    "gt" => Rel::Gt,
                    _ => Rel::Ge,
                };
                let a = one(&mut args);
                Math::Compare(rel, a, one(&mut args))
            }
            "and" => Math::And(args),
            "or" => Math::Or(args),
            "not" => {
                arity(1)?;
                Math::Not(one(&mut args))
            }
            "ci" => {
                let f = op.text().unwrap_or_default().trim();
                let (parameters, body) = self.functions.get(f).ok_or_else(|| {
                    self.err(op, format!("a call of `{f}`, which is no function definition"))
                })?;
                if parameters.len() != args.len() {
                    return Err(self.err(
                        op,
                        format!("`{f}` takes {} arguments, given {}", parameters.len(), args.len()),
                    ));
                }
                let measures: Vec<(usize, usize)> = args.iter().map(Math::measure).collect();
                let composed = body
                    .measure_with(&|n| parameters.iter().position(|p| p == n).map(|i| measures[i]));
                crate::math::check_composed(composed)
                    .map_err(|m| self.err(op, format!("this call of `{f}` {m}")))?;
                body.substitute(&|n| {
                    parameters.iter().position(|p| p == n).map(|i| args[i].clone())
                })
            }
            "csymbol" => {
                let url = op.attribute("definitionURL").unwrap_or_default();
                let what = url.rsplit('/').next().unwrap_or(url);
                return Err(self.err(op, format!("`{what}` (csymbol) is not supported")));
            }
            other => return Err(self.err(op, format!("MathML <{other}> is not supported"))),
        })
    }
}

fn elements<'a, 'b>(node: Node<'a, 'b>) -> impl Iterator<Item = Node<'a, 'b>> {
    node.children().filter(Node::is_element)
}

fn child<'a, 'b>(node: Node<'a, 'b>, name: &str) -> Option<Node<'a, 'b>> {
    elements(node).find(|n| n.tag_name().name() == name)
}

fn list<'a, 'b>(node: Node<'a, 'b>, name: &str) -> impl Iterator<Item = Node<'a, 'b>> {
    child(node, name).into_iter().flat_map(elements)
}

fn id<'a>(node: Node<'a, '_>) -> &'a str {
    node.attribute("id")
        .or_else(|| node.attribute("variable"))
        .or_else(|| node.attribute("symbol"))
        .unwrap_or("?")
}

/// The text of the SBML file at `path`: UTF-8, or ISO 8859-1 (Latin-1) where its XML
/// declaration says so. Any other byte that is not UTF-8 is refused at its line and column,
/// naming the byte.
pub fn read_text(path: &std::path::Path) -> Result<String, ModelError> {
    let file = path.display().to_string();
    let bytes =
        std::fs::read(path).map_err(|e| ModelError::file(&file, format!("cannot be read: {e}")))?;
    let error = match String::from_utf8(bytes) {
        Ok(text) => return Ok(text),
        Err(e) => e,
    };
    let bytes = error.as_bytes();
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(200)]).to_lowercase();
    // encoding = "…" in the declaration, spaces around `=` allowed.
    let declared = head
        .split_once("encoding")
        .and_then(|(_, rest)| rest.trim_start().strip_prefix('='))
        .map(|rest| rest.trim_start().trim_start_matches(['"', '\'']))
        .and_then(|rest| rest.split(['"', '\'']).next())
        .map(str::trim)
        .unwrap_or("");
    if matches!(declared, "iso-8859-1" | "iso8859-1" | "latin1" | "latin-1" | "l1") {
        // Latin-1 maps each byte to the code point of the same number.
        return Ok(bytes.iter().map(|&b| char::from(b)).collect());
    }
    let at = error.utf8_error().valid_up_to();
    let (line, column) = sysid_model::line_column(&String::from_utf8_lossy(&bytes[..at]), at);
    Err(ModelError {
        file,
        line: Some(line),
        column: Some(column),
        message: format!(
            "byte 0x{:02X} is not UTF-8, and the XML declaration does not name another encoding sysid reads ({}): save the file as UTF-8 (or declare encoding=\"ISO-8859-1\" if it is Latin-1)",
            bytes[at],
            if declared.is_empty() {
                "it names none".to_string()
            } else {
                format!("it says {declared}")
            }
        ),
    })
}

impl Sbml {
    /// Whether an event sets `id`.
    pub fn set_by_events(&self, id: &str) -> bool {
        self.events.iter().any(|e| e.assignments.iter().any(|a| a.0 == id))
    }

    /// Reads SBML text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, ModelError> {
        let options = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
        let doc = Document::parse_with_options(text, options).map_err(|e| {
            let pos = e.pos();
            ModelError {
                file: file.to_string(),
                line: Some(pos.row as usize),
                column: Some(pos.col as usize),
                message: format!("not valid XML: {e}"),
            }
        })?;
        let line_starts = std::iter::once(0)
            .chain(doc.input_text().match_indices('\n').map(|(i, _)| i + 1))
            .collect();
        let mut r = Reader {
            doc: &doc,
            file,
            functions: HashMap::new(),
            depth: Default::default(),
            line_starts,
        };
        let root = doc.root_element();
        let model =
            child(root, "model").ok_or_else(|| r.err(root, "no <model> in the SBML file"))?;
        if model.attribute("conversionFactor").is_some() {
            return Err(r.err(model, "conversion factors are not supported"));
        }
        let mut out = Sbml::default();
        // The names each piece of mathematics uses, where it is, and what it is: checked once
        // every id is known.
        let mut uses: Vec<(Vec<String>, Node<'_, '_>, String)> = Vec::new();
        // What rules and assignments set, where, and what sets it.
        let mut targets: Vec<(String, Node<'_, '_>, &str)> = Vec::new();
        for f in list(model, "listOfFunctionDefinitions") {
            let math = child(f, "math")
                .ok_or_else(|| r.err(f, format!("function `{}` has no <math>", id(f))))?;
            let lambda = child(math, "lambda")
                .ok_or_else(|| r.err(math, format!("function `{}` is not a <lambda>", id(f))))?;
            let mut parameters = Vec::new();
            let mut body = None;
            for part in elements(lambda) {
                match part.tag_name().name() {
                    "bvar" => {
                        let ci =
                            child(part, "ci").ok_or_else(|| r.err(part, "<bvar> without <ci>"))?;
                        parameters.push(ci.text().unwrap_or_default().trim().to_string());
                    }
                    _ => body = Some(r.math(part)?),
                }
            }
            let body =
                body.ok_or_else(|| r.err(lambda, format!("function `{}` has no body", id(f))))?;
            r.declare(f, "function definition", &mut out)?;
            r.functions.insert(id(f).to_string(), (parameters, body));
        }
        for c in list(model, "listOfCompartments") {
            r.declare(c, "compartment", &mut out)?;
            let size = r.number(c, "size")?.or(r.number(c, "volume")?);
            if size.is_none() {
                out.sizeless.push(id(c).to_string());
            }
            out.compartments.push((id(c).to_string(), size.unwrap_or(1.0)));
        }
        for s in list(model, "listOfSpecies") {
            r.declare(s, "species", &mut out)?;
            if s.attribute("conversionFactor").is_some() {
                return Err(
                    r.err(s, format!("species `{}`: conversion factors are not supported", id(s)))
                );
            }
            let initial =
                match (r.number(s, "initialConcentration")?, r.number(s, "initialAmount")?) {
                    (Some(c), _) => Some(Initial::Concentration(c)),
                    (None, Some(a)) => Some(Initial::Amount(a)),
                    (None, None) => None,
                };
            let compartment = s.attribute("compartment").unwrap_or_default().to_string();
            if !out.compartments.iter().any(|c| c.0 == compartment) {
                return Err(r.err(
                    s,
                    format!(
                        "species `{}` is in compartment `{compartment}`, which is not declared",
                        id(s)
                    ),
                ));
            }
            out.species.push(Species {
                id: id(s).to_string(),
                compartment,
                initial,
                amount: Reader::flag(s, "hasOnlySubstanceUnits"),
                fixed: Reader::flag(s, "boundaryCondition") || Reader::flag(s, "constant"),
            });
        }
        for p in list(model, "listOfParameters") {
            r.declare(p, "parameter", &mut out)?;
            out.parameters.push((id(p).to_string(), r.number(p, "value")?.unwrap_or(f64::NAN)));
        }
        for a in list(model, "listOfInitialAssignments") {
            targets.push((id(a).to_string(), a, "the initial assignment"));
            let math = r.math_of(a)?;
            uses.push((math.names(), a, format!("the initial assignment of `{}`", id(a))));
            out.initial_assignments.push((id(a).to_string(), math));
        }
        let compartment = |name: &str| out.compartments.iter().any(|c| c.0 == name);
        for rule in list(model, "listOfRules") {
            let variable = id(rule).to_string();
            let kind = rule.tag_name().name();
            if kind == "algebraicRule" {
                return Err(r.err(rule, "algebraic rules are not supported"));
            }
            if compartment(&variable) {
                return Err(r.err(
                    rule,
                    format!("rules on compartments are not supported (compartment `{variable}`)"),
                ));
            }
            targets.push((variable.clone(), rule, "the rule"));
            let math = r.math_of(rule)?;
            uses.push((math.names(), rule, format!("the {kind} of `{variable}`")));
            match kind {
                "assignmentRule" => out.assignment_rules.push((variable, math)),
                "rateRule" => out.rate_rules.push((variable, math)),
                other => return Err(r.err(rule, format!("<{other}> is not supported"))),
            }
        }
        for event in list(model, "listOfEvents") {
            let eid = id(event).to_string();
            if event.attribute("id").is_some() {
                r.declare(event, "event", &mut out)?;
            }
            if let Some(delay) = child(event, "delay") {
                return Err(r.err(delay, format!("event `{eid}`: delays are not supported")));
            }
            let trigger = child(event, "trigger")
                .ok_or_else(|| r.err(event, format!("event `{eid}` has no <trigger>")))?;
            let initially_true = trigger.attribute("initialValue").is_none_or(|v| {
                let v = v.trim();
                v == "true" || v == "1"
            });
            for a in list(event, "listOfEventAssignments") {
                targets.push((id(a).to_string(), a, "the event assignment"));
            }
            let assignments = list(event, "listOfEventAssignments")
                .map(|a| Ok((id(a).to_string(), r.math_of(a)?)))
                .collect::<Result<Vec<_>, ModelError>>()?;
            let (line, column) = r.position(event);
            let trigger = r.math_of(trigger)?;
            let names = assignments.iter().flat_map(|(_, m)| m.names()).chain(trigger.names());
            uses.push((names.collect(), event, format!("event `{eid}`")));
            out.events.push(Event {
                id: eid,
                trigger,
                initially_true,
                assignments,
                at: (line, column),
            });
        }
        if let Some(c) = list(model, "listOfConstraints").next() {
            return Err(r.err(c, "constraints are not supported"));
        }
        for reaction in list(model, "listOfReactions") {
            r.declare(reaction, "reaction", &mut out)?;
            let rid = id(reaction).to_string();
            if Reader::flag(reaction, "fast") {
                return Err(r.err(
                    reaction,
                    format!("fast reactions are not supported (reaction `{rid}`)"),
                ));
            }
            let references = |name: &str| -> Result<Vec<(String, f64)>, ModelError> {
                list(reaction, name)
                    .map(|s| {
                        if child(s, "stoichiometryMath").is_some() {
                            return Err(r.err(
                                s,
                                format!("reaction `{rid}`: stoichiometryMath is not supported"),
                            ));
                        }
                        let species = s.attribute("species").unwrap_or_default().to_string();
                        if !out.species.iter().any(|x| x.id == species) {
                            return Err(r.err(
                                s,
                                format!("reaction `{rid}` refers to species `{species}`, which is not declared"),
                            ));
                        }
                        Ok((species, r.number(s, "stoichiometry")?.unwrap_or(1.0)))
                    })
                    .collect()
            };
            let reactants = references("listOfReactants")?;
            let products = references("listOfProducts")?;
            let law = child(reaction, "kineticLaw")
                .ok_or_else(|| r.err(reaction, format!("reaction `{rid}` has no kinetic law")))?;
            let mut local = Vec::new();
            for list_name in ["listOfLocalParameters", "listOfParameters"] {
                for p in list(law, list_name) {
                    let value = r.number(p, "value")?.ok_or_else(|| {
                        r.err(
                            p,
                            format!("local parameter `{}` of reaction `{rid}` has no value", id(p)),
                        )
                    })?;
                    local.push((id(p).to_string(), value));
                }
            }
            let rate = r.math_of(law)?;
            let rate =
                rate.substitute(&|n| local.iter().find(|l| l.0 == n).map(|l| Math::Num(l.1)));
            uses.push((rate.names(), reaction, format!("the kinetic law of reaction `{rid}`")));
            out.reactions.push(Reaction { id: rid, reactants, products, rate });
        }
        for (target, node, what) in targets {
            let declared = out.species.iter().any(|x| x.id == target)
                || out.parameters.iter().any(|p| p.0 == target)
                || out.compartments.iter().any(|c| c.0 == target);
            if !declared {
                return Err(r.err(
                    node,
                    format!("{what} sets `{target}`, which is no declared compartment, species or parameter"),
                ));
            }
        }
        // Every name the mathematics uses is declared: a compartment, species or parameter.
        for (names, node, what) in uses {
            for name in names {
                let known = out.species.iter().any(|x| x.id == name)
                    || out.parameters.iter().any(|p| p.0 == name)
                    || out.compartments.iter().any(|c| c.0 == name);
                if known {
                    continue;
                }
                let message = match out.reactions.iter().any(|x| x.id == name) {
                    true => format!(
                        "{what} uses the rate of reaction `{name}` (its id as a symbol), which is not supported"
                    ),
                    false => format!(
                        "{what} uses `{name}`, which is no compartment, species or parameter of the model"
                    ),
                };
                return Err(r.err(node, message));
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODEL: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<sbml xmlns="http://www.sbml.org/sbml/level3/version1/core" level="3" version="1">
  <model id="m">
    <listOfFunctionDefinitions>
      <functionDefinition id="mm">
        <math xmlns="http://www.w3.org/1998/Math/MathML">
          <lambda><bvar><ci>v</ci></bvar><bvar><ci>s</ci></bvar>
            <apply><divide/><apply><times/><ci>v</ci><ci>s</ci></apply>
              <apply><plus/><cn>1</cn><ci>s</ci></apply></apply>
          </lambda>
        </math>
      </functionDefinition>
    </listOfFunctionDefinitions>
    <listOfCompartments><compartment id="c" size="2"/></listOfCompartments>
    <listOfSpecies><species id="A" compartment="c" initialConcentration="1.5"/></listOfSpecies>
    <listOfReactions>
      <reaction id="r">
        <listOfReactants><speciesReference species="A" stoichiometry="1"/></listOfReactants>
        <kineticLaw>
          <math xmlns="http://www.w3.org/1998/Math/MathML">
            <apply><ci>mm</ci><ci>k</ci><cn type="e-notation"> 2 <sep/> -3 </cn></apply>
          </math>
          <listOfLocalParameters><localParameter id="k" value="4"/></listOfLocalParameters>
        </kineticLaw>
      </reaction>
    </listOfReactions>
  </model>
</sbml>"#;

    #[test]
    fn function_definitions_are_inlined_and_local_parameters_substituted() {
        let m = Sbml::parse(MODEL, "m.xml").expect("reads");
        let rate = m.reactions[0].rate.render(&|n| n.to_string());
        assert_eq!(rate, "4 * 0.002 / (1 + 0.002)");
        assert_eq!(m.compartments, vec![("c".to_string(), 2.0)]);
    }

    /// An <apply> around one expression is that expression (Beer's kinetic laws); a
    /// piecewise without <otherwise> takes its last piece's value where no condition holds
    /// (Alkan's); one with neither is refused where it is.
    #[test]
    fn wrapped_applies_and_piecewise_without_otherwise() {
        let with_rate = |math: &str| {
            MODEL.replace(
                "<apply><ci>mm</ci><ci>k</ci><cn type=\"e-notation\"> 2 <sep/> -3 </cn></apply>",
                math,
            )
        };
        let rate = |math: &str| {
            let m = Sbml::parse(&with_rate(math), "m.xml").expect("reads");
            m.reactions[0].rate.render(&|n| n.to_string())
        };
        let wrapped = "<apply><apply><times/><ci>k</ci><ci>A</ci></apply></apply>";
        assert_eq!(rate(wrapped), "4 * A");
        let piece = |value: &str, rel: &str| {
            format!("<piece><cn>{value}</cn><apply><{rel}/><ci>A</ci><cn>0</cn></apply></piece>")
        };
        let pieces = format!("<piecewise>{}{}</piecewise>", piece("1", "gt"), piece("2", "leq"));
        assert_eq!(rate(&pieces), "if(gt(A, 0), 1, 2)");
        let otherwise = format!(
            "<piecewise>{}{}<otherwise><cn>3</cn></otherwise></piecewise>",
            piece("1", "gt"),
            piece("2", "leq")
        );
        assert_eq!(rate(&otherwise), "if(gt(A, 0), 1, if(le(A, 0), 2, 3))");
        let e = Sbml::parse(&with_rate("<piecewise></piecewise>"), "m.xml").unwrap_err();
        assert!(e.message.contains("a <piecewise> with neither a piece nor otherwise"), "{e}");
        assert_eq!(e.line, Some(21));
    }

    /// An event is read with its trigger and assignments; one without a trigger, or with a
    /// delay, is refused naming it, at its line.
    #[test]
    fn events_are_read_and_their_faults_located() {
        let with = |event: &str| {
            MODEL.replace(
                "</listOfReactions>",
                &format!("</listOfReactions><listOfEvents>{event}</listOfEvents>"),
            )
        };
        let math = |body: &str| {
            format!("<math xmlns=\"http://www.w3.org/1998/Math/MathML\">{body}</math>")
        };
        let assignment = format!(
            "<listOfEventAssignments><eventAssignment variable=\"A\">{}</eventAssignment></listOfEventAssignments>",
            math("<cn> 0 </cn>")
        );
        let trigger = |attributes: &str| {
            format!(
                "<trigger{attributes}>{}</trigger>",
                math(
                    "<apply><geq/><csymbol definitionURL=\"http://www.sbml.org/sbml/symbols/time\"> t </csymbol><cn> 2 </cn></apply>"
                )
            )
        };
        let m = Sbml::parse(
            &with(&format!("<event id=\"pulse\">{}{assignment}</event>", trigger(""))),
            "m.xml",
        )
        .expect("reads");
        let e = &m.events[0];
        assert_eq!((e.id.as_str(), e.initially_true), ("pulse", true));
        assert_eq!(e.trigger.render(&|n| n.to_string()), "ge(t, 2)");
        assert_eq!(e.assignments[0].0, "A");
        let m = Sbml::parse(
            &with(&format!(
                "<event id=\"pulse\">{}{assignment}</event>",
                trigger(" initialValue=\"false\"")
            )),
            "m.xml",
        )
        .expect("reads");
        assert!(!m.events[0].initially_true);
        for (event, message) in [
            ("<event id=\"pulse\"/>".to_string(), "event `pulse` has no <trigger>"),
            (
                format!(
                    "<event id=\"pulse\">{}<delay>{}</delay>{assignment}</event>",
                    trigger(""),
                    math("<cn> 1 </cn>")
                ),
                "event `pulse`: delays are not supported",
            ),
        ] {
            let e = Sbml::parse(&with(&event), "m.xml").unwrap_err();
            assert!(e.message.contains(message), "{e}");
            assert!(e.line.is_some());
        }
    }
}
