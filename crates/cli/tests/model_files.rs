//! Model files from the command line: the workflow, and one clear line (file, line, column
//! or column name), exit code 2, no panic and no partial output for every mistake.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sysid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sysid")).args(args).output().expect("the binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8(bytes.to_vec()).expect("utf-8 output")
}

/// A fresh directory with a model file and a data file.
struct Case {
    dir: PathBuf,
}

impl Case {
    fn new(tag: &str, model: &str, data: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("sysid-model-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("model.toml"), model).unwrap();
        std::fs::write(dir.join("data.csv"), data).unwrap();
        Self { dir }
    }
    fn model(&self) -> String {
        self.dir.join("model.toml").display().to_string()
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

impl Drop for Case {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

const DECAY: &str = r#"states = ["x"]
parameters = ["k"]
[equations]
x = "-k * x"
[initial]
x = 2.0
[unknowns]
k = 0.5
[data]
file = "data.csv"
"#;

const DECAY_DATA: &str = "t,x\n0,2\n1,0.9\n2,0.4\n3,0.18\n";

/// Runs `fit --model` and checks the error: exit 2, nothing on stdout, one line on stderr
/// that contains `needle`.
#[track_caller]
fn bad(tag: &str, model: &str, data: &str, needle: &str) {
    let case = Case::new(tag, model, data);
    let out = sysid(&["fit", "--model", &case.model()]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{tag}: {stderr}");
    assert!(out.stdout.is_empty(), "{tag}: stdout {}", text(&out.stdout));
    assert_eq!(stderr.trim_end().lines().count(), 1, "{tag}: {stderr}");
    assert!(stderr.contains(needle), "{tag}: `{needle}` not in: {stderr}");
    assert!(!stderr.contains("panicked"), "{tag}: {stderr}");
}

#[test]
fn the_workflow_fits_simulates_and_predicts() {
    let case = Case::new("workflow", DECAY, DECAY_DATA);
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let k = json["estimates"]["k"].as_f64().unwrap();
    assert!((k - 0.8).abs() < 0.02, "k = {k}");
    assert!(json["std_errors"]["k"].as_f64().unwrap() > 0.0);

    let sim = case.path("sim.csv");
    let out = sysid(&[
        "simulate",
        "--model",
        &case.model(),
        "--times",
        "0:2:0.5",
        "--set",
        "k=0.8",
        "--out",
        sim.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let lines: Vec<String> =
        std::fs::read_to_string(&sim).unwrap().lines().map(String::from).collect();
    assert_eq!(lines[0], "t,x");
    assert_eq!(lines.len(), 6);
    let x2: f64 = lines[5].split(',').nth(1).unwrap().parse().unwrap();
    assert!((x2 - 2.0 * (-1.6f64).exp()).abs() < 1e-7, "{x2}");
    // The integrator's options hold for one simulation as for a fit: the classical
    // Runge–Kutta step of 0.5 multiplies x by R(hλ) = 1 + z + z²/2 + z³/6 + z⁴/24, z = −0.4,
    // at each of the four steps to t = 2.
    let simulate = |extra: &[&str]| {
        let base = ["simulate", "--model", &case.model(), "--times", "0:2:0.5", "--set", "k=0.8"];
        sysid(&[&base[..], extra].concat())
    };
    let out = simulate(&["--integrator", "rk4", "--fixed-step", "0.5"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let last = text(&out.stdout).lines().last().unwrap().to_string();
    let x2: f64 = last.split(',').nth(1).unwrap().parse().unwrap();
    let z: f64 = -0.4;
    let r = 1.0 + z + z * z / 2.0 + z.powi(3) / 6.0 + z.powi(4) / 24.0;
    assert!((x2 - 2.0 * r.powi(4)).abs() <= 1e-15, "{x2} vs {}", 2.0 * r.powi(4));
    let out = simulate(&["--max-steps", "1"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("too many steps: 1 steps"), "{}", text(&out.stderr));

    let pred = case.path("pred.csv");
    let out = sysid(&[
        "predict",
        "--model",
        &case.model(),
        "--until",
        "6",
        "--step",
        "1",
        "--out",
        pred.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let lines: Vec<String> =
        std::fs::read_to_string(&pred).unwrap().lines().map(String::from).collect();
    assert_eq!(lines[0], "t,x,x_lower,x_upper");
    assert_eq!(lines.len(), 8);
    let row: Vec<f64> = lines[7].split(',').map(|v| v.parse().unwrap()).collect();
    assert!((row[0] - 6.0).abs() < 1e-12, "{row:?}");
    assert!(row[2] < row[1] && row[1] < row[3], "band {row:?}");
}

#[test]
fn a_byte_order_mark_at_the_start_of_a_file_is_skipped() {
    // As Excel ("CSV UTF-8") and Notepad write them.
    let case = Case::new("bom", &format!("\u{feff}{DECAY}"), &format!("\u{feff}{DECAY_DATA}"));
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let k = json["estimates"]["k"].as_f64().unwrap();
    assert!((k - 0.8).abs() < 0.02, "k = {k}");
    // Errors are located as without the mark.
    bad(
        "bom-cell",
        &format!("\u{feff}{DECAY}"),
        "\u{feff}t,x\n0,2\n1,abc\n2,0.4\n",
        "data.csv:3:3: column `x`: `abc` is not a number",
    );
    bad(
        "bom-time",
        DECAY,
        "\u{feff}x\n2\n0.9\n",
        "data.csv:1: the first column must be the time, named `t` or `time`; found `x`",
    );
}

/// The header is read as the table reads it: R's write.csv quotes every name (`"t","x"`), and
/// the quoted time column was refused as `"t"`; an empty file says so.
#[test]
fn a_quoted_header_is_its_names() {
    for (tag, data) in [
        ("quoted", "\"t\",\"x\"\n0,2\n1,0.9\n2,0.4\n3,0.18\n"),
        ("quoted-bom", "\u{feff}\"time\",x\n0,2\n1,0.9\n2,0.4\n3,0.18\n"),
    ] {
        let case = Case::new(tag, DECAY, data);
        let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
        assert_eq!(out.status.code(), Some(0), "{tag}: {}", text(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let k = json["estimates"]["k"].as_f64().unwrap();
        assert!((k - 0.8).abs() < 0.02, "{tag}: k = {k}");
    }
    bad(
        "quoted-x",
        DECAY,
        "\"x\",\"t\"\n2,0\n",
        "data.csv:1: the first column must be the time, named `t` or `time`; found `x`",
    );
    bad("empty", DECAY, "", "data.csv:1: the file is empty: its first row must name the columns");
    // Relative weights all far below 1 underflow ε: 1e-320 alone was reported an exact fit.
    let tiny = DECAY.to_string() + "[data.weights]\nx = 1e-320\n";
    bad(
        "tiny-weights",
        &tiny,
        DECAY_DATA,
        "model.toml:12:1: [data.weights]: the largest weight, 1e-320, is below 1e-300",
    );
    bad("blank", DECAY, "\n\n", "data.csv:1: the file is empty");
}

/// A noise scale is σ: a negative guess was fitted as |σ| and reported converged at −1, its
/// interval reversed; fixed or started there it is refused too.
#[test]
fn a_noise_scale_must_be_positive() {
    let model =
        DECAY.replace("[initial]", "[outputs]\ny = { value = \"x\", sigma = \"sd\" }\n[initial]");
    let data = "t,y\n0,2\n1,0.9\n2,0.4\n3,0.18\n";
    let scale =
        |guess: &str| model.replace("k = 0.5\n", &format!("k = 0.5\nsd = {{ guess = {guess} }}\n"));
    let needle = "unknown `sd`: a noise scale is a σ: it must not be negative, and finite, got ";
    // At the unknown's key, as the bounds' errors (which named the file alone).
    bad("scale-negative", &scale("-1"), data, &format!("model.toml:11:1: {needle}-1"));
    let reversed = DECAY.replace("k = 0.5", "k = { guess = 0.5, min = 1.0, max = 0.1 }");
    bad(
        "reversed",
        &reversed,
        DECAY_DATA,
        "model.toml:8:1: unknown `k`: min 1 is not below max 0.1",
    );
    // 0 makes the residuals infinite, named at the start (not as an integration's failure).
    bad(
        "scale-zero",
        &scale("0"),
        data,
        "the starting guess cannot be used (k = 0.5): the residual of the observable `y`",
    );
    let case = Case::new("scale-fixed", &scale("1"), data);
    for flag in ["--fix", "--start"] {
        let out = sysid(&["fit", "--model", &case.model(), flag, "sd=-2"]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag}: {stderr}");
        assert!(stderr.contains(needle), "{flag}: {stderr}");
    }
    // evaluate's --set too (its NLL took ln(−1) and blamed a residual).
    for v in ["sd=-1", "sd=0"] {
        let out = sysid(&["evaluate", "--model", &case.model(), "--set", v]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{v}: {stderr}");
        assert!(stderr.contains("--set sd: a noise scale is a σ: it must be positive"), "{stderr}");
    }
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    // The scale alone free: its standard error sd/√(2N) in the JSON as in the table (the
    // JSON's was null).
    let out = sysid(&["fit", "--model", &case.model(), "--fix", "k=0.8", "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let sd = json["estimates"]["sd"].as_f64().unwrap();
    let se = json["std_errors"]["sd"].as_f64().unwrap_or_else(|| panic!("{json}"));
    assert!((se - sd / 8f64.sqrt()).abs() <= 1e-12 * sd, "{se} against {sd}/√8");
    let [lo, hi] = [0, 1].map(|i| json["intervals"]["sd"][i].as_f64().unwrap());
    assert!(lo < sd && sd < hi, "[{lo}, {hi}] around {sd}");
}

#[test]
fn a_file_that_cannot_be_read_says_why_once() {
    // The system's reason appears once, after the path: the CLI prints the whole error
    // chain, so an error that also kept the reason as its source would repeat it.
    let case = Case::new("unreadable", DECAY, DECAY_DATA);
    let dir = case.dir.display().to_string();
    let missing = case.path("missing.toml").display().to_string();
    let model = case.model();
    for (args, path) in [
        (vec!["fit", "--model", &dir], &dir),
        (vec!["fit", "--model", &missing], &missing),
        (vec!["compare", "--model", &model, "--data", &dir], &dir),
        (vec!["predict", "--model", &missing, "--until", "5"], &missing),
        (vec!["simulate", "--model", &dir, "--times", "0:1:1"], &dir),
    ] {
        let out = sysid(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.starts_with(&format!("error: {path}: ")), "{args:?}: {stderr}");
        assert_eq!(stderr.matches("(os error").count(), 1, "{args:?}: {stderr}");
    }
    // A data file that cannot be read says what named it: the model file's key, or --data
    // (it said only the data file's path).
    let nowhere = case.path("nowhere.csv").display().to_string();
    let unnamed = DECAY.replace("data.csv", "nowhere.csv");
    let elsewhere = Case::new("unreadable-data", &unnamed, DECAY_DATA);
    let model_path = elsewhere.model();
    for (args, named) in [
        (vec!["fit", "--model", &model_path], format!("that `[data] file` in {model_path} names")),
        (
            vec!["fit", "--model", &model, "--data", &nowhere],
            "given by --data (in Python, data=)".to_string(),
        ),
    ] {
        let out = sysid(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.trim_end().ends_with(&format!("the data file {named}")),
            "{args:?}: {stderr}"
        );
    }
}

#[test]
fn toml_syntax_error() {
    bad(
        "toml",
        "states = [\"x\"\nparameters = [\"k\"]\n",
        DECAY_DATA,
        "model.toml:2:1: TOML syntax error",
    );
}

#[test]
fn unknown_identifier_in_an_equation() {
    let model = DECAY.replace("x = \"-k * x\"", "x = \"-kk * x\"");
    bad(
        "ident",
        &model,
        DECAY_DATA,
        "model.toml:4:7: equation of x: unknown name `kk` (names: x, k, t)",
    );
}

#[test]
fn syntax_error_in_an_expression() {
    let model = DECAY.replace("x = \"-k * x\"", "x = \"-k * * x\"");
    bad(
        "syntax",
        &model,
        DECAY_DATA,
        "model.toml:4:11: equation of x: expected a number, a name or `(`, found `*`",
    );
}

#[test]
fn state_without_an_equation() {
    let model = DECAY
        .replace("states = [\"x\"]", "states = [\"x\", \"y\"]")
        .replace("x = 2.0", "x = 2.0\ny = 0.0");
    bad("noeq", &model, DECAY_DATA, "model.toml:1:16: state `y` has no equation in [equations]");
}

#[test]
fn name_used_twice() {
    let model = DECAY.replace("parameters = [\"k\"]", "parameters = [\"k\", \"x\"]");
    bad(
        "twice",
        &model,
        DECAY_DATA,
        "model.toml:2:20: the name `x` is used twice (as a state and as a parameter)",
    );
}

#[test]
fn neither_known_nor_unknown() {
    let model = DECAY.replace("[unknowns]\nk = 0.5\n", "");
    bad(
        "unspecified",
        &model,
        DECAY_DATA,
        "model.toml:2:15: parameter `k` is neither in [known] nor in [unknowns]",
    );
}

#[test]
fn data_column_that_names_nothing() {
    bad(
        "column",
        DECAY,
        "t,x,zz\n0,2,1\n1,0.9,1\n",
        "data.csv:1: column `zz` names nothing in the model (states: x; outputs: none; inputs: none)",
    );
}

#[test]
fn missing_time_column() {
    bad(
        "time",
        DECAY,
        "x\n2\n0.9\n",
        "data.csv:1: the first column must be the time, named `t` or `time`; found `x`",
    );
}

#[test]
fn non_increasing_or_duplicate_times() {
    bad(
        "dup",
        DECAY,
        "t,x\n0,2\n1,0.9\n1,0.4\n",
        "data.csv:4:1: column `t`: time 1 is repeated (previous 1)",
    );
    bad(
        "back",
        DECAY,
        "t,x\n0,2\n2,0.9\n1,0.4\n",
        "data.csv:4:1: column `t`: time 1 goes back (previous 2)",
    );
}

#[test]
fn non_numeric_cell() {
    bad(
        "cell",
        DECAY,
        "t,x\n0,2\n1,abc\n2,0.4\n",
        "data.csv:3:3: column `x`: `abc` is not a number",
    );
}

#[test]
fn nan_or_infinite_values() {
    bad(
        "nan",
        DECAY,
        "t,x\n0,2\n1,NaN\n2,0.4\n",
        "data.csv:3:3: column `x`: `NaN` is not a finite number",
    );
    bad(
        "inf",
        DECAY,
        "t,x\n0,2\n1,inf\n2,0.4\n",
        "data.csv:3:3: column `x`: `inf` is not a finite number",
    );
    let model = DECAY.replace("x = 2.0", "x = nan");
    bad(
        "nanmodel",
        &model,
        DECAY_DATA,
        "model.toml:6:5: [initial] x must be a finite number, got NaN",
    );
}

/// Fewer data than unknowns is a problem like any other (the collection's Chen: 120 data, 155
/// unknowns): one datum x(1) = 2 for x(0) and k is fitted exactly, on the curve x₀e^{−k} = 2,
/// and the fit names the combination the datum cannot see.
#[test]
fn fewer_data_than_unknowns_are_fitted_and_the_unseen_combination_named() {
    let model = DECAY.replace("[initial]\nx = 2.0\n", "").replace("k = 0.5", "k = 0.5\nx = 1.0");
    let case = Case::new("few", &model, "t,x\n1,2\n");
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let (k, x0) =
        (json["estimates"]["k"].as_f64().unwrap(), json["estimates"]["x"].as_f64().unwrap());
    assert!((x0 * (-k).exp() - 2.0).abs() <= 1e-6, "x(1) = {}", x0 * (-k).exp());
    assert_eq!(json["dof"], 0);
    let out = sysid(&["fit", "--model", &case.model()]);
    let stdout = text(&out.stdout);
    assert!(stdout.contains("the data cannot identify k, x here (condition inf)"), "{stdout}");
}

#[test]
fn unknowns_the_data_cannot_identify() {
    let model = DECAY
        .replace("parameters = [\"k\"]", "parameters = [\"a\", \"b\"]")
        .replace("-k * x", "-(a + b) * x")
        .replace("k = 0.5", "a = 0.3\nb = 0.3");
    // Goodman's step is regularised where the data do not see a direction: the fit reaches
    // the valley a + b = const and names the combination; Gauss–Newton refuses the start.
    let case = Case::new("singular", &model, DECAY_DATA);
    let out = sysid(&["fit", "--model", &case.model()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(
        stdout
            .contains("the data cannot identify a, b here (condition inf): the combination a − b"),
        "{stdout}"
    );
    let out = sysid(&["fit", "--model", &case.model(), "--method", "gauss-newton"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("the data cannot identify a, b at the starting guess (singular normal matrix, condition inf; the combination"),
        "{stderr}"
    );
}

#[test]
fn an_expression_ten_thousand_deep_is_refused_not_a_stack_overflow() {
    let message = "equation of x: the expression nests more than 200 levels deep (parentheses, signs, function calls and operators)";
    // The expression starts at column 6 after `-k * `: the 202nd open level, at
    // character 206, is refused.
    let parens = format!("-k * {}x{}", "(".repeat(10_000), ")".repeat(10_000));
    let minuses = format!("-k * {}x", "-".repeat(10_000));
    for (tag, equation) in [("deep-parens", parens), ("deep-minuses", minuses)] {
        let model = DECAY.replace("-k * x", &equation);
        bad(tag, &model, DECAY_DATA, &format!("model.toml:4:212: {message}"));
    }
}

#[test]
fn an_expression_at_the_depth_limit_fits_and_studies_on_worker_threads() {
    // −k·x at the limit twice over: x inside 200 parentheses, and a chain of 198 zero terms
    // after it (200 operations deep).
    let equation =
        format!("-k * {}x{}{}", "(".repeat(200), ")".repeat(200), " + 0 * x".repeat(198));
    let case = Case::new("deep-limit", &DECAY.replace("-k * x", &equation), DECAY_DATA);
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let k = json["estimates"]["k"].as_f64().unwrap();
    assert!((k - 0.8).abs() < 0.02, "k = {k}");
    // A study fits its trials on rayon's worker threads (2 MiB stacks).
    let dir = case.path("study");
    let out = sysid(&[
        "study",
        "--model",
        &case.model(),
        "--trials",
        "4",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

#[test]
fn data_before_t0_are_refused_at_the_first_sample() {
    // t0 after all the data: integrated backward, the decay grew until the data could not
    // identify k. Refused at the first sample, saying where t0 is set.
    let model = DECAY.replace("file = \"data.csv\"", "file = \"data.csv\"\nt0 = 5");
    let message = "data.csv:2:3: column `x`: a sample at t = 0 lies before t0 = 5 (";
    bad("t0-after", &model, DECAY_DATA, message);
    let message =
        "model.toml:11:6), the time of the initial values: the data must start at t0 or later";
    bad("t0-after-line", &model, DECAY_DATA, message);
}

#[test]
fn a_model_that_blows_up() {
    let model = DECAY.replace("-k * x", "k * x^2");
    bad(
        "blowup",
        &model,
        DECAY_DATA,
        "the model cannot be integrated from the starting guess (k = 0.5): the solution blows up: state x reaches",
    );
}

/// Errors found at run time, past the file's reading, begin with the model file: which of a
/// user's files could not be integrated (they had said only "the model cannot be integrated").
#[test]
fn run_time_errors_name_the_model_file() {
    let case = Case::new("run-time", &DECAY.replace("-k * x", "k * x^2"), DECAY_DATA);
    let model = case.model();
    let starts = ["fit", "--model", &model, "--starts", "2", "--starts-without-guess"];
    let cannot =
        "the model cannot be integrated from the starting guess (k = 0.5): the solution blows up";
    for (args, message) in [
        (vec!["fit", "--model", &model], cannot),
        (starts.to_vec(), "every start fails; the best: the model cannot be integrated"),
        (vec!["profile", "--model", &model], cannot),
        (vec!["predict", "--model", &model, "--until", "5"], cannot),
        (vec!["evaluate", "--model", &model], "the NLL cannot be evaluated at this point"),
    ] {
        let out = sysid(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.starts_with(&format!("error: {model}: {message}")), "{args:?}: {stderr}");
    }
    // x′ = k x fits k ≈ 0.5 and grows past f64 long before t = 2000: the prediction, after
    // the fit, says what it was asked and of which file.
    let growth = Case::new(
        "run-time-growth",
        &DECAY.replace("-k * x", "k * x"),
        "t,x\n0,2\n1,3.3\n2,5.4\n3,9\n",
    );
    let model = growth.model();
    let out = sysid(&["predict", "--model", &model, "--until", "2000"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let message =
        format!("error: {model}: the fitted model cannot be integrated to --until 2000: ");
    assert!(stderr.starts_with(&message), "{stderr}");
    assert!(out.stdout.is_empty(), "{}", text(&out.stdout));
}

/// x′ = k x² from x(0) = 0.1 blows up at t = 20 for the guess k = 0.5, after the data end;
/// from the datum x(5) = 2, multiple shooting's node for its second interval, it blows up at
/// t = 6. Multiple shooting says where it started, not "from the starting guess", which
/// integrates.
#[test]
fn multiple_shooting_names_its_own_start() {
    let model = DECAY.replace("-k * x", "k * x^2").replace("x = 2.0", "x = 0.1");
    let data: String = std::iter::once("t,x".to_string())
        .chain((0..=15).map(|t| format!("{t},{}", if t < 5 { 0.1 } else { 2.0 })))
        .collect::<Vec<_>>()
        .join("\n");
    let case = Case::new("ms-start", &model, &data);
    let out = sysid(&["fit", "--model", &case.model(), "--method", "multiple-shooting"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("from multiple shooting's starting nodes"), "{stderr}");
    assert!(stderr.contains("the solution blows up"), "{stderr}");
    let out = sysid(&["fit", "--model", &case.model(), "--method", "goodman-halving"]);
    assert!(!text(&out.stderr).contains("cannot be integrated from"), "{}", text(&out.stderr));
}

#[test]
fn failures_leave_no_partial_output_file() {
    let case = Case::new("partial", DECAY, "t,x\n0,2\n1,abc\n");
    let out_file = case.path("out.csv");
    for args in [
        vec![
            "predict",
            "--model",
            &case.model(),
            "--until",
            "5",
            "--out",
            out_file.to_str().unwrap(),
        ],
        vec![
            "simulate",
            "--model",
            &case.model(),
            "--times",
            "0:1:x",
            "--out",
            out_file.to_str().unwrap(),
        ],
    ] {
        let out = sysid(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out.stderr));
        assert!(
            !out_file.exists() && !Path::new(&format!("{}.partial", out_file.display())).exists()
        );
    }
}

#[test]
fn examples_fit_with_every_method() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    for example in ["falling-body", "kinetics", "short-period"] {
        let model = root.join(example).join("model.toml");
        let out = sysid(&["compare", "--model", model.to_str().unwrap(), "--format", "json"]);
        assert_eq!(out.status.code(), Some(0), "{example}: {}", text(&out.stderr));
        let fits: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for fit in fits.as_array().unwrap() {
            assert_certified(fit);
        }
    }
}

#[test]
fn a_continuous_record_from_a_model_file() {
    // Goodman's continuous case: the record sampled every millisecond, record = "continuous".
    let model = r#"states = ["y", "v"]
parameters = ["g"]
[equations]
y = "v"
v = "g"
[unknowns]
y = 0.0
v = 0.0
g = 32.0
[data]
file = "data.csv"
record = "continuous"
"#;
    let mut data = String::from("t,y\n");
    for i in 0..=3000 {
        let t = i as f64 * 1e-3;
        data += &format!("{t},{}\n", 16.25 * t * t - 0.25 * t - 0.25 + 0.5 * (5.0 * t).sin());
    }
    let case = Case::new("continuous", model, &data);
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // docs/catalogue.md's exact answer; the 1 ms samples move it by a few 1e-6.
    for (name, value) in
        [("y", 0.14500913909107217), ("v", -0.9022248117533034), ("g", 32.9279895615339)]
    {
        let v = json["estimates"][name].as_f64().unwrap();
        assert!((v - value).abs() < 1e-5, "{name}: {v} vs {value}");
    }
}

/// Robertson's stiff kinetics as a model file fitted with the implicit integrator.
const ROBERTSON: &str = r#"states = ["y1", "y2", "y3"]
parameters = ["k1", "k2", "k3"]
[equations]
y1 = "-k1 * y1 + k3 * y2 * y3"
y2 = "k1 * y1 - k2 * y2^2 - k3 * y2 * y3"
y3 = "k2 * y2^2"
[initial]
y1 = 1.0
y2 = 0.0
y3 = 0.0
[unknowns]
k1 = { guess = 0.08, log = true }
k2 = { guess = 6e7, log = true }
k3 = { guess = 2e4, log = true }
[data]
file = "data.csv"
[integrator]
method = "rodas4"
rtol = 1e-9
atol = 1e-16
"#;

#[test]
fn a_stiff_model_file_fits_with_rodas4_and_explicit_integration_says_why_it_fails() {
    let case = Case::new("robertson", ROBERTSON, "");
    let data = case.path("data.csv");
    let simulated = case.path("simulated.csv");
    let args = ["--set", "k1=0.04", "--set", "k2=3e7", "--set", "k3=1e4"];
    let simulate = |out: &Path| {
        sysid(
            &[
                &["simulate", "--model", &case.model(), "--times", "0:40:2", "--out"][..],
                &[out.to_str().unwrap()],
                &args,
            ]
            .concat(),
        )
    };
    // Not over the model's own data file, which it names: elsewhere, then copied there.
    let out = simulate(&data);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("which this command reads"), "{}", text(&out.stderr));
    let out = simulate(&simulated);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    std::fs::copy(&simulated, &data).unwrap();
    // The model file's Rodas4, and Rodas5P from the command line.
    for scheme in [&[][..], &["--integrator", "rodas5p"][..]] {
        let fit = ["fit", "--model", &case.model(), "--format", "json"];
        let out = sysid(&[&fit[..], scheme].concat());
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        // Noise-free data from the truth: the fit returns it, to the integration tolerance
        // (measured: 1e-9 relative).
        for (name, value) in [("k1", 0.04), ("k2", 3e7), ("k3", 1e4)] {
            let k = json["estimates"][name].as_f64().unwrap();
            assert!((k - value).abs() < 1e-7 * value, "{scheme:?} {name}: {k} vs {value}");
        }
    }
    // DOPRI5 with a modest step budget: exit 2, and the message says the model is stiff.
    let out =
        sysid(&["fit", "--model", &case.model(), "--integrator", "dopri5", "--max-steps", "20000"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("stiff") && stderr.contains("rodas5p"), "{stderr}");
}

#[test]
fn integrator_choices_are_checked() {
    let model = ROBERTSON.replace("method = \"rodas4\"", "method = \"radau\"");
    bad(
        "radau",
        &model,
        DECAY_DATA,
        "[integrator] method must be \"dopri5\", \"dop853\", \"rk4\", \"rodas4\", \"rodas5p\", \"bdf\" or \"auto\", got \"radau\"",
    );
    let case = Case::new("rk4-step", DECAY, DECAY_DATA);
    let out = sysid(&["fit", "--model", &case.model(), "--integrator", "rk4"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--fixed-step"), "{}", text(&out.stderr));
    let out = sysid(&["fit", "--model", &case.model(), "--integrator", "radau"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("rodas4"), "{}", text(&out.stderr));
    let out =
        sysid(&["fit", "--model", &case.model(), "--integrator", "rk4", "--fixed-step", "0.01"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

/// Every method ends on its stopping rule at a certified point.
fn assert_certified(fit: &serde_json::Value) {
    let code = fit["termination_code"].as_str().unwrap();
    assert_eq!(fit["converged"], true, "{fit}");
    assert!(code.starts_with("converged_"), "{fit}");
}

/// The two-dose example from the command line: the JSON's likelihood keys, a prediction and
/// a simulation per experiment, and an unknown experiment refused by name.
#[test]
fn several_experiments_from_the_command_line() {
    let model =
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/two-doses/model.toml").to_string();
    let out = sysid(&["fit", "--model", &model, "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(json["nll"].as_f64().is_some() && json["aic"].as_f64().is_some());
    let experiments = json["experiments"].as_array().unwrap();
    assert_eq!(experiments.len(), 2);
    assert_eq!(experiments[0]["name"], "low");
    assert_eq!(experiments[1]["points"], 20);
    // The noise scale is an estimate like the others.
    assert!(json["estimates"]["sigma_B"].as_f64().is_some());
    assert!(json["std_errors"]["sigma_B"].as_f64().is_some());
    let table = text(&sysid(&["fit", "--model", &model]).stdout);
    assert!(table.contains("nll") && table.contains("experiment   high"), "{table}");

    let out = sysid(&["predict", "--model", &model, "--until", "12", "--experiment", "high"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(text(&out.stdout).starts_with("t,A,A_lower,A_upper,"));
    let both = text(&sysid(&["predict", "--model", &model, "--until", "12"]).stdout);
    assert!(both.starts_with("experiment,t,") && both.contains("\nhigh,"), "{both}");

    let sim = text(&sysid(&["simulate", "--model", &model, "--times", "0:2:1"]).stdout);
    assert_eq!(sim.lines().next(), Some("experiment,t,A,B,C,Bm,Ct"));
    assert_eq!(sim.lines().count(), 1 + 2 * 3);
    let out = sysid(&["predict", "--model", &model, "--until", "12", "--experiment", "mid"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("no such experiment (experiments: low, high)"));
}

/// A switch time as an unknown: x' = if(le(t, tau), a, −k·x) fitted to noise-free data of
/// τ = 1.5 from τ = 1.2 returns τ, certified, by Goodman's method and by quasilinearization.
/// Without the sensitivity jump at the switch, ∂r/∂τ would be 0 and τ would never move (or
/// a zero gradient would certify the guess).
#[test]
fn a_switch_time_is_estimated() {
    let model = r#"states = ["x"]
parameters = ["a", "k", "tau"]
[equations]
x = "if(le(t, tau), a, -k * x)"
[initial]
x = 0.0
[known]
a = 2.0
k = 0.5
[unknowns]
tau = 1.2
[data]
file = "data.csv"
"#;
    let x = |t: f64| if t <= 1.5 { 2.0 * t } else { 3.0 * (-0.5 * (t - 1.5)).exp() };
    let mut data = String::from("t,x\n");
    for i in 1..=8 {
        let t = 0.5 * f64::from(i) - 0.25;
        data.push_str(&format!("{t},{}\n", x(t)));
    }
    let case = Case::new("switch-time", model, &data);
    for method in ["goodman", "quasilinearization"] {
        let out = sysid(&["fit", "--model", &case.model(), "--method", method, "--format", "json"]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let tau = json["estimates"]["tau"].as_f64().unwrap();
        assert!((tau - 1.5).abs() < 1e-6, "{method}: tau = {tau}");
        assert_eq!(json["converged"], true, "{json}");
        if method == "quasilinearization" {
            // Its own steps, each from a linear family whose Φ jumps at the switch as the
            // sensitivity does (without the jump Φ_τ = 0, the least squares is singular and
            // every step is the safeguard's, which has no linear cost).
            let history = json["history"].as_array().unwrap();
            assert!(history[1..].iter().all(|h| h["linear_cost"].is_number()), "{json}");
        }
    }
}

/// A switch time whose best value is a sample time, where the objective has a kink:
/// x' = if(lt(t, tau), 0, 1) from x(0) = 0 gives x(t) = max(0, t − τ), sampled at t = 0…4
/// with data 0, 0, −1.5, 1.5, 2.5. On 1 ≤ τ ≤ 2 the cost (2 − τ + 1.5)² + 2(1.5 − τ)² + …
/// falls towards τ = 2 (its own minimum is at 13/6); on 2 ≤ τ ≤ 3 it is (1.5 − τ)² … rising
/// from τ = 2 (minimum at 1.5): the minimum is the kink at τ = 2, cost 1.5² + 0.5² + 0.5² =
/// 2.75 (σ = 1). Each trust-region method reaches it, certified with τ held on the sample
/// time (`switch_on_sample`), from 3.7 (over a kink at 3 first). Before kinks bounded the
/// retries, a trial over the kink failed again and again, the radius shrank on every
/// unknown, and the run stalled beside it.
#[test]
fn a_switch_time_on_a_sample_time_is_a_certified_kink() {
    let model = r#"states = ["x"]
parameters = ["tau"]
[equations]
x = "if(lt(t, tau), 0, 1)"
[initial]
x = 0.0
[unknowns]
tau = 3.7
[data]
file = "data.csv"
"#;
    let data = "t,x\n0,0\n1,0\n2,-1.5\n3,1.5\n4,2.5\n";
    let case = Case::new("switch-kink", model, data);
    for method in ["nl2sol", "levenberg-marquardt", "hybrid-newton", "geodesic-lm"] {
        let out = sysid(&["fit", "--model", &case.model(), "--method", method, "--format", "json"]);
        assert_eq!(out.status.code(), Some(0), "{method}: {}", text(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(json["converged"], true, "{method}: {json}");
        let tau = json["estimates"]["tau"].as_f64().unwrap();
        // Within the sliver of the kink (1e-9 of the time, either side), to rounding.
        assert!((tau - 2.0).abs() <= 2e-9 + 1e-15, "{method}: tau = {tau}");
        assert_eq!(json["active_bounds"]["tau"], "switch_on_sample", "{method}: {json}");
        let cost = json["cost"].as_f64().unwrap();
        assert!((cost - 2.75).abs() <= 1e-8, "{method}: cost {cost}");
    }
}

/// `also`: an experiment answers to other names too (the PEtab conditions merged into it):
/// `simulate` and `predict` find it by either; a name taken twice is refused where written.
#[test]
fn an_experiment_answers_to_its_other_names() {
    let model = r#"states = ["x"]
parameters = ["k"]
[equations]
x = "-k * x"
[initial]
x = 2.0
[unknowns]
k = 0.5
[[experiments]]
name = "first"
file = "data.csv"
also = ["same-settings", "again"]
"#;
    let case = Case::new("also", model, DECAY_DATA);
    let sim = |name: &str| {
        let times = ["--times", "0:2:1", "--experiment", name];
        sysid(&[&["simulate", "--model", &case.model()][..], &times[..]].concat())
    };
    let (by_name, by_other) = (sim("first"), sim("again"));
    assert_eq!(by_other.status.code(), Some(0), "{}", text(&by_other.stderr));
    assert_eq!(text(&by_name.stdout), text(&by_other.stdout));
    let out = sysid(&[
        "predict",
        "--model",
        &case.model(),
        "--until",
        "5",
        "--experiment",
        "same-settings",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(text(&out.stdout).starts_with("t,x,"), "{}", text(&out.stdout));
    bad(
        "also-twice",
        &model.replace(r#"["same-settings", "again"]"#, r#"["first"]"#),
        DECAY_DATA,
        "model.toml:12:9: [[experiments]]: two experiments are called `first`",
    );
}

/// Laplace noise of an unknown scale b, the rate known: the fit's b is the closed form's
/// maximum-likelihood scale, the mean absolute residual (to 1e-6 relative), the fit is
/// certified, and its NLL is n·ln(2b̂) + n (each |d|/b̂ sums to n).
#[test]
fn a_laplace_scale_is_fitted_to_the_mean_absolute_residual() {
    let times: [f64; 5] = [0.5, 1.0, 2.0, 3.0, 4.0];
    let measured: [f64; 5] = [1.3, 0.9, 0.55, 0.25, 0.18];
    let mut data = String::from("t,y\n");
    for (t, m) in times.iter().zip(measured) {
        data += &format!("{t},{m}\n");
    }
    let model = "states = [\"x\"]\nparameters = [\"k\"]\n[equations]\nx = \"-k * x\"\n[initial]\nx = 2.0\n[known]\nk = 0.6\n[outputs]\ny = { value = \"x\", sigma = \"b\", distribution = \"laplace\" }\n[unknowns]\nb = { guess = 0.5, min = 0.001 }\n[data]\nfile = \"data.csv\"\n[integrator]\nrtol = 1e-12\natol = 1e-14\n";
    let case = Case::new("laplace", model, &data);
    let out = sysid(&["fit", "--model", &case.model(), "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(json["converged"].as_bool(), Some(true), "{json}");
    let b = json["estimates"]["b"].as_f64().expect("b");
    let n = times.len() as f64;
    let mean: f64 =
        times.iter().zip(measured).map(|(t, m)| (2.0 * (-0.6 * t).exp() - m).abs()).sum::<f64>()
            / n;
    assert!((b - mean).abs() <= 1e-6 * mean, "b = {b}, mean |d| = {mean}");
    let nll = json["nll"].as_f64().expect("nll");
    let expected = n * (2.0 * mean).ln() + n;
    assert!((nll - expected).abs() <= 1e-9 * expected.abs().max(1.0), "{nll} vs {expected}");
}

/// A Laplace prior of location 0 and scale b on an offset c (y = x + c, x = x0·e^(−0.6t),
/// normal noise σ = 0.05): the objective ½Σ((x0·e_i + c − m_i)/σ)² + |c|/b is an L1-penalised
/// linear least squares, whose minimiser is in closed form. With b = 1 the data pull c off
/// the kink: the 2×2 normal equations with the prior's slope sign(c)·σ²/b on c's row. With
/// b = 0.001 the data's pull at c = 0 (33 in units of 1/σ²) is below the prior's 1/b = 1000:
/// c = 0 exactly, held there (`"prior_location"`, no standard error), x0 the fit without c.
/// With b = 1/30 the pull beats the prior by a tenth only, and from c = 0 a step must count
/// the prior's slope to be accepted. With `max = 0` the location is c's upper bound and the
/// data pull c past it: held there as on a bound (`"upper"`).
/// Every method that takes priors is certified there, to 1e-7 relative, from c = 0.3 and
/// from c = 0 (on the kink, which it must leave when b = 1). Before the kink was a bound of
/// the step, the Gauss–Newton row of |c|/b stepped to −c and back.
#[test]
fn a_laplace_prior_holds_an_unknown_at_its_location_by_its_subgradient() {
    let times = [0.5, 1.0, 2.0, 3.0, 4.0];
    let measured = [1.541636, 1.127623, 0.667388, 0.375598, 0.241436];
    let mut data = String::from("t,y\n");
    for (t, m) in times.iter().zip(measured) {
        data += &format!("{t},{m}\n");
    }
    let e: Vec<f64> = times.iter().map(|t: &f64| (-0.6 * t).exp()).collect();
    let sigma: f64 = 0.05;
    let (see, se, n) = (e.iter().map(|v| v * v).sum::<f64>(), e.iter().sum::<f64>(), 5.0);
    let (sme, sm) =
        (e.iter().zip(measured).map(|(v, m)| v * m).sum::<f64>(), measured.iter().sum::<f64>());
    // Off the kink (c > 0): [Σe² Σe; Σe n][x0; c] = [Σme; Σm − σ²/b].
    let off = |b: f64| {
        let rhs = sm - sigma * sigma / b;
        let det = see * n - se * se;
        ((sme * n - se * rhs) / det, (see * rhs - se * sme) / det)
    };
    let (x0_off, c_off) = off(1.0);
    assert!(c_off > 0.0, "the premise: c > 0 at b = 1");
    // On the kink: x0 = Σme/Σe², and the data's pull on c is below the prior's slope.
    let x0_on = sme / see;
    let pull = e.iter().zip(measured).map(|(v, m)| x0_on * v - m).sum::<f64>() / (sigma * sigma);
    assert!(pull.abs() < 0.1 / 0.001 && pull.abs() > 1.0, "the premise: {pull}");
    // b = 1/30: the pull 33 beats the prior's 30 by a tenth, too little for a step whose
    // model leaves the prior's slope out (ρ ≤ 1 − 30/33 < ¼).
    let (x0_near, c_near) = off(1.0 / 30.0);
    assert!(
        c_near > 0.0 && pull.abs() > 30.0 && pull.abs() < 40.0,
        "the premise: {c_near}, {pull}"
    );
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-7 * b.abs().max(1e-2);
    // (b, the start of x and of c, x0, c, c's bound, what active_bounds says of c.) From
    // x = x0_on, c = 0 with b = 1/30, the start is the kink's best point, where the data pull
    // c by only a tenth more than the prior does.
    for (b, (x_guess, guess), x0, c, max, held) in [
        (1.0, (1.5, 0.3), x0_off, c_off, "", None),
        (1.0, (1.5, 0.0), x0_off, c_off, "", None),
        (1.0 / 30.0, (x0_on, 0.0), x0_near, c_near, "", None),
        (0.001, (1.5, 0.3), x0_on, 0.0, "", Some("prior_location")),
        // The location on c's upper bound, the data pulling c up past it: held on the bound.
        (1.0, (1.5, -0.3), x0_on, 0.0, ", max = 0", Some("upper")),
    ] {
        let model = format!(
            "states = [\"x\"]\nparameters = [\"c\"]\n[equations]\nx = \"-0.6 * x\"\n[outputs]\n\
             y = {{ value = \"x + c\", sigma = 0.05 }}\n[unknowns]\nx = {x_guess:?}\n\
             c = {{ guess = {guess}{max}, prior = {{ mean = 0, sd = {b}, distribution = \"laplace\" }} }}\n\
             [data]\nfile = \"data.csv\"\n[integrator]\nrtol = 1e-12\natol = 1e-14\n"
        );
        let case = Case::new("laplace-prior", &model, &data);
        for method in [
            "nl2sol",
            "levenberg-marquardt",
            "hybrid-newton",
            "geodesic-lm",
            "goodman",
            "goodman-halving",
            "gauss-newton",
            "gauss-newton-ls",
        ] {
            // argmin's steps move the free unknowns without the kink's box (only its holds
            // see it): off a kink by a pull a tenth above the prior's, its full Gauss–Newton
            // steps on the √|d| row crawl, and it stops honestly uncertified (optimality
            // 1.04e-6 after 52 iterations; docs/methods.md).
            if method.starts_with("gauss-newton") && (30.0 * b - 1.0f64).abs() < 1e-12 {
                continue;
            }
            // Without the trust regions' coarse stage: with it, levenberg-marquardt from c = 0
            // at b = 1/30 certifies a point 2e-6 from c's closed form (relative), within the
            // certificate's gtol but not the 1e-7 held here.
            let model = case.model();
            let args = ["fit", "--model", &model, "--method", method, "--format", "json"];
            let out = sysid(&[&args[..], &["--no-coarse-first"]].concat());
            let what = format!("{method}, b = {b}, from c = {guess}");
            assert_eq!(out.status.code(), Some(0), "{what}: {}", text(&out.stderr));
            let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
            assert_eq!(json["converged"], true, "{what}: {json}");
            let (fx, fc) = (
                json["estimates"]["x"].as_f64().unwrap(),
                json["estimates"]["c"].as_f64().unwrap(),
            );
            assert!(close(fx, x0) && close(fc, c), "{what}: x0 = {fx} vs {x0}, c = {fc} vs {c}");
            match held {
                Some(bound) => {
                    assert_eq!(fc.abs().to_bits(), 0, "{what}: on the kink exactly, not {fc}");
                    assert_eq!(json["active_bounds"]["c"], bound, "{what}");
                    assert!(json["std_errors"]["c"].is_null(), "{what}");
                }
                None => assert!(json["active_bounds"].as_object().unwrap().is_empty(), "{what}"),
            }
        }
    }
}

/// Two noise scales set in closed form, by the two ways the driver has: the trust-region
/// methods profile them at every iterate after the first round, goodman and gauss-newton fit
/// in rounds between closed-form updates. Both are certified at the same maximum-likelihood
/// point (to 1e-6 relative in the estimates, the certificate's gtol; the NLL to 1e-9).
#[test]
fn profiled_noise_scales_and_rounds_reach_the_same_optimum() {
    let model = "states = [\"x\"]
parameters = [\"k\"]
[equations]
x = \"-k * x\"
[outputs]
X = { value = \"x\", sigma = \"s1\" }
Y = { value = \"x * x\", sigma = \"s2\" }
[unknowns]
k = { guess = 0.3, log = true }
x = 1.0
s1 = { guess = 1.0, log = true }
s2 = { guess = 1.0, log = true }
[data]
file = \"data.csv\"
";
    let case = Case::new(
        "profile",
        model,
        "t,X,Y\n0.0,2.0047,4.2500\n0.5,1.3628,2.1848\n1.0,0.9802,0.9341\n1.5,0.7949,0.5213\n2.0,0.4910,0.3891\n2.5,0.4039,0.1146\n3.0,0.2743,-0.1348\n3.5,0.1542,-0.0578\n4.0,0.0550,-0.2869\n4.5,0.0044,-0.0404\n5.0,0.0518,-0.0604\n5.5,0.0460,-0.2653\n",
    );
    let fit = |method: &str| {
        let out = sysid(&["fit", "--model", &case.model(), "--method", method, "--format", "json"]);
        assert_eq!(out.status.code(), Some(0), "{method}: {}", text(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(json["converged"], true, "{method}");
        json
    };
    let reference = fit("goodman");
    for method in ["nl2sol", "levenberg-marquardt", "gauss-newton-ls"] {
        let json = fit(method);
        for name in ["k", "x", "s1", "s2"] {
            let (a, b) = (
                json["estimates"][name].as_f64().unwrap(),
                reference["estimates"][name].as_f64().unwrap(),
            );
            assert!((a / b - 1.0).abs() < 1e-6, "{method}: {name} {a} against {b}");
        }
        let (a, b) = (json["nll"].as_f64().unwrap(), reference["nll"].as_f64().unwrap());
        assert!((a - b).abs() < 1e-9, "{method}: nll {a} against {b}");
    }
}

/// `evaluate`'s integration errors against the closed form: x = 2e^{−kt} measured with σ = 0.1,
/// so NLL = Σ ½ln(2πσ²) + ½((x(t) − m)/σ)² and ∂NLL/∂k = Σ (x(t) − m)/σ² · (−t x(t)). At
/// rtol 1e-5 the integration's error is measurable; `nll_error` and `gradient_error` are
/// |x − x′| with x′ at a tenth of rtol and atol (checked by evaluating there), and the true
/// error is within 3 times them (the estimate is of the error at the given tolerance, not a
/// bound: at a tenth of the tolerance the error of DOPRI5 is about a tenth). A fixed step has
/// no finer integration, and `--no-integration-error` skips it: both are null then.
#[test]
fn evaluate_reports_the_integration_error_of_its_numbers() {
    let model =
        DECAY.replace("[unknowns]", "[outputs]\ny = { value = \"x\", sigma = 0.1 }\n[unknowns]");
    let data = "t,y\n0.5,1.6\n1,1.2\n2,0.75\n3,0.43\n";
    let case = Case::new("errors", &model, data);
    let path = case.model();
    let evaluate = |extra: &[&str]| -> serde_json::Value {
        let mut args = vec!["evaluate", "--model", &path, "--gradient", "--format", "json"];
        args.extend_from_slice(extra);
        let out = sysid(&args);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        serde_json::from_slice(&out.stdout).expect("JSON")
    };
    let at = evaluate(&["--rtol", "1e-5", "--atol", "1e-8"]);
    let finer = evaluate(&["--rtol", "1e-6", "--atol", "1e-9"]);
    let (k, sigma) = (0.5_f64, 0.1_f64);
    let (mut nll, mut gradient) = (0.0, 0.0);
    for (t, m) in [(0.5, 1.6), (1.0, 1.2), (2.0, 0.75), (3.0, 0.43)] {
        let x = 2.0 * (-k * t).exp();
        nll += 0.5 * (2.0 * std::f64::consts::PI * sigma * sigma).ln()
            + 0.5 * ((x - m) / sigma).powi(2);
        gradient += (x - m) / (sigma * sigma) * (-t * x);
    }
    let value = |v: &serde_json::Value, key: &str| v[key].as_f64().expect(key);
    let (got, error) = (value(&at, "nll"), value(&at, "nll_error"));
    let measured = (got - value(&finer, "nll")).abs();
    assert!((error - measured).abs() <= 1e-3 * measured, "nll_error {error} against {measured}");
    assert!(error > 0.0 && (got - nll).abs() <= 3.0 * error, "{got} vs {nll} ± {error}");
    let g = at["gradient"]["k"].as_f64().expect("gradient");
    let g_error = at["gradient_error"]["k"].as_f64().expect("gradient_error");
    let measured = (g - finer["gradient"]["k"].as_f64().expect("gradient")).abs();
    assert!((g_error - measured).abs() <= 1e-3 * measured, "{g_error} against {measured}");
    assert!(
        g_error > 0.0 && (g - gradient).abs() <= 3.0 * g_error,
        "{g} vs {gradient} ± {g_error}"
    );
    let fixed = evaluate(&["--integrator", "rk4", "--fixed-step", "0.01"]);
    assert!(fixed["nll_error"].is_null() && fixed["gradient_error"].is_null(), "{fixed}");
    let skipped = evaluate(&["--no-integration-error"]);
    assert!(skipped["nll_error"].is_null() && skipped["gradient_error"].is_null(), "{skipped}");
}

/// `simulate --times` keeps times that 15 significant digits would merge (1.7e9 + 1e-6 is not
/// 1.7e9) and still writes 0 + 3·0.1 as 0.3; a step below a float's resolution there, an
/// experiment the file does not have, a catalogue system given a model file's options and an
/// `evaluate --repeat` beyond its limit are refused (exit 2, one line), not ignored.
#[test]
fn simulated_times_keep_their_digits_and_options_are_not_ignored() {
    // x′ = 0: nothing to integrate, whatever the times.
    let constant = "states = [\"x\"]\n[equations]\nx = \"0\"\n[unknowns]\nx = 0.1\n[data]\nfile = \"data.csv\"\n";
    let case = Case::new("digits", constant, "t,x\n0,0.1\n");
    let times = |spec: &str| -> Vec<String> {
        let out = sysid(&["simulate", "--model", &case.model(), "--times", spec]);
        assert!(out.status.success(), "{spec}: {}", text(&out.stderr));
        let csv = text(&out.stdout);
        csv.lines().skip(1).map(|l| l.split(',').next().unwrap().to_string()).collect()
    };
    let late = times("1700000000:1700000000.000003:0.000001");
    assert_eq!(late.len(), 4);
    let parsed: Vec<f64> = late.iter().map(|t| t.parse().unwrap()).collect();
    for (k, t) in parsed.iter().enumerate() {
        // Within the float's spacing there (2.4e-7) of 1.7e9 + k·1e-6.
        assert!((t - 1.7e9 - k as f64 * 1e-6).abs() <= 2.4e-7, "{late:?}");
    }
    assert_eq!(times("0:0.3:0.1"), ["0", "0.1", "0.2", "0.3"]);
    for (args, needle) in [
        (vec!["--times", "1e17:1.0000000000000002e17:1"], "below the resolution of a float"),
        (
            vec!["--times", "0:1:0.5", "--experiment", "other"],
            "--experiment other: no such experiment",
        ),
    ] {
        let model = case.model();
        let mut all = vec!["simulate", "--model", &model];
        all.extend(args);
        let out = sysid(&all);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{all:?}: {stderr}");
        assert!(stderr.contains(needle) && stderr.trim_end().lines().count() == 1, "{stderr}");
    }
    // More timed evaluations than are kept is refused before any (it aborted allocating).
    let out = sysid(&["evaluate", "--model", &case.model(), "--repeat", "1000000000000"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("at most 1000000 evaluations"));
    for option in [["--times", "0:1:0.1"], ["--set", "mu=2"], ["--experiment", "data"]] {
        let out = sysid(&["simulate", "--system", "van-der-pol", option[0], option[1]]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{option:?}: {stderr}");
        assert!(stderr.contains(&format!("{} is for a model file's", option[0])), "{stderr}");
    }
}

/// A σ column that is the measured column itself (or a state's or input's name) is refused
/// at the `column` key: model-files.md says the σ column names nothing else, and the fit
/// would otherwise weigh each value by itself.
#[test]
fn a_sigma_column_that_names_something_else_is_refused() {
    let model = |column: &str| {
        format!(
            "states = [\"x\"]\nparameters = [\"k\"]\n[equations]\nx = \"-k * x\"\n[initial]\nx = 2.0\n\
             [unknowns]\nk = 0.5\n[outputs]\nxm = {{ value = \"x\", sigma = {{ column = \"{column}\" }} }}\n\
             [data]\nfile = \"data.csv\"\n"
        )
    };
    let data = "t,xm,s\n0,2,0.1\n1,0.9,0.1\n2,0.4,0.1\n";
    bad(
        "sigma-self",
        &model("xm"),
        data,
        "10:40: [outputs] xm.sigma.column `xm` is an output's name",
    );
    bad("sigma-state", &model("x"), data, "xm.sigma.column `x` is a state's name");
    let case = Case::new("sigma-own", &model("s"), data);
    let out = sysid(&["fit", "--model", &case.model()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
}

/// Growth from far below atol: x′ = s + b x (1 − x) from x(0) = 0, fed at s = 1e-14 (data
/// from the closed form, a Riccati equation). Below atol the integration controls nothing of
/// x, which starts at 0 and so has atol for its floor: the cost is an artefact of the
/// integration, and a fit says so instead of naming a minimum, a flat direction or a sloppy
/// one; at an atol below the source it finds s and b. Logistic growth from x(0) = 1e-14 (the
/// start an unknown) is resolved at the default atol: a state that starts below atol is held
/// to a thousandth of its initial size at rtol 1e-8 (before, that fit was certified exact at x(0) = 2.7e-14).
#[test]
fn a_fit_the_integration_does_not_resolve_says_so() {
    let model = |initial: &str, rate: &str, unknown: &str| {
        format!(
            "states = [\"x\"]\nparameters = [\"b\", \"{unknown}\"]\n[equations]\nx = \"{rate}\"\n\
             [initial]\nx = {initial}\n[unknowns]\nb = {{ guess = 1.0, log = true }}\n\
             {unknown} = {{ guess = 1e-14, log = true, min = 1e-30, max = 1 }}\n\
             [data]\nfile = \"data.csv\"\n[data.weights]\nx = 10000.0\n"
        )
    };
    let data = |x: &dyn Fn(f64) -> f64| {
        let mut data = String::from("t,x\n");
        for i in 0..=40 {
            let t = f64::from(i);
            data += &format!("{t},{:e}\n", x(t));
        }
        data
    };
    // x′ = −b (x − r1)(x − r2), r1 < 0 < r2 the roots of s + b x − b x² (b = 1, s = 1e-14;
    // r1 = −s/(b r2) without cancellation): (x − r2)/(x − r1) = (r2/r1)·e^(−b (r2 − r1) t).
    let (s, b) = (1e-14_f64, 1.0_f64);
    let r2 = 0.5 * (1.0 + (1.0 + 4.0 * s / b).sqrt());
    let r1 = -s / (b * r2);
    let fed = |t: f64| {
        let k = r2 / r1 * (-b * (r2 - r1) * t).exp();
        (r2 - k * r1) / (1.0 - k)
    };
    let case = Case::new("unresolved", &model("0.0", "s + b * x * (1 - x)", "s"), &data(&fed));
    let path = case.model();
    let fit = |path: &str, extra: &[&str]| {
        let mut args = vec!["fit", "--model", path, "--format", "json"];
        args.extend_from_slice(extra);
        let out = sysid(&args);
        let json = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap();
        // 0 where the fit converged, 1 where it did not.
        let code = if json["converged"] == true { 0 } else { 1 };
        assert_eq!(out.status.code(), Some(code), "{}", text(&out.stderr));
        json
    };
    // At the model file's atol 1e-10.
    let json = fit(&path, &[]);
    let said = json["termination"].as_str().unwrap();
    assert_eq!(json["converged"], false, "{said}");
    assert!(said.contains("the integration does not resolve the model"), "{said}");
    assert!(!said.contains("`s`") && !said.contains("not a minimum"), "{said}");
    assert_eq!(json["undetermined"], serde_json::json!([]));
    let (cost, error) = (json["cost"].as_f64().unwrap(), json["cost_error"].as_f64().unwrap());
    assert!(error > 0.1 * cost, "ε {cost}, its error {error}");
    // At atol 1e-22 the source and the rate are found: s to 1e-5 and b to 1e-6 relative.
    let json = fit(&path, &["--atol", "1e-22"]);
    let said = json["termination"].as_str().unwrap();
    assert_eq!(json["converged"], true, "{said}");
    let found = json["estimates"]["s"].as_f64().unwrap();
    let rate = json["estimates"]["b"].as_f64().unwrap();
    assert!((found / s - 1.0).abs() < 1e-5 && (rate - b).abs() < 1e-6, "s {found}, b {rate}");
    assert!(json["nll_error"].as_f64().unwrap() < 1e-9, "{}", json["nll_error"]);
    // Logistic growth from x0 = 1e-14 at the default atol 1e-10: x0 and b found, x0 to 1e-4
    // (x's floor is a thousandth of its initial size; 1.3e-5 measured, b 1.3e-8).
    let logistic = |t: f64| 1.0 / (1.0 + (1e14 - 1.0) * (-t).exp());
    let case = Case::new("below-atol", &model("\"x0\"", "b * x * (1 - x)", "x0"), &data(&logistic));
    let json = fit(&case.model(), &[]);
    let said = json["termination"].as_str().unwrap();
    assert_eq!(json["converged"], true, "{said}");
    let x0 = json["estimates"]["x0"].as_f64().unwrap();
    let rate = json["estimates"]["b"].as_f64().unwrap();
    assert!((x0 / 1e-14 - 1.0).abs() < 1e-4 && (rate - 1.0).abs() < 1e-6, "x0 {x0}, b {rate}");
}
