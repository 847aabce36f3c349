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
        "m.toml:16:1: [unknowns]: `unused` is used nowhere: it is no state or parameter, and no sigma, set, preequilibrate, initial or [initial] expression names it",
    );
    refused(
        &TWO.replace("sigma = \"s\" }", "distribution = \"laplace\" }"),
        "m.toml:12:1: [outputs] Bm: laplace noise needs a `sigma`, its scale b",
    );
    refused(
        &TWO.replace("sigma = \"s\" }", "sigma = \"s\", distribution = \"cauchy\" }"),
        "m.toml:12:57: [outputs] Bm.distribution must be \"normal\" or \"laplace\", got \"cauchy\"",
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
    // A σ that also enters a setting moves the model, so it is no pure scale: the methods
    // move it, whichever key the setting is under.
    for key in ["set", "preequilibrate", "initial"] {
        let other = match key {
            "initial" => "initial = { B = \"s\" }",
            _ => &format!("{key} = {{ dose = \"s\" }}"),
        };
        let model = format!(
            "{TWO}[[experiments]]\nname = \"third\"\nfile = \"low.csv\"\nset = {{ dose = 2.0 }}\n{other}\n"
        );
        let model = model.replace("set = { dose = 2.0 }\nset = ", "set = ");
        std::fs::write(&path, model).unwrap();
        let problem = Model::load(&path).unwrap().problem(None).unwrap();
        assert_eq!(problem.names(), ["k", "s"], "{key}");
        assert!(problem.scales().is_empty(), "{key}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `preequilibrate`: the experiment starts from the steady state reached under other
/// settings. x' = a − b·x settles at a/b (a = 1 before, 4 in the experiment); A ⇌ B keeps
/// A + B, so its steady state k₂/(k₁ + k₂)·A₀ depends on the unknown initial value A₀ (a
/// singular Jacobian: the implicit-function formula would lose it). The cost and its
/// gradient against the closed form x(t) = 4/b − 3/b·e^{−bt}, A(t) = k₂A₀/(k₁ + k₂), the
/// gradient by central differences of the closed form.
#[test]
fn preequilibration_starts_from_the_steady_state() {
    let model = "states = [\"x\", \"A\", \"B\"]
parameters = [\"a\", \"b\", \"k1\", \"k2\"]
[equations]
x = \"a - b * x\"
A = \"-k1 * A + k2 * B\"
B = \"k1 * A - k2 * B\"
[initial]
x = 0.0
B = 0.0
[known]
a = 1.0
k2 = 0.5
[unknowns]
b = 2.0
k1 = 1.5
A = 3.0
[[experiments]]
name = \"after\"
file = \"low.csv\"
set = { a = 4.0 }
preequilibrate = { a = 1.0 }
[integrator]
method = \"rodas4\"
rtol = 1e-10
atol = 1e-12
";
    let data = "t,x,A\n0.5,1.2,0.8\n1,1.6,0.7\n2,1.9,0.75\n";
    let dir = scratch("preequilibrate", data, data);
    let path = dir.join("m.toml");
    std::fs::write(&path, model).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    let cost = |b: f64, k1: f64, a0: f64| {
        let k2 = 0.5;
        let mut eps = 0.0;
        for (t, x, a) in [(0.5, 1.2, 0.8), (1.0, 1.6, 0.7), (2.0, 1.9, 0.75)] {
            let xm = 4.0 / b - 3.0 / b * (-b * t).exp();
            let am = k2 * a0 / (k1 + k2);
            eps += (x - xm) * (x - xm) + (a - am) * (a - am);
        }
        eps
    };
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).unwrap();
    // Forgetting the cached steady state (as `evaluate --repeat` does between timed
    // evaluations) solves it again, to the same bits.
    problem.forget_cached();
    assert_eq!(problem.linearize(&z).unwrap().cost.to_bits(), lin.cost.to_bits());
    let (b, k1, a0) = (2.0, 1.5, 3.0);
    assert!((lin.cost - cost(b, k1, a0)).abs() <= 1e-8, "{} vs {}", lin.cost, cost(b, k1, a0));
    let h = 1e-6;
    let fd = [
        (cost(b + h, k1, a0) - cost(b - h, k1, a0)) / (2.0 * h),
        (cost(b, k1 + h, a0) - cost(b, k1 - h, a0)) / (2.0 * h),
        (cost(b, k1, a0 + h) - cost(b, k1, a0 - h)) / (2.0 * h),
    ];
    for (j, d) in fd.iter().enumerate() {
        // U is half the gradient of ε.
        assert!(
            (lin.gradient[j] - 0.5 * d).abs() <= 1e-7 * d.abs().max(1.0),
            "{j}: {} vs {}",
            lin.gradient[j],
            0.5 * d
        );
    }
    // Fits side by side (a multistart's starts) share the steady state's cache: two threads
    // at 100 points each, more than the cache holds, each cost the closed form's at its own
    // point, none another thread's steady state.
    std::thread::scope(|scope| {
        for thread in 0..2 {
            let (problem, cost) = (&problem, &cost);
            scope.spawn(move || {
                for i in 0..100 {
                    let a0 = 1.0 + 0.01 * i as f64 + 0.5 * thread as f64;
                    let z = problem.unknowns().coordinates(&[b, k1, a0]);
                    let got = problem.linearize(&z).unwrap().cost;
                    let want = cost(b, k1, a0);
                    assert!(
                        (got - want).abs() <= 1e-8,
                        "thread {thread}, A0 {a0}: {got} vs {want}"
                    );
                }
            });
        }
    });
    // A steady state's values are no sizes for the states' tolerances (rounding may leave
    // 1e-20 there): each is held to atol; a value the experiment gives after the
    // preequilibration is a size.
    let v = problem.values_at(&z);
    let e = &problem.experiments()[0];
    assert_eq!(e.sizes(&e.point(&v).0), [0.0; 3]);
    let given = model.replace("preequilibrate =", "initial = { x = 0.25 }\npreequilibrate =");
    std::fs::write(&path, given).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    let e = &problem.experiments()[0];
    let y0 = e.point(&v).0;
    assert_eq!((y0[0], e.sizes(&y0)), (0.25, vec![0.25, 0.0, 0.0]));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Experiments whose preequilibrations set the same values share one steady state; one that
/// sets another value has its own. x' = a − b·x settles at a_pre/b and then goes to a/b:
/// x(t) = a/b + (a_pre − a)/b·e^{−bt}. "one" and "two" preequilibrate at a = 1, "three" at
/// a = 2 (were it given the others' steady state, its start would be 1/b instead of 2/b); the
/// cost against the closed form, each experiment's own, at two points (the second met after
/// the first is cached).
#[test]
fn experiments_preequilibrated_alike_share_a_steady_state_and_no_other() {
    let model = "states = [\"x\"]
parameters = [\"a\", \"b\"]
[equations]
x = \"a - b * x\"
[initial]
x = 0.0
[known]
a = 1.0
[unknowns]
b = 2.0
[[experiments]]
name = \"one\"
file = \"low.csv\"
set = { a = 4.0 }
preequilibrate = { a = 1.0 }
[[experiments]]
name = \"two\"
file = \"high.csv\"
set = { a = 3.0 }
preequilibrate = { a = 1.0 }
[[experiments]]
name = \"three\"
file = \"low.csv\"
set = { a = 4.0 }
preequilibrate = { a = 2.0 }
[integrator]
method = \"rodas4\"
rtol = 1e-10
atol = 1e-12
";
    let (low, high) = ("t,x\n0.5,1.2\n1,1.6\n2,1.9\n", "t,x\n0.5,1.1\n1,1.3\n2,1.45\n");
    let dir = scratch("preequilibrated-alike", low, high);
    let path = dir.join("m.toml");
    std::fs::write(&path, model).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    let data = |csv: &str| -> Vec<(f64, f64)> {
        csv.lines()
            .skip(1)
            .map(|l| {
                let (t, x) = l.split_once(',').unwrap();
                (t.parse().unwrap(), x.parse().unwrap())
            })
            .collect()
    };
    let cost = |b: f64| {
        let mut eps = 0.0;
        for (a_pre, a, csv) in [(1.0, 4.0, low), (1.0, 3.0, high), (2.0, 4.0, low)] {
            for (t, x) in data(csv) {
                let xm: f64 = a / b + (a_pre - a) / b * (-b * t).exp();
                eps += (x - xm) * (x - xm);
            }
        }
        eps
    };
    for b in [2.0, 1.5, 2.0] {
        let z = problem.unknowns().coordinates(&[b]);
        let got = problem.linearize(&z).unwrap().cost;
        assert!((got - cost(b)).abs() <= 1e-8, "b = {b}: {got} vs {}", cost(b));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A steady state's derivatives settle after the state does. x' = e·(a − x) from x₀ = 2
/// settles at x = a, so ∂x/∂a = 1 there; at a = 2 the state is steady from the start while
/// its sensitivity s' = e·(1 − s), s(0) = 0, takes t ≈ ln(e/rtol)/e to settle. The experiment
/// holds x (e = 0), so ε = Σ(a − dᵢ)² and its half-gradient U = Σ(a − dᵢ).
///
/// Alone, x's Jacobian −e is nonsingular and stable: the state settles, one Newton step
/// lands on a, and ∂x/∂a = −J⁻¹·∂f/∂a = 1 without integrating it, at any tolerance. With a
/// conserved pair beside it (A ⇌ B, not measured) the Jacobian is singular and the
/// sensitivities are integrated until they settle; that steady state follows the problem's
/// tolerances: at the model file's rtol 1e-3 it stops at t = 10 with x 2e-5 short of a, and
/// `with_integrator` at rtol 1e-10 gives the closed form to 1e-9.
#[test]
fn a_steady_states_derivatives_settle_after_it_does() {
    let alone = "states = [\"x\"]
parameters = [\"a\", \"e\"]
[equations]
x = \"e * (a - x)\"
[initial]
x = 2.0
[unknowns]
a = 2.0
[[experiments]]
name = \"held\"
file = \"low.csv\"
set = { e = 0.0 }
preequilibrate = { e = EPS }
[integrator]
method = \"rodas5p\"
rtol = RTOL
atol = 1e-12
";
    let conserved = alone
        .replace("states = [\"x\"]", "states = [\"x\", \"A\", \"B\"]")
        .replace("x = \"e * (a - x)\"", "x = \"e * (a - x)\"\nA = \"B - A\"\nB = \"A - B\"")
        .replace("x = 2.0", "x = 2.0\nA = 1.0\nB = 0.0");
    let data = "t,x\n1,2.1\n2,2.3\n3,2.2\n";
    let dir = scratch("steady-derivatives", data, data);
    let path = dir.join("m.toml");
    let closed = |a: f64| {
        let d = [2.1, 2.3, 2.2];
        (d.iter().map(|d| (a - d) * (a - d)).sum::<f64>(), d.iter().map(|d| a - d).sum::<f64>())
    };
    for model in [alone, conserved.as_str()] {
        for eps in ["0.01", "1.0"] {
            std::fs::write(&path, model.replace("EPS", eps).replace("RTOL", "1e-10")).unwrap();
            let problem = Model::load(&path).unwrap().problem(None).unwrap();
            for a in [2.0, 2.5] {
                let lin = problem.linearize(&problem.unknowns().coordinates(&[a])).unwrap();
                let (cost, gradient) = closed(a);
                // The state settles to rtol/e (1e-8 at e = 0.01), its derivative to e^{-e·t}.
                assert!(
                    (lin.cost - cost).abs() <= 1e-7,
                    "e {eps}, a {a}: ε {} vs {cost}",
                    lin.cost
                );
                assert!(
                    (lin.gradient[0] - gradient).abs() <= 1e-7,
                    "e {eps}, a {a}: U {} vs {gradient}",
                    lin.gradient[0]
                );
            }
        }
    }
    let (cost, _) = closed(2.5);
    let gaps = |model: &str| {
        std::fs::write(&path, model.replace("EPS", "1.0").replace("RTOL", "1e-3")).unwrap();
        let loose = Model::load(&path).unwrap().problem(None).unwrap();
        let z = loose.unknowns().coordinates(&[2.5]);
        let mut tight = *loose.integrator();
        (tight.rtol, tight.atol) = (1e-10, 1e-12);
        let tight = loose.clone().with_integrator(tight).unwrap();
        let gap = |p: &sysid_core::Problem<_>| (p.linearize(&z).unwrap().cost - cost).abs();
        (gap(&loose), gap(&tight))
    };
    let (loose, tight) = gaps(alone);
    assert!(loose <= 1e-9 && tight <= 1e-9, "alone: {loose} and {tight} from the closed form");
    let (loose, tight) = gaps(&conserved);
    assert!(loose > 1e-5, "the loose steady state is {loose} from the closed form");
    assert!(tight <= 1e-9, "the tight steady state is {tight} from the closed form");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `steady = true`: the experiment starts from the steady state under its own settings,
/// after its preequilibration if it has one (PEtab's measurement at time `inf`). x' = p − o·x
/// − k·x, y' = k·x keeps x + y while p = o = 0: preequilibrated with k = 0, x settles at p/o
/// = 3 and y stays 0.5, and the experiment's own steady state is y = p/o + 0.5 = 3.5; without
/// the preequilibration it is y = x₀ + y₀ = 1.5. The cost and its gradient (∂y/∂p = 1/o) in
/// closed form.
#[test]
fn a_steady_experiment_starts_from_its_own_steady_state() {
    let model = "states = [\"x\", \"y\"]
parameters = [\"p\", \"o\", \"k\"]
[equations]
x = \"p - o * x - k * x\"
y = \"k * x\"
[initial]
x = 1.0
y = 0.5
[known]
o = 1.0
k = 1.0
[unknowns]
p = 3.0
[[experiments]]
name = \"after\"
file = \"low.csv\"
set = { p = 0.0, o = 0.0 }
preequilibrate = { k = 0.0 }
steady = true
[[experiments]]
name = \"alone\"
file = \"high.csv\"
set = { p = 0.0, o = 0.0 }
steady = true
[integrator]
method = \"rodas5p\"
rtol = 1e-10
atol = 1e-12
";
    let dir = scratch("steady", "t,y\n0,3.4\n", "t,y\n0,1.45\n");
    let path = dir.join("m.toml");
    std::fs::write(&path, model).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).unwrap();
    // ε = (3.4 − (p + 0.5))² + (1.45 − 1.5)², U = ½ dε/dp = −(3.4 − 3.5) = 0.1.
    assert!((lin.cost - 0.0125).abs() <= 1e-9, "{}", lin.cost);
    assert!((lin.gradient[0] - 0.1).abs() <= 1e-8, "{}", lin.gradient[0]);
    let steady = |extra: &str| format!("{TWO}steady = {extra}\n");
    let e = problem_error(&dir, &steady("1"));
    assert!(e.contains("experiment `high`: steady must be true or false"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `initial` in an experiment: its own initial values. x' = a − b·x with x(0) = 2 in one
/// experiment (x = a/b + (2 − a/b)e^{−bt}), and in another, after a preequilibration that
/// settles x at 1/b with a = 1, x restarts at the unknown `c` (PEtab's re-initialisation):
/// x = 4/b + (c − 4/b)e^{−bt}. Cost and gradient in closed form, the gradient by central
/// differences of it.
#[test]
fn an_experiment_sets_its_own_initial_values() {
    let model = "states = [\"x\"]
parameters = [\"a\", \"b\"]
[equations]
x = \"a - b * x\"
[initial]
x = 0.0
[known]
a = 4.0
[unknowns]
b = 2.0
c = 3.0
[[experiments]]
name = \"low\"
file = \"low.csv\"
initial = { x = 2.0 }
[[experiments]]
name = \"high\"
file = \"high.csv\"
preequilibrate = { a = 1.0 }
initial = { x = \"c\" }
[integrator]
method = \"rodas5p\"
rtol = 1e-11
atol = 1e-13
";
    let low = [(0.5, 1.9), (1.0, 2.05)];
    let high = [(0.5, 2.4), (2.0, 2.1)];
    let to_csv = |rows: &[(f64, f64)]| {
        rows.iter().fold(String::from("t,x\n"), |s, (t, x)| format!("{s}{t},{x}\n"))
    };
    let dir = scratch("initial", &to_csv(&low), &to_csv(&high));
    let path = dir.join("m.toml");
    std::fs::write(&path, model).unwrap();
    let problem = Model::load(&path).unwrap().problem(None).unwrap();
    let cost = |b: f64, c: f64| {
        let low_x = |t: f64| 4.0 / b + (2.0 - 4.0 / b) * (-b * t).exp();
        let high_x = |t: f64| 4.0 / b + (c - 4.0 / b) * (-b * t).exp();
        let low_eps: f64 = low.iter().map(|(t, x)| (x - low_x(*t)).powi(2)).sum();
        low_eps + high.iter().map(|(t, x)| (x - high_x(*t)).powi(2)).sum::<f64>()
    };
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).unwrap();
    assert!((lin.cost - cost(2.0, 3.0)).abs() <= 1e-9, "{} vs {}", lin.cost, cost(2.0, 3.0));
    let h = 1e-6;
    let fd = [
        (cost(2.0 + h, 3.0) - cost(2.0 - h, 3.0)) / (2.0 * h),
        (cost(2.0, 3.0 + h) - cost(2.0, 3.0 - h)) / (2.0 * h),
    ];
    for (j, d) in fd.iter().enumerate() {
        assert!(
            (lin.gradient[j] - 0.5 * d).abs() <= 1e-7,
            "{j}: {} vs {}",
            lin.gradient[j],
            d / 2.0
        );
    }
    let e = problem_error(&dir, &format!("{TWO}initial = {{ zz = 1.0 }}\n"));
    assert!(e.contains("experiment `high`: initial `zz`: not a state (states: "), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A switch in time in the equations, at a parameter: the integrators stop on it, each side
/// taking its own branch, so x' = if(lt(t, c), 1, 0) integrates to exactly c (DOPRI5 and
/// Rodas4; without the stop the step at the switch straddles it).
#[test]
fn integrators_stop_at_a_switch_in_time() {
    use sysid_ode::{Integrator, Ivp, Scheme};
    let model = "states = [\"x\"]
parameters = [\"c\"]
[equations]
x = \"if(lt(t - c, 0), 1, 0) + 0 * x\"
[initial]
x = 0.0
[unknowns]
c = 1.37
[data]
file = \"unused.csv\"
";
    let file = ModelFile::parse(model, Path::new("switch.toml")).unwrap();
    let system = Model { file }.system(Default::default());
    for scheme in [Scheme::Dopri5, Scheme::Rodas4] {
        let integrator = Integrator { scheme, ..Integrator::default() };
        let x = Ivp::new(&system, 0.0, &[0.0], &[1.37]).solve(&integrator, &[3.0]).unwrap();
        assert!((x.state(0)[0] - 1.37).abs() <= 1e-13, "{scheme:?}: {}", x.state(0)[0]);
    }
}

/// `preequilibrate` names parameters, as `set` does, and needs a model without inputs.
#[test]
fn preequilibrate_is_checked_like_set() {
    let with = |extra: &str| format!("{TWO}preequilibrate = {{ {extra} }}\n");
    refused(
        &with("zz = 1.0"),
        "m.toml:24:20: experiment `high`: preequilibrate `zz`: not a parameter (parameters: k, dose, scale)",
    );
    let inputs = TWO.replace("parameters = [", "inputs = [\"u\"]\nparameters = [");
    refused(
        &format!("{inputs}preequilibrate = {{ dose = 1.0 }}\n"),
        "m.toml:25:18: experiment `high`: preequilibrate: a model with inputs has no steady state to run to",
    );
}

/// A σ that is not positive at the start is refused, naming the output, the experiment and
/// the time: with a σ of the model's values (found along the trajectory) and with a σ of the
/// unknowns alone (evaluated without integrating).
#[test]
fn a_sigma_that_is_not_positive_at_the_start_is_refused() {
    let dir = scratch("sigma", LOW, HIGH);
    for (sigma, what) in [("s * (Bm - 10)", "Bm"), ("s * c", "Bm")] {
        let mut model = TWO.replace("sigma = \"s\"", &format!("sigma = \"{sigma}\""));
        if sigma.contains('c') {
            model = model.replace(
                "s = { guess = 0.1, log = true }",
                "s = { guess = 0.1, log = true }\nc = -2.0",
            );
        }
        let message = problem_error(&dir, &model);
        assert!(
            message.contains(&format!("the σ of `{what}`, {sigma}, is "))
                && message.contains("in experiment `low` at the start: σ must be positive"),
            "{message}"
        );
    }
    // Below the likelihood's floor e^-25 it is refused the same way, where it is written (it
    // was refused as "the starting guess cannot be used", with no file, line or experiment).
    let model = TWO.replace("sigma = \"s\"", "sigma = \"1e-13 * s\"");
    let message = problem_error(&dir, &model);
    assert!(
        message.contains("the σ of `Bm`, 1e-13 * s, is 1.0000000000000002e-14 at t = 1 ")
            && message.contains("in experiment `low` at the start: σ must be at least e^-25"),
        "{message}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
