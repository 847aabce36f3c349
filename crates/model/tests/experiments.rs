//! Experiments, noise models and settings in model files: each mistake the issue lists with
//! its one-line message naming the file, the key, the experiment, the row or the column; and
//! a valid file read as the problem it describes.

use std::path::{Path, PathBuf};

use sysid_model::{Model, ModelFile};

/// A model of two experiments (18 lines), to which the cases append or in which they replace.
const TWO: &str = "states = [\"A\", \"B\"]
parameters = [\"k\", \"dose\", \"scale\"]
[equations]
A = \"-k * A\"
B = \"k * A\"
[initial]
A = \"dose\"
B = 0.0
[known]
scale = 1.0
[outputs]
Bm = { value = \"scale * B\", sigma = \"s\" }
[unknowns]
k = 0.5
s = { guess = 0.1, log = true }
[[experiments]]
name = \"low\"
file = \"low.csv\"
set = { dose = 1.0 }
[[experiments]]
name = \"high\"
file = \"high.csv\"
set = { dose = 5.0 }
";

#[track_caller]
fn refused(model: &str, expected: &str) {
    match ModelFile::parse(model, Path::new("m.toml")) {
        Ok(_) => panic!("accepted:\n{model}"),
        Err(e) => assert_eq!(e.to_string(), expected, "model:\n{model}"),
    }
}

#[test]
fn mistakes_in_the_file_are_named_where_they_are() {
    refused(
        &format!("{TWO}[data]\nfile = \"d.csv\"\n"),
        "m.toml:24:1: [data] and [[experiments]] together: with experiments, each experiment names its own data file",
    );
    refused(
        &TWO.replace("name = \"high\"", "name = \"low\""),
        "m.toml:21:8: [[experiments]]: two experiments are called `low`",
    );
    refused(
        &TWO.replace("set = { dose = 5.0 }", "set = { dose = 5.0, rate = 2.0 }"),
        "m.toml:23:21: experiment `high`: set `rate`: not a parameter (parameters: k, dose, scale)",
    );
    refused(
        &TWO.replace("set = { dose = 5.0 }", "set = { }"),
        "m.toml:21:8: experiment `high` does not set parameter `dose`, which is neither in [known] nor in [unknowns]",
    );
    refused(
        &TWO.replace(
            "s = { guess = 0.1, log = true }",
            "s = { guess = 0.1, log = true }\nunused = 1.0",
        ),
        "m.toml:16:1: [unknowns]: `unused` is used nowhere: it is no state or parameter, and no sigma, set or [initial] expression names it",
    );
    refused(
        &TWO.replace("sigma = \"s\" }", "sigma = \"s\", distribution = \"laplace\" }"),
        "m.toml:12:57: [outputs] Bm.distribution: \"laplace\" noise is not supported yet (the likelihood is normal)",
    );
    refused(
        &TWO.replace("sigma = \"s\"", "sigma = -0.1"),
        "m.toml:12:37: [outputs] Bm.sigma must be positive, got -0.1",
    );
    refused(
        &TWO.replace("A = \"dose\"", "A = \"dose * q\""),
        "m.toml:7:13: [initial] A: unknown name `q` (names: k, dose, scale, s)",
    );
}

/// A scratch directory with the two data files.
fn scratch(name: &str, low: &str, high: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("sysid-model-experiments-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("low.csv"), low).unwrap();
    std::fs::write(dir.join("high.csv"), high).unwrap();
    dir
}

fn problem_error(dir: &Path, model: &str) -> String {
    let path = dir.join("m.toml");
    std::fs::write(&path, model).unwrap();
    let message = match Model::load(&path).and_then(|m| m.problem(None)) {
        Ok(_) => panic!("accepted:\n{model}"),
        Err(e) => e.to_string(),
    };
    message.replace(&dir.display().to_string(), "DIR")
}

const LOW: &str = "t,Bm\n1,0.6\n2,0.85\n3,0.95\n";
const HIGH: &str = "t,Bm\n1,3.2\n2,4.3\n3,4.8\n";

#[test]
fn mistakes_in_the_data_are_named_with_their_experiment_row_and_column() {
    let dir = scratch("data", LOW, HIGH);
    // A missing file.
    let e = problem_error(&dir, &TWO.replace("file = \"high.csv\"", "file = \"gone.csv\""));
    assert!(e.starts_with("DIR/gone.csv: experiment `high`: "), "{e}");
    // A log scale and a measurement that is not positive.
    std::fs::write(dir.join("high.csv"), "t,Bm\n1,3.2\n2,-4.3\n3,4.8\n").unwrap();
    let e =
        problem_error(&dir, &TWO.replace("sigma = \"s\"", "sigma = \"s\", transform = \"log\""));
    assert_eq!(
        e,
        "DIR/high.csv:3:3: experiment `high`: column `Bm`: -4.3 is not positive, and `Bm` is measured on the log scale"
    );
    std::fs::write(dir.join("high.csv"), HIGH).unwrap();
    // Weights and a σ on one output (one experiment: [data]).
    let single = TWO.split("[[experiments]]").next().unwrap().replace("A = \"dose\"", "A = 1.0");
    let single = single
        .replace("parameters = [\"k\", \"dose\", \"scale\"]", "parameters = [\"k\", \"scale\"]");
    let e = problem_error(
        &dir,
        &format!("{single}[data]\nfile = \"low.csv\"\n[data.weights]\nBm = 2.0\n"),
    );
    assert_eq!(
        e,
        "DIR/m.toml:19:1: [data.weights] Bm: the output has a `sigma`; give its noise one way"
    );
    // A σ that is not positive at the start, named with its output, experiment and time.
    let e = problem_error(
        &dir,
        &TWO.replace("sigma = \"s\"", "sigma = \"0.5 - Bm\"")
            .replace("s = { guess = 0.1, log = true }\n", ""),
    );
    assert!(e.contains("`Bm`") && e.contains("experiment `low`") && e.contains("t = "), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_valid_file_is_the_problem_it_describes() {
    let dir = scratch("valid", LOW, HIGH);
    let path = dir.join("m.toml");
    std::fs::write(&path, TWO).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    let names: Vec<&str> = problem.experiments().iter().map(|e| e.name()).collect();
    assert_eq!(names, ["low", "high"]);
    // k is moved by the methods; s is a noise scale set in closed form.
    assert_eq!(problem.names(), ["k"]);
    assert_eq!(problem.scales().len(), 1);
    // A(0) = dose: 1 and 5.
    let v = problem.values_at(&problem.unknowns().coordinates(&problem.guesses()));
    let starts: Vec<f64> = problem.experiments().iter().map(|e| e.point(&v).0[0]).collect();
    assert_eq!(starts, [1.0, 5.0]);
    let _ = std::fs::remove_dir_all(&dir);
}
