//! Every mistake in a model file, with its exact message, line and column. These pin the
//! behaviour of `ModelFile::parse` section by section, including which of two mistakes
//! is reported first; and a file that uses every section, read value by value.

use std::path::Path;

use sysid_core::{Data, Problem, Unknown};
use sysid_model::expr::{MAX_DEPTH, Program, Slot, parse};
use sysid_model::{DataSpec, Model, ModelFile, RecordKind};
use sysid_ode::{Inputs, Integrator, Interpolation, Scheme};

/// The start of most cases: two states and a parameter.
const HEAD: &str = "states = [\"x\", \"y\"]\nparameters = [\"k\"]\n";
/// An equation for each state.
const EQ: &str = "[equations]\nx = \"-k * x\"\ny = \"k * x\"\n";
/// Both initial values known.
const INIT: &str = "[initial]\nx = 1.0\ny = 0.0\n";
/// A complete, valid model (11 lines), to which the cases append a section.
const OK: &str = "states = [\"x\", \"y\"]\nparameters = [\"k\"]\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n[unknowns]\nk = 0.5\n";

/// Checks that each model fails with exactly the expected `file:line:column: message`.
#[track_caller]
fn check(cases: &[(String, &str)]) {
    for (model, expected) in cases {
        match ModelFile::parse(model, Path::new("models/m.toml")) {
            Ok(_) => panic!("accepted:\n{model}"),
            Err(e) => assert_eq!(e.to_string(), *expected, "model:\n{model}"),
        }
    }
}

/// TOML syntax, unknown top-level keys (checked before anything else) and a missing `states`.
#[test]
fn toml_syntax_and_top_level_keys() {
    check(&[
        (
            String::from("states = [\"x\"\n"),
            "models/m.toml:1:14: TOML syntax error: unclosed array, expected `]`",
        ),
        (
            String::from("states = [\"x\"]\ncolour = \"red\"\n"),
            "models/m.toml:2:1: unknown key `colour` (keys: states, parameters, inputs, equations, initial, known, unknowns, outputs, data, experiments, integrator, events)",
        ),
        (
            String::from("parameters = [\"k\"]\n"),
            "models/m.toml: `states` is missing: list the state names",
        ),
        (
            String::from("colour = 1\nparameters = [\"k\"]\n"),
            "models/m.toml:1:1: unknown key `colour` (keys: states, parameters, inputs, equations, initial, known, unknowns, outputs, data, experiments, integrator, events)",
        ),
        (
            format!("{OK}[solver]\nmethod = \"x\"\n"),
            "models/m.toml:11:2: unknown key `solver` (keys: states, parameters, inputs, equations, initial, known, unknowns, outputs, data, experiments, integrator, events)",
        ),
    ]);
}

/// The name lists: shape, valid identifiers, reserved words, emptiness and uniqueness.
#[test]
fn state_parameter_and_input_names() {
    check(&[
        (
            String::from("states = \"x\"\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"),
            "models/m.toml:1:10: `states` must be a list of names, like [\"x\", \"y\"]",
        ),
        (
            String::from("states = [1]\n"),
            "models/m.toml:1:11: each entry of `states` must be a string",
        ),
        (
            String::from("states = [\"x\", \"1y\"]\n"),
            "models/m.toml:1:16: `1y` is not a valid name (letters, digits and _, not starting with a digit)",
        ),
        (
            String::from("states = [\"x\", \"exp\"]\n"),
            "models/m.toml:1:16: `exp` is reserved (the time or a function)",
        ),
        (
            String::from("states = [\"t\"]\n"),
            "models/m.toml:1:11: `t` is reserved (the time or a function)",
        ),
        (
            String::from("states = []\n"),
            "models/m.toml:1:10: `states` is empty: a model needs at least one state",
        ),
        (
            String::from("states = [\"α\", \"β γ\"]\n"),
            "models/m.toml:1:16: `β γ` is not a valid name (letters, digits and _, not starting with a digit)",
        ),
        (
            String::from(
                "states = [\"x\", \"y\"]\nparameters = \"k\"\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n",
            ),
            "models/m.toml:2:14: `parameters` must be a list of names, like [\"x\", \"y\"]",
        ),
        (
            String::from("states = [\"x\", \"x\"]\n"),
            "models/m.toml:1:16: the name `x` is used twice (as a state and as a state)",
        ),
        (
            String::from("states = [\"x\", \"y\"]\nparameters = [\"y\"]\n"),
            "models/m.toml:2:15: the name `y` is used twice (as a state and as a parameter)",
        ),
        (
            String::from("states = [\"x\"]\ninputs = [\"x\"]\n"),
            "models/m.toml:2:11: the name `x` is used twice (as a state and as an input)",
        ),
        (
            String::from("states = [\"x\"]\nparameters = [\"k\"]\ninputs = [\"k\"]\n"),
            "models/m.toml:3:11: the name `k` is used twice (as a parameter and as an input)",
        ),
    ]);
}

/// `inputs` as a list or a `{ names, mode }` table; `mode` is checked before stray keys.
#[test]
fn inputs() {
    check(&[
        (
            format!("{HEAD}inputs = 3\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"),
            "models/m.toml:3:10: `inputs` must be a list of names or a table {names, mode}",
        ),
        (
            format!("{HEAD}inputs = [\"u\", 2]\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"),
            "models/m.toml:3:16: each entry of `inputs` must be a string",
        ),
        (
            format!(
                "{HEAD}inputs = {{ mode = \"step\" }}\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"
            ),
            "models/m.toml:3:10: [inputs] needs `names = [...]`",
        ),
        (
            format!("{HEAD}[inputs]\nnames = \"u\"\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"),
            "models/m.toml:4:9: `inputs.names` must be a list of names, like [\"x\", \"y\"]",
        ),
        (
            format!(
                "{HEAD}[inputs]\nnames = [\"u\"]\nmode = \"ramp\"\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"
            ),
            "models/m.toml:5:8: inputs.mode must be \"linear\" or \"step\", got \"ramp\"",
        ),
        (
            format!(
                "{HEAD}[inputs]\nnames = [\"u\"]\nmode = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"
            ),
            "models/m.toml:5:8: inputs.mode must be a string",
        ),
        (
            format!(
                "{HEAD}[inputs]\nnames = [\"u\"]\nshape = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"
            ),
            "models/m.toml:5:1: unknown key `shape` in [inputs] (keys: names, mode)",
        ),
        (
            format!(
                "{HEAD}[inputs]\nshape = 1\nnames = [\"u\"]\nmode = \"ramp\"\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"
            ),
            "models/m.toml:6:8: inputs.mode must be \"linear\" or \"step\", got \"ramp\"",
        ),
        (
            format!("{HEAD}[inputs]\nshape = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"),
            "models/m.toml:3:1: [inputs] needs `names = [...]`",
        ),
    ]);
}

/// `[outputs]`: a table of valid, unique names whose expressions compile after the equations.
#[test]
fn outputs() {
    check(&[
        (
            format!(
                "{HEAD}outputs = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n[unknowns]\nk = 0.5\n"
            ),
            "models/m.toml:3:11: [outputs] must be a table",
        ),
        (
            format!("{OK}[outputs]\n\"1z\" = \"x\"\n"),
            "models/m.toml:12:1: `1z` is not a valid name (letters, digits and _, not starting with a digit)",
        ),
        (
            format!("{OK}[outputs]\ny = \"x\"\n"),
            "models/m.toml:12:1: the name `y` is used twice (as a state and as an output)",
        ),
        (
            format!("{OK}[outputs]\nz = \"x +\"\n"),
            "models/m.toml:12:9: output z: expected a number, a name or `(`, found the end",
        ),
        (
            format!("{OK}[outputs]\nz = \"x + q\"\n"),
            "models/m.toml:12:10: output z: unknown name `q` (names: x, y, k, t)",
        ),
        (format!("{OK}[outputs]\nz = 2\n"), "models/m.toml:12:5: output z must be a string"),
        (
            format!("{HEAD}[equations]\nx = \"-k * x\"\ny = \"k * q\"\n[outputs]\nz = \"x + q\"\n"),
            "models/m.toml:5:10: equation of y: unknown name `q` (names: x, y, k, t)",
        ),
        (
            format!("{HEAD}[outputs]\n\"1z\" = \"x\"\n"),
            "models/m.toml:4:1: `1z` is not a valid name (letters, digits and _, not starting with a digit)",
        ),
    ]);
}

/// `[equations]`: one compiled expression per state, errors at the expression's character.
#[test]
fn equations() {
    check(&[
        (
            HEAD.to_string(),
            "models/m.toml:1:10: [equations] is missing: give d(state)/dt for every state",
        ),
        (format!("{HEAD}\n\nequations = 1\n"), "models/m.toml:5:13: [equations] must be a table"),
        (
            format!("{HEAD}{EQ}z = \"1\"\n"),
            "models/m.toml:6:1: [equations]: `z` is not a state (states: x, y)",
        ),
        (
            format!("{HEAD}[equations]\nx = 1\ny = \"x\"\n"),
            "models/m.toml:4:5: equation of x must be a string",
        ),
        (
            format!("{HEAD}[equations]\nx = \"-k * \"\ny = \"x\"\n"),
            "models/m.toml:4:11: equation of x: expected a number, a name or `(`, found the end",
        ),
        (
            format!("{HEAD}[equations]\nx = \"-k * q\"\ny = \"x\"\n"),
            "models/m.toml:4:11: equation of x: unknown name `q` (names: x, y, k, t)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"\"\"-k * q\"\"\"\ny = \"x\"\n"),
            "models/m.toml:4:13: equation of x: unknown name `q` (names: x, y, k, t)",
        ),
        (
            format!("{HEAD}[equations]\nx = '-k ** x'\ny = \"x\"\n"),
            "models/m.toml:4:10: equation of x: expected a number, a name or `(`, found `*`",
        ),
        (
            format!("{HEAD}[equations]\nx = '''\n-k * x\n  + q'''\ny = \"x\"\n"),
            "models/m.toml:6:4: equation of x: unknown name `q` (names: x, y, k, t)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"α + β * q\"\ny = \"x\"\n"),
            "models/m.toml:4:6: equation of x: unknown name `α` (names: x, y, k, t)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"foo(x)\"\ny = \"x\"\n"),
            "models/m.toml:4:6: equation of x: unknown function `foo` (functions: exp, log, sqrt, sin, cos, tan, tanh, abs, min, max, if, lt, le, gt, ge, eq, ne, and, or, not)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"min(x)\"\ny = \"x\"\n"),
            "models/m.toml:4:6: equation of x: min takes 2 argument(s), got 1",
        ),
        (
            format!("{HEAD}[equations]\nx = \"x # 2\"\ny = \"x\"\n"),
            "models/m.toml:4:8: equation of x: unexpected character `#`",
        ),
        // Constant errors are named where they are written, not found by the integrator
        // as a state that "became non-finite at t = 0".
        (
            format!("{HEAD}[equations]\nx = \"-k * x / 0\"\ny = \"x\"\n"),
            "models/m.toml:4:13: equation of x: division by a constant zero: `(((-k) * x) / 0.0)`",
        ),
        (
            format!("{HEAD}[equations]\nx = \"-k * x + sqrt(-1)\"\ny = \"x\"\n"),
            "models/m.toml:4:15: equation of x: `sqrt((-1.0))` is not a finite number (it is NaN)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"-k * x * 1e309\"\ny = \"x\"\n"),
            "models/m.toml:4:15: equation of x: `1e309` is beyond the largest floating-point number (about 1.8e308)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"x + 1e200 * 1e200\"\ny = \"x\"\n"),
            "models/m.toml:4:16: equation of x: `(1e200 * 1e200)` is not a finite number (it is inf)",
        ),
        (
            format!("{HEAD}[equations]\nx = \"-k * x\"\n"),
            "models/m.toml:1:16: state `y` has no equation in [equations]",
        ),
        (
            format!("{HEAD}[equations]\n"),
            "models/m.toml:1:11: state `x` has no equation in [equations]",
        ),
        (
            String::from("states = [\"x\"]\ninputs = [\"u\"]\n[equations]\nx = \"q\"\n"),
            "models/m.toml:4:6: equation of x: unknown name `q` (names: x, u, t)",
        ),
    ]);
}

/// An expression nested deeper than [`MAX_DEPTH`] is refused where the limit is crossed:
/// parentheses, signs, calls and exponents at the innermost operand, a chain of operations
/// at the operator that makes it too deep.
#[test]
fn expressions_nested_too_deeply() {
    let deep = |expression: String| format!("{HEAD}[equations]\nx = \"{expression}\"\ny = \"x\"\n");
    let message = "equation of x: the expression nests more than 200 levels deep (parentheses, signs, function calls and operators)";
    check(&[
        // The expression starts at column 6; 201 parentheses put `x` at column 207.
        (
            deep(format!("{}x{}", "(".repeat(201), ")".repeat(201))),
            &format!("models/m.toml:4:207: {message}"),
        ),
        (deep(format!("{}x", "-".repeat(201))), &format!("models/m.toml:4:207: {message}")),
        (
            deep(format!("{}x{}", "sin(".repeat(201), ")".repeat(201))),
            &format!("models/m.toml:4:810: {message}"),
        ),
        (deep(format!("x{}", "^x".repeat(201))), &format!("models/m.toml:4:408: {message}")),
        // A chain longer than the limit is a balanced tree (crates/model/src/expr.rs), 8
        // levels for 202 terms: inside 193 calls it is 201 deep, at the outermost call.
        (
            deep(format!("{}x{}{}", "sin(".repeat(193), "+x".repeat(201), ")".repeat(193))),
            &format!("models/m.toml:4:6: {message}"),
        ),
        (deep(format!("{}x", "-(".repeat(201))), &format!("models/m.toml:4:207: {message}")),
    ]);
}

/// One expression of every shape exactly at the depth limit: parentheses, signs, calls of
/// one and of two arguments, exponents, sums, products, and parentheses around a chain.
fn at_the_depth_limit() -> Vec<String> {
    let n = MAX_DEPTH;
    vec![
        format!("{}x{}", "(".repeat(n), ")".repeat(n)),
        format!("{}x", "-".repeat(n)),
        format!("{}x{}", "sin(".repeat(n), ")".repeat(n)),
        format!("{}x{}", "max(y, ".repeat(n), ")".repeat(n)),
        format!("x{}", "^x".repeat(n)),
        format!("x{}", " + x".repeat(n)),
        format!("x{}", " * x".repeat(n)),
        format!("{}x{}{}", "(".repeat(n), " - y".repeat(n), ")".repeat(n)),
    ]
}

/// Every pass over an expression at the depth limit fits in the 2 MiB stack of a worker
/// thread (rayon's, where studies fit): parsing, printing, compiling with its constant folding,
/// evaluating (recursively, as the trees have more nodes than the evaluation's slots) in f64
/// and in the dual numbers of the explicit and the implicit integrators' sensitivities,
/// and dropping the tree.
#[test]
fn every_pass_at_the_depth_limit_fits_a_worker_threads_stack() {
    let passes = || {
        for expression in at_the_depth_limit() {
            assert!(!parse(&expression).unwrap().to_string().is_empty());
            let model = format!(
                "states = [\"x\", \"y\"]\nparameters = [\"k\"]\n[equations]\nx = \"{expression}\"\ny = \"-k * y\"\n[initial]\nx = 0.5\ny = 1.0\n[unknowns]\nk = 0.5\n"
            );
            let file = ModelFile::parse(&model, Path::new("deep.toml")).unwrap();
            assert!(!file.equations[0].is_constant(), "{expression}");
            let system = Model { file }.system(Inputs::default());
            let times = [0.01, 0.02, 0.03];
            let data =
                Data::discrete().series("x", &times, &[0.5; 3]).series("y", &times, &[1.0; 3]);
            for integrator in [Integrator::default(), Integrator::rodas4(1e-8, 1e-10)] {
                let problem = Problem::builder(system.clone())
                    .known("x", 0.5)
                    .known("y", 1.0)
                    .unknown("k", 0.5)
                    .data(data.clone())
                    .integrator(integrator)
                    .build()
                    .unwrap();
                let linearization = problem.linearize(&[0.5]).unwrap();
                let (cost, _) = problem.cost(&[0.5]).unwrap();
                assert!(cost.is_finite(), "{expression}: {linearization:?}");
            }
        }
    };
    std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(passes)
        .unwrap()
        .join()
        .expect("every pass at the depth limit within 2 MiB");
}

/// `[initial]` and `[known]`: finite numbers for states and parameters; `[initial]` is read first.
#[test]
fn initial_and_known() {
    check(&[
        (
            format!("{HEAD}initial = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n"),
            "models/m.toml:3:11: [initial] must be a table",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nz = 1\n"),
            "models/m.toml:7:1: [initial]: `z` is not a state (names: x, y)",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nk = 1\n"),
            "models/m.toml:7:1: [initial]: `k` is not a state (names: x, y)",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = \"one\"\n"),
            "models/m.toml:7:6: [initial] x: unknown name `one` (names: k)",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = inf\n"),
            "models/m.toml:7:5: [initial] x must be a finite number, got inf",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = -nan\n"),
            "models/m.toml:7:5: [initial] x must be a finite number, got NaN",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = 1e400\n"),
            "models/m.toml:7:5: [initial] x must be a finite number, got inf",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = 99999999999999999999\n"),
            "models/m.toml:7:5: [initial] x must be a number",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = true\n"),
            "models/m.toml:7:5: [initial] x must be a number",
        ),
        (
            format!("{HEAD}{EQ}[known]\nx = 1\n"),
            "models/m.toml:7:1: [known]: `x` is not a parameter (names: k)",
        ),
        (
            format!("{HEAD}{EQ}[known]\nk = \"a\"\n"),
            "models/m.toml:7:5: [known] k must be a number",
        ),
        (
            format!("{HEAD}{EQ}[known]\nz = 1\n[initial]\nq = 1\n"),
            "models/m.toml:9:1: [initial]: `q` is not a state (names: x, y)",
        ),
        (
            format!(
                "{HEAD}known = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n"
            ),
            "models/m.toml:3:9: [known] must be a table",
        ),
    ]);
}

/// `[unknowns]`: a number or a `{ guess, min, max, log }` table, each name given once.
#[test]
fn unknowns() {
    check(&[
        (
            format!(
                "{HEAD}unknowns = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n"
            ),
            "models/m.toml:3:12: [unknowns] must be a table",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nz = 1\n"),
            "models/m.toml:10:1: [unknowns]: `z` is used nowhere: it is no state or parameter, and no sigma, set, preequilibrate, initial or [initial] expression names it",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nx = 1\n"),
            "models/m.toml:10:1: `x` is given twice (in [initial] and in [unknowns])",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[known]\nk = 1\n[unknowns]\nk = 1\n"),
            "models/m.toml:12:1: `k` is given twice (in [known] and in [unknowns])",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = 1\nk2 = 2\n"),
            "models/m.toml:11:1: [unknowns]: `k2` is used nowhere: it is no state or parameter, and no sigma, set, preequilibrate, initial or [initial] expression names it",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ min = 0 }}\n"),
            "models/m.toml:10:5: [unknowns] k: an unknown needs `guess`",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns.k]\nmin = 0\n"),
            "models/m.toml:9:1: [unknowns] k: an unknown needs `guess`",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = \"a\" }}\n"),
            "models/m.toml:10:15: [unknowns] k.guess must be a number",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, min = \"a\" }}\n"),
            "models/m.toml:10:24: [unknowns] k.min must be a number",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, max = nan }}\n"),
            "models/m.toml:10:24: [unknowns] k.max must be a finite number, got NaN",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, log = 1 }}\n"),
            "models/m.toml:10:24: [unknowns] k.log must be true or false",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, scale = 1 }}\n"),
            "models/m.toml:10:18: [unknowns] k: unknown key `scale` (keys: guess, min, max, log, prior, initialization)",
        ),
        (
            format!(
                "{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, initialization = {{ distribution = \"beta\", a = 0, b = 1 }} }}\n"
            ),
            "models/m.toml:10:52: [unknowns] k.initialization.distribution: `beta` (distributions: uniform, normal, laplace)",
        ),
        (
            format!(
                "{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, initialization = {{ distribution = \"normal\", a = 0, b = -1 }} }}\n"
            ),
            "models/m.toml:10:73: [unknowns] k.initialization: a normal one needs b > 0, got a = 0, b = -1",
        ),
        (
            format!(
                "{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, initialization = {{ distribution = \"uniform\", a = 0 }} }}\n"
            ),
            "models/m.toml:10:35: [unknowns] k.initialization: an initialization needs `b`",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ scale = 1, guess = \"a\" }}\n"),
            "models/m.toml:10:26: [unknowns] k.guess must be a number",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = \"a\"\n"),
            "models/m.toml:10:5: [unknowns] k must be a number",
        ),
        (
            format!("{HEAD}{EQ}{INIT}[unknowns]\nk = [1]\n"),
            "models/m.toml:10:5: [unknowns] k must be a number",
        ),
    ]);
}

/// Every state and parameter is known or unknown; states are checked first.
#[test]
fn every_state_and_parameter_given() {
    check(&[
        (
            format!("{HEAD}{EQ}[initial]\nx = 1\n[unknowns]\nk = 0.5\n"),
            "models/m.toml:1:16: state `y` is neither in [initial] nor in [unknowns]",
        ),
        (
            format!("{HEAD}{EQ}{INIT}"),
            "models/m.toml:2:15: parameter `k` is neither in [known] nor in [unknowns]",
        ),
        (
            format!("{HEAD}{EQ}"),
            "models/m.toml:1:11: state `x` is neither in [initial] nor in [unknowns]",
        ),
        (
            format!("{HEAD}{EQ}[initial]\ny = 1\n"),
            "models/m.toml:1:11: state `x` is neither in [initial] nor in [unknowns]",
        ),
    ]);
}

/// `[data]` and `[data.weights]`, read after the names are complete.
#[test]
fn data() {
    check(&[
        (
            format!(
                "{HEAD}data = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n[unknowns]\nk = 0.5\n"
            ),
            "models/m.toml:3:8: [data] must be a table",
        ),
        (format!("{OK}[data]\nfile = 1\n"), "models/m.toml:12:8: [data] file must be a string"),
        (format!("{OK}[data]\nt0 = \"a\"\n"), "models/m.toml:12:6: [data] t0 must be a number"),
        (
            format!("{OK}[data]\nrecord = \"sampled\"\n"),
            "models/m.toml:12:10: [data] record must be \"discrete\" or \"continuous\", got \"sampled\"",
        ),
        (
            format!("{OK}[data]\nrecord = 1\n"),
            "models/m.toml:12:10: [data] record must be a string",
        ),
        (
            format!("{OK}[data]\nweights = 1\n"),
            "models/m.toml:12:11: [data.weights] must be a table",
        ),
        (
            format!("{OK}[data.weights]\nx = \"a\"\n"),
            "models/m.toml:12:5: [data.weights] x must be a number",
        ),
        (
            format!("{OK}[data.weights]\nx = 0\n"),
            "models/m.toml:12:5: [data.weights] x must be positive, got 0",
        ),
        (
            format!("{OK}[data.weights]\nx = -1.5\n"),
            "models/m.toml:12:5: [data.weights] x must be positive, got -1.5",
        ),
        (
            format!("{OK}[data]\nformat = \"csv\"\n"),
            "models/m.toml:12:1: unknown key `format` in [data] (keys: file, t0, record, weights)",
        ),
        (
            format!("{OK}[data]\nformat = \"csv\"\nt0 = \"a\"\n"),
            "models/m.toml:12:1: unknown key `format` in [data] (keys: file, t0, record, weights)",
        ),
        (
            format!("{HEAD}{EQ}[initial]\nx = 1.0\n[data]\nt0 = \"a\"\n[unknowns]\nk = 0.5\n"),
            "models/m.toml:1:16: state `y` is neither in [initial] nor in [unknowns]",
        ),
    ]);
}

/// Data before t0, where the initial values are given, are refused at the first such sample
/// (its cell in the data file), saying where t0 is set.
#[test]
fn data_before_t0() {
    let dir = std::env::temp_dir().join(format!("sysid-model-t0-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (model, data) = (dir.join("m.toml"), dir.join("d.csv"));
    let (m, d) = (model.display(), data.display());
    let problem = |data_table: &str, csv: &str| {
        std::fs::write(&model, format!("{OK}[data]\nfile = \"d.csv\"\n{data_table}")).unwrap();
        std::fs::write(&data, csv).unwrap();
        Model::load(&model).and_then(|model| model.problem(None)).map(|_| ())
    };
    let tail = "the time of the initial values: the data must start at t0 or later";
    let cases = [
        // t0 after all the data.
        (
            "t0 = 5\n",
            "t,y\n0,0.1\n1,0.3\n",
            format!("{d}:2:3: column `y`: a sample at t = 0 lies before t0 = 5 ({m}:13:6), {tail}"),
        ),
        // The first sample before t0, whichever its column.
        (
            "t0 = 1.5\n",
            "t,x,y\n0,,0.1\n1,0.5,0.3\n2,0.2,0.5\n",
            format!(
                "{d}:2:4: column `y`: a sample at t = 0 lies before t0 = 1.5 ({m}:13:6), {tail}"
            ),
        ),
        (
            "",
            "t, y\n-1, 0\n0, 0.1\n1, 0.3\n",
            format!(
                "{d}:2:5: column `y`: a sample at t = -1 lies before t0 = 0 (the default: {m} has no [data] t0), {tail}"
            ),
        ),
        // A continuous record spans every row.
        (
            "t0 = 0.5\nrecord = \"continuous\"\n",
            "t,y\n0,\n1,0.3\n2,0.5\n",
            format!(
                "{d}:2:1: column `t`: the continuous record at t = 0 lies before t0 = 0.5 ({m}:13:6), {tail}"
            ),
        ),
    ];
    for (data_table, csv, expected) in cases {
        assert_eq!(problem(data_table, csv).unwrap_err().to_string(), expected, "{csv}");
    }
    // A time far from 0 in exponent form (it was 309 digits).
    assert_eq!(
        problem("t0 = 1e308\n", "t,y\n0,0.1\n").unwrap_err().to_string(),
        format!("{d}:2:3: column `y`: a sample at t = 0 lies before t0 = 1e308 ({m}:13:6), {tail}")
    );
    // Discrete data from t0 on, a row before t0 without a measured value, are accepted.
    assert_eq!(problem("t0 = 0.5\n", "t,x,y\n0,,\n0.5,1,0\n1,0.6,0.4\n2,0.4,0.6\n"), Ok(()));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `[integrator]`: its keys, then the options' own validation located at the table.
#[test]
fn integrator() {
    check(&[
        (
            format!(
                "{HEAD}integrator = 1\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n[unknowns]\nk = 0.5\n"
            ),
            "models/m.toml:3:14: [integrator] must be a table",
        ),
        (
            format!("{OK}[integrator]\nmethod = \"euler\"\n"),
            "models/m.toml:12:10: [integrator] method must be \"dopri5\", \"dop853\", \"rk4\", \"rodas4\", \"rodas5p\", \"bdf\" or \"auto\", got \"euler\"",
        ),
        (
            format!("{OK}[integrator]\nmethod = 1\n"),
            "models/m.toml:12:10: [integrator] method must be a string",
        ),
        (
            format!("{OK}[integrator]\nrtol = \"a\"\n"),
            "models/m.toml:12:8: [integrator] rtol must be a number",
        ),
        (
            format!("{OK}[integrator]\natol = \"a\"\n"),
            "models/m.toml:12:8: [integrator] atol must be a number",
        ),
        (
            format!("{OK}[integrator]\nstep = \"a\"\n"),
            "models/m.toml:12:8: [integrator] step must be a number",
        ),
        (
            format!("{OK}[integrator]\nmax_steps = \"a\"\n"),
            "models/m.toml:12:13: [integrator] max_steps must be a number",
        ),
        (
            format!("{OK}[integrator]\nrtol = -1\n"),
            "models/m.toml:11:1: [integrator] rtol must be positive and below 1 (a relative error of 100 % or more controls nothing), got -1",
        ),
        (
            format!("{OK}[integrator]\natol = -1\n"),
            "models/m.toml:11:1: [integrator] atol must be a finite non-negative number, got -1",
        ),
        (
            format!("{OK}[integrator]\nmethod = \"rk4\"\n"),
            "models/m.toml:11:1: [integrator] step is needed by RK4, which has no error control",
        ),
        (
            format!("{OK}[integrator]\nmethod = \"auto\"\nstep = 0.1\n"),
            "models/m.toml:11:1: [integrator] step cannot be used with the automatic choice of scheme, which needs error control",
        ),
        (
            format!("{OK}[integrator]\nstep = 0\n"),
            "models/m.toml:11:1: [integrator] step must be positive, got 0",
        ),
        (
            format!("{OK}[integrator]\nmax_steps = 0\n"),
            "models/m.toml:11:1: [integrator] max_steps must be at least 1",
        ),
        (
            format!("{OK}[integrator]\nmax_steps = -5\n"),
            "models/m.toml:11:1: [integrator] max_steps must be at least 1",
        ),
        (
            format!("{OK}[integrator]\norder = 5\n"),
            "models/m.toml:12:1: unknown key `order` in [integrator] (keys: method, rtol, atol, step, max_steps)",
        ),
        (
            format!("{OK}[integrator]\norder = 5\nrtol = -1\n"),
            "models/m.toml:12:1: unknown key `order` in [integrator] (keys: method, rtol, atol, step, max_steps)",
        ),
        (
            format!(
                "{HEAD}integrator = {{ rtol = -1 }}\n[equations]\nx = \"-k * x\"\ny = \"k * x\"\n[initial]\nx = 1.0\ny = 0.0\n[unknowns]\nk = 0.5\n"
            ),
            "models/m.toml:3:14: [integrator] rtol must be positive and below 1 (a relative error of 100 % or more controls nothing), got -1",
        ),
        (
            format!("{OK}[integrator]\nrtol = -1\n[data]\nt0 = \"a\"\n"),
            "models/m.toml:14:6: [data] t0 must be a number",
        ),
    ]);
}

/// A model file with every section, keys out of order, and TOML's number forms.
const FULL: &str = r#"# every section
states = ["x", "y"]
parameters = ["k", "c"]
inputs = { names = ["u", "w"], mode = "step" }

[equations]
y = "k * x - c * y + w"
x = """-k * x + u^2 / (1 + t)"""

[outputs]
total = 'x + y'
ratio = "x / max(y, 1e-3)"

[known]
c = 0x10

[initial]
x = 1_000
y = 2.5e-1

[unknowns]
k = { log = true, guess = 0.5, min = 1e-3, max = 1_0 }

[data]
record = "continuous"
file = "sub/data.csv"
t0 = -1
[data.weights]
y = 4
total = 0.25

[integrator]
method = "rodas4"
rtol = 1e-6
atol = 1e-9
max_steps = 5000.9
"#;

/// A leading byte-order mark is skipped: the file reads as without it, and its errors are
/// located as without it.
#[test]
fn a_leading_byte_order_mark_is_skipped() {
    let with = ModelFile::parse(&format!("\u{feff}{FULL}"), Path::new("models/m.toml")).unwrap();
    let without = ModelFile::parse(FULL, Path::new("models/m.toml")).unwrap();
    assert_eq!(
        (with.states, with.equations, with.data),
        (without.states, without.equations, without.data)
    );
    check(&[(
        format!("\u{feff}{HEAD}[equations]\nx = \"-k * q\"\ny = \"x\"\n"),
        "models/m.toml:4:11: equation of x: unknown name `q` (names: x, y, k, t)",
    )]);
}

/// Every value of a file that uses every section is read as written.
#[test]
fn a_file_with_every_section_reads_every_value() {
    let file = ModelFile::parse(FULL, Path::new("models/m.toml")).unwrap();
    let at = |needle: &str| FULL.find(needle).unwrap();
    assert_eq!(
        (file.states, file.parameters),
        (vec!["x".into(), "y".into()], vec!["k".into(), "c".into()])
    );
    assert_eq!((file.inputs, file.input_mode), (vec!["u".into(), "w".into()], Interpolation::Step));
    let resolve = |name: &str| match name {
        "x" => Some(Slot::State(0)),
        "y" => Some(Slot::State(1)),
        "k" => Some(Slot::Parameter(0)),
        "c" => Some(Slot::Parameter(1)),
        "u" => Some(Slot::Input(0)),
        "w" => Some(Slot::Input(1)),
        "t" => Some(Slot::Time),
        _ => None,
    };
    let program = |text: &str| Program::compile(&parse(text).unwrap(), &resolve).unwrap();
    assert_eq!(file.equations, [program("-k * x + u^2 / (1 + t)"), program("k * x - c * y + w")]);
    let outputs: Vec<(String, Program)> =
        file.outputs.iter().map(|o| (o.name.clone(), o.value.clone())).collect();
    assert_eq!(
        outputs,
        [("total".into(), program("x + y")), ("ratio".into(), program("x / max(y, 1e-3)"))]
    );
    assert_eq!(file.known, [("x".into(), 1000.0), ("y".into(), 0.25), ("c".into(), 16.0)]);
    assert_eq!(file.unknowns, [Unknown::new("k", 0.5).min(1e-3).max(10.0).log()]);
    let data = DataSpec {
        file: Some("models/sub/data.csv".into()),
        t0: -1.0,
        t0_at: Some(at("t0 = -1") + 5),
        record: RecordKind::Continuous,
        weights: vec![("y".into(), 4.0, at("y = 4")), ("total".into(), 0.25, at("total = 0.25"))],
    };
    assert_eq!(file.data, data);
    let integrator = Integrator {
        scheme: Scheme::Rodas4,
        rtol: 1e-6,
        atol: 1e-9,
        max_steps: 5000,
        ..Integrator::default()
    };
    assert_eq!(file.integrator, integrator);
    assert_eq!(file.states_at, at("[\"x\", \"y\"]"));
}

/// Every adaptive `[integrator] method` reads as its scheme (`rk4` needs a `step`: the errors above).
#[test]
fn every_method_name_reads_as_its_scheme() {
    for (name, scheme) in [
        ("dopri5", Scheme::Dopri5),
        ("dop853", Scheme::Dop853),
        ("rodas4", Scheme::Rodas4),
        ("rodas5p", Scheme::Rodas5p),
        ("bdf", Scheme::Bdf),
        ("auto", Scheme::Auto),
    ] {
        let text = FULL.replace("method = \"rodas4\"", &format!("method = \"{name}\""));
        let file = ModelFile::parse(&text, Path::new("models/m.toml")).unwrap();
        assert_eq!(file.integrator.scheme, scheme, "{name}");
    }
}

/// A prior's distribution: normal by default, `"laplace"` with location `mean` and scale
/// `sd`; any other is refused at its value.
#[test]
fn a_prior_is_normal_or_laplace() {
    use sysid_core::{Prior, Transform};
    let prior = |spec: &str| {
        let text = format!("{HEAD}{EQ}{INIT}[unknowns]\nk = {{ guess = 1, prior = {spec} }}\n");
        ModelFile::parse(&text, Path::new("models/m.toml")).map(|f| f.unknowns[0].prior)
    };
    assert_eq!(
        prior("{ mean = 0.5, sd = 2, on = \"log\" }").unwrap(),
        Some(Prior::normal(0.5, 2.0, Transform::Log))
    );
    assert_eq!(
        prior("{ mean = 0, sd = 3, distribution = \"laplace\" }").unwrap(),
        Some(Prior::laplace(0.0, 3.0, Transform::Lin))
    );
    assert_eq!(
        prior("{ mean = 0, sd = 3, distribution = \"cauchy\" }").unwrap_err().to_string(),
        "models/m.toml:10:61: [unknowns] k.prior.distribution: `cauchy` (normal, laplace)"
    );
}

/// A model whose equations do not mention t and which has no inputs is autonomous, and its
/// Rosenbrock steps skip ∂f/∂t; t in an equation, or an input, makes it depend on time.
#[test]
fn autonomy_of_the_examples() {
    use sysid_ode::System;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    for (example, autonomous) in [("kinetics", true), ("boehm", false), ("short-period", false)] {
        let model = Model::load(&root.join(example).join("model.toml")).unwrap();
        let problem = model.problem(None).unwrap();
        assert_eq!(problem.system().autonomous(), autonomous, "{example}");
    }
}
