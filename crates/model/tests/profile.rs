//! Hierarchical optimisation's pieces against independent references, on a model whose
//! outputs are linear in its unknowns (x' = a, x(0) = b; X = x with σ = s1, Z = 2x + c·a with
//! σ = s2; two experiments, c = 1 and 3; a normal prior on a), so that the Gauss–Newton model
//! is exact and the profile's curvature can be checked by differences:
//!
//! * the scales' closed form from a linearization's residuals against the one from an
//!   integration;
//! * a linearization re-weighted to other scales against a fresh one there;
//! * the profile's model matrix A − Σ 2U_gU_gᵀ/n_g against central second differences of
//!   twice the profile NLL, 2·NLL(z, ŝ(z));
//! * the gain of moving the scales to a trial's closed form against two NLLs.

use std::path::PathBuf;

use nalgebra::DMatrix;
use sysid_model::Model;

const MODEL: &str = "states = [\"x\"]
parameters = [\"a\", \"b\", \"c\"]
[equations]
x = \"a\"
[initial]
x = \"b\"
[outputs]
X = { value = \"x\", sigma = \"s1\" }
Z = { value = \"2 * x + c * a\", sigma = \"s2\" }
[unknowns]
a = { guess = 0.8, prior = { mean = 1.0, sd = 0.5 } }
b = 0.3
s1 = { guess = 0.2, log = true }
s2 = { guess = 2.0, log = true }
[[experiments]]
name = \"one\"
file = \"one.csv\"
set = { c = 1.0 }
[[experiments]]
name = \"two\"
file = \"two.csv\"
set = { c = 3.0 }
[integrator]
rtol = 1e-12
atol = 1e-14
";

const ONE: &str = "t,X,Z\n0,0.25,1.4\n1,1.3,3.1\n2,2.2,5.3\n3,3.4,7.0\n4,4.1,9.6\n";
const TWO: &str = "t,X,Z\n0.5,0.8,4.2\n1.5,1.9,6.8\n2.5,2.6,8.1\n3.5,3.9,11.4\n";

fn scratch() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sysid-model-profile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("one.csv"), ONE).unwrap();
    std::fs::write(dir.join("two.csv"), TWO).unwrap();
    std::fs::write(dir.join("m.toml"), MODEL).unwrap();
    dir
}

#[track_caller]
fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol * b.abs().max(1.0), "{what}: {a} against {b}");
}

#[track_caller]
fn close_matrix(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64, what: &str) {
    let scale = b.amax().max(1.0);
    assert!((a - b).amax() <= tol * scale, "{what}:\n{a}against\n{b}");
}

#[test]
fn the_profile_pieces_match_their_references() {
    let dir = scratch();
    let problem = Model::load(&dir.join("m.toml")).unwrap().problem(None).unwrap();
    assert_eq!(problem.names(), ["a", "b"]);
    assert_eq!(problem.scales().len(), 2);
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).unwrap();

    // The closed form from the residuals is the one from an integration.
    let sigma = problem.scales_at(&lin).unwrap();
    let integrated = problem.optimal_scales(&problem.unknowns().values(&z)).unwrap();
    for (s, i) in sigma.iter().zip(&integrated) {
        close(*s, *i, 1e-12, "closed form");
    }
    assert!((sigma[0] / 0.2 - 1.0).abs() > 0.1 && (sigma[1] / 2.0 - 1.0).abs() > 0.1, "{sigma:?}");

    // Re-weighted to those scales, the linearization is a fresh one there.
    let held = problem.with_scales(&sigma);
    let fresh = held.linearize(&z).unwrap();
    let moved = problem.reweighed(&lin, &sigma);
    close(moved.cost, fresh.cost, 1e-12, "ε");
    close(moved.norm, fresh.norm, 1e-12, "‖r‖");
    assert_eq!(moved.experiment_costs.len(), 3, "two experiments and the priors");
    for (m, f) in moved.experiment_costs.iter().zip(&fresh.experiment_costs) {
        close(*m, *f, 1e-12, "an experiment's ε");
    }
    for (m, f) in moved.gradient.iter().zip(&fresh.gradient) {
        close(*m, *f, 1e-12, "U");
    }
    close_matrix(&moved.normal, &fresh.normal, 1e-12, "A");
    let (mr, fr) = (moved.residuals.as_ref().unwrap(), fresh.residuals.as_ref().unwrap());
    close_matrix(&mr.jacobian, &fr.jacobian, 1e-12, "J");
    assert!((&mr.r - &fr.r).amax() <= 1e-12 * fr.r.amax());

    // Twice the profile NLL (the prior's term included, as A holds its row), and its
    // curvature by central second differences (the model is linear: A is exact, and the
    // differences err by O(h²) through the logarithms).
    let profile = |z: &[f64]| {
        let s = problem.optimal_scales(&problem.unknowns().values(z)).unwrap();
        let at = problem.with_scales(&s);
        2.0 * (at.nll_at(z).unwrap().unwrap() + at.prior_nll_at(z).unwrap())
    };
    let h = 1e-4;
    let mut hessian = DMatrix::zeros(2, 2);
    for i in 0..2 {
        for j in 0..2 {
            let at = |di: f64, dj: f64| {
                let mut p = z.clone();
                p[i] += di;
                p[j] += dj;
                profile(&p)
            };
            hessian[(i, j)] = (at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4.0 * h * h);
        }
    }
    let curvature = held.profile_curvature(&fresh).unwrap();
    let model = (&fresh.normal - &curvature) * 2.0;
    close_matrix(&hessian, &model, 1e-6, "the profile's curvature");
    // Without the scales' part the model is far off: the check can fail.
    assert!((&hessian - &fresh.normal * 2.0).amax() > 1e-2 * hessian.amax());
    // Its slope is 2U at the closed form (the scales' own slope vanishes there).
    for i in 0..2 {
        let (mut up, mut down) = (z.clone(), z.clone());
        up[i] += h;
        down[i] -= h;
        close((profile(&up) - profile(&down)) / (2.0 * h), 2.0 * fresh.gradient[i], 1e-6, "slope");
    }

    // At a trial point evaluated at the first scales, the gain of moving them to the
    // trial's closed form is the fall of twice the NLL.
    let trial = [z[0] + 0.2, z[1] - 0.1];
    let at_trial = problem.linearize(&trial).unwrap();
    let closed = problem.scales_at(&at_trial).unwrap();
    let nll = |p: &sysid_core::Problem<_>| p.nll_at(&trial).unwrap().unwrap();
    let fall = 2.0 * (nll(&problem) - nll(&problem.with_scales(&closed)));
    assert!(fall > 1.0, "the scales move: {fall}");
    close(problem.profile_gain(&at_trial), fall, 1e-10, "the gain");
    let _ = std::fs::remove_dir_all(&dir);
}
