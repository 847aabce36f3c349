//! Laplace noise (`distribution = "laplace"`): the negative log-likelihood
//! Σ ln(2b) + |T(h) − T(m)|/b and its gradient against closed forms, with the scale b known
//! and as an unknown.

use std::path::{Path, PathBuf};

use sysid_model::Model;

const TIMES: [f64; 5] = [0.5, 1.0, 2.0, 3.0, 4.0];
const MEASURED: [f64; 5] = [1.3, 0.9, 0.55, 0.25, 0.18];

/// x' = −k x, x(0) = 2, measured as y = x with Laplace noise of scale `sigma`; the unknowns
/// `unknowns`. Written with its data into a directory of its own.
fn model(name: &str, sigma: &str, unknowns: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sysid-laplace-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a directory");
    let mut csv = String::from("t,y\n");
    for (t, m) in TIMES.iter().zip(MEASURED) {
        csv += &format!("{t},{m}\n");
    }
    std::fs::write(dir.join("data.csv"), csv).expect("written");
    let text = format!(
        "states = [\"x\"]\nparameters = [\"k\"]\n[equations]\nx = \"-k * x\"\n[initial]\nx = 2.0\n\
         [outputs]\ny = {{ value = \"x\", sigma = {sigma}, distribution = \"laplace\" }}\n\
         [unknowns]\n{unknowns}\n[data]\nfile = \"data.csv\"\n[integrator]\nrtol = 1e-12\natol = 1e-14\n"
    );
    let path = dir.join("m.toml");
    std::fs::write(&path, text).expect("written");
    path
}

/// The closed form at (k, b): the NLL, ∂NLL/∂k and ∂NLL/∂b.
fn closed_form(k: f64, b: f64) -> (f64, f64, f64) {
    let (mut nll, mut dk, mut db) = (0.0, 0.0, 0.0);
    for (&t, m) in TIMES.iter().zip(MEASURED) {
        let x = 2.0 * (-k * t).exp();
        let d = x - m;
        nll += (2.0 * b).ln() + d.abs() / b;
        dk += d.signum() * (-t * x) / b;
        db += 1.0 / b - d.abs() / (b * b);
    }
    (nll, dk, db)
}

/// The NLL and its gradient at the unknowns' guesses.
fn at_guess(path: &Path) -> (f64, Vec<f64>) {
    let problem = Model::load(path).and_then(|m| m.problem(None)).unwrap_or_else(|e| panic!("{e}"));
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).expect("integrates");
    (problem.nll(&lin).expect("a likelihood"), lin.gradient.as_slice().to_vec())
}

/// b = 0.3 known: the NLL and ∂NLL/∂k to 1e-9 relative.
#[test]
fn laplace_noise_of_a_known_scale_is_its_absolute_deviation() {
    let path = model("known", "0.3", "k = 0.6");
    let (nll, gradient) = at_guess(&path);
    let (expected, dk, _) = closed_form(0.6, 0.3);
    assert!((nll - expected).abs() <= 1e-9 * expected.abs(), "NLL {nll} vs {expected}");
    assert!((gradient[0] - dk).abs() <= 1e-9 * dk.abs(), "{gradient:?} vs {dk}");
    let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
}

/// b an unknown: ln(2b) enters through the noise rows; ∂NLL/∂b = Σ 1/b − |d|/b².
#[test]
fn laplace_noise_of_an_unknown_scale_has_its_gradient() {
    let path = model("unknown", "\"b\"", "k = 0.6\nb = { guess = 0.25, min = 0.001 }");
    let (nll, gradient) = at_guess(&path);
    let (expected, dk, db) = closed_form(0.6, 0.25);
    assert!((nll - expected).abs() <= 1e-9 * expected.abs(), "NLL {nll} vs {expected}");
    assert!((gradient[0] - dk).abs() <= 1e-9 * dk.abs(), "{gradient:?} vs {dk}");
    assert!((gradient[1] - db).abs() <= 1e-9 * db.abs(), "{gradient:?} vs {db}");
    let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
}
