//! A built document (what the PEtab importer hands the model file's reader): its expressions
//! as trees and its positions as origins in other files. It reads as the TOML it prints, and
//! every error is located at the origin of the key or value it is about.

use std::path::Path;

use sysid_model::expr::{Expr, Op};
use sysid_model::file::document::{Document, Node, Table, Value};
use sysid_model::{ModelError, ModelFile};

/// An origin: a place in another file, with what to put before an error's message there.
fn origin(file: &str, line: usize, column: usize, prefix: &str) -> ModelError {
    ModelError { file: file.into(), line: Some(line), column: Some(column), message: prefix.into() }
}

fn name(n: &str) -> Expr {
    Expr::Name(n.into(), 0)
}

/// x' = −k·x, y' = k·x with x(0) = 1, y(0) = 0, k unknown in [0, 10], and the output
/// `total = x + y` with σ = 0.1: equations and output as trees, the rest as values; the
/// equation of y at `sbml:7:3` and the output at `obs.tsv:2:5`.
fn document(equation_of_y: Expr) -> Document {
    let mut doc = Document::built(ModelError::file("problem.yaml", "the importer: "));
    let y_at = doc.origin(origin("sbml", 7, 3, "reaction `r1`: "));
    let output_at = doc.origin(origin("obs.tsv", 2, 5, "column `observableFormula`: "));
    let names = |list: &[&str]| {
        Value::Array(list.iter().map(|n| Node::new(Value::String(n.to_string()), 0)).collect())
    };
    let mut equations = Table::new();
    let minus_kx =
        Expr::Neg(Box::new(Expr::Bin(Op::Mul, Box::new(name("k")), Box::new(name("x")))));
    equations.push("x", Value::Expr(minus_kx), 0);
    equations.push("y", Value::Expr(equation_of_y), y_at);
    let mut initial = Table::new();
    initial.push("x", Value::Number(1.0), 0);
    initial.push("y", Value::Number(0.0), 0);
    let mut k = Table::new();
    k.push("guess", Value::Number(0.5), 0);
    k.push("min", Value::Number(0.0), 0);
    k.push("max", Value::Number(10.0), 0);
    let mut unknowns = Table::new();
    unknowns.push("k", Value::Table(k), 0);
    let mut total = Table::new();
    let sum = Expr::Bin(Op::Add, Box::new(name("x")), Box::new(name("y")));
    total.push("value", Value::Expr(sum), output_at);
    total.push("sigma", Value::Number(0.1), output_at);
    let mut outputs = Table::new();
    outputs.push("total", Value::Table(total), output_at);
    let root = &mut doc.root;
    root.push("states", names(&["x", "y"]), 0);
    root.push("parameters", names(&["k"]), 0);
    root.push("equations", Value::Table(equations), 0);
    root.push("initial", Value::Table(initial), 0);
    root.push("unknowns", Value::Table(unknowns), 0);
    root.push("outputs", Value::Table(outputs), 0);
    doc
}

fn k_times_x() -> Expr {
    Expr::Bin(Op::Mul, Box::new(name("k")), Box::new(name("x")))
}

/// The document and the TOML it prints read as the same model file: the same expressions
/// (by their text), values, unknowns and outputs.
#[test]
fn a_built_document_reads_as_the_toml_it_prints() {
    let doc = document(k_times_x());
    let text = doc.to_toml();
    let path = Path::new("m.toml");
    let built = ModelFile::from_document(&doc, path).expect("a valid document");
    let parsed = ModelFile::parse(&text, path).unwrap_or_else(|e| panic!("{e}\n{text}"));
    assert_eq!(built.text, text);
    assert_eq!(built.states, parsed.states);
    assert_eq!(built.parameters, parsed.parameters);
    assert_eq!(built.known, parsed.known);
    assert_eq!(built.unknowns, parsed.unknowns);
    assert_eq!(built.outputs.len(), 1);
    // The same programs: evaluated at one point, to the bit.
    let (y, p) = ([0.3, 0.7], [2.5]);
    let at = |program: &sysid_model::expr::Program| program.eval::<f64>(0.0, &y, &p, &[]).to_bits();
    for (a, b) in built.equations.iter().zip(&parsed.equations) {
        assert_eq!(at(a), at(b));
    }
    let (a, b) = (&built.outputs[0].value, &parsed.outputs[0].value);
    assert_eq!(at(a), 1f64.to_bits());
    assert_eq!(at(a), at(b));
    // The text is the document's, section by section.
    assert!(text.starts_with("states = [\"x\", \"y\"]\nparameters = [\"k\"]\n"), "{text}");
    assert!(text.contains("\n[equations]\nx = \"-(k * x)\"\ny = \"k * x\"\n"), "{text}");
    assert!(text.contains("k = { guess = 5e-1, min = 0e0, max = 1e1 }"), "{text}");
    assert!(text.contains("total = { value = \"x + y\", sigma = 1e-1 }"), "{text}");
    // Parsed from its own text, a document prints that text again.
    let again = Document::parse(&text).expect("TOML");
    assert_eq!(again.to_toml(), text);
}

/// An error in a built document is located at its value's origin, that origin's message
/// before the reader's; a value without an origin of its own is at position 0's.
#[test]
fn an_error_in_a_built_document_is_at_its_origin() {
    let path = Path::new("m.toml");
    let unknown_name = Expr::Bin(Op::Mul, Box::new(name("kk")), Box::new(name("x")));
    let e = ModelFile::from_document(&document(unknown_name), path).expect_err("kk is no name");
    assert_eq!(
        e.to_string(),
        "sbml:7:3: reaction `r1`: equation of y: unknown name `kk` (names: x, y, k, t)"
    );
    let constant = Expr::Bin(Op::Div, Box::new(Expr::Num(1.0)), Box::new(Expr::Num(0.0)));
    let e = ModelFile::from_document(&document(constant), path).expect_err("1/0");
    assert!(e.to_string().starts_with("sbml:7:3: reaction `r1`: equation of y: "), "{e}");
    let mut doc = document(k_times_x());
    doc.root.push("stray", Value::Bool(true), 0);
    let e = ModelFile::from_document(&doc, path).expect_err("an unknown key");
    assert!(e.to_string().starts_with("problem.yaml: the importer: unknown key `stray`"), "{e}");
    let mut doc = document(k_times_x());
    let sigma_at = doc.origin(origin("obs.tsv", 2, 9, "column `noiseFormula`: "));
    if let Value::Table(outputs) = &mut doc.root.get_mut("outputs").expect("outputs").value
        && let Value::Table(total) = &mut outputs.get_mut("total").expect("total").value
    {
        total.get_mut("sigma").expect("sigma").at = sigma_at;
        total.get_mut("sigma").expect("sigma").value = Value::Number(-1.0);
    }
    let e = ModelFile::from_document(&doc, path).expect_err("σ < 0");
    assert_eq!(
        e.to_string(),
        "obs.tsv:2:9: column `noiseFormula`: [outputs] total.sigma must be positive, got -1"
    );
}
