//! Geodesic acceleration against its closed form: for y′ = −k·y with y(0) = y0 unknown, the
//! residuals r_m = y0·e^{−k t_m} − b_m have the second derivatives ∂²r/∂k² = y0 t² e^{−kt},
//! ∂²r/∂k∂y0 = −t e^{−kt}, ∂²r/∂y0² = 0, so the acceleration a = −(A + λD²)⁻¹ Jᵀ r″ of a step
//! v is known exactly; the method's one-sided difference with h = 0.1 differs from it by the
//! third-order term, O(h‖v‖) relative.

use nalgebra::{DMatrix, DVector};
use sysid::core::{
    Problem,
    method::{Accelerated, Curve, Evaluations, Geodesic},
};
use sysid::model::{Model, ModelSystem};

const TIMES: [f64; 6] = [0.0, 0.5, 1.0, 2.0, 3.0, 5.0];

/// Decay data from k = 0.7, y0 = 2 with a misfit of a few percent, fitted from k = 1.2,
/// y0 = 1.5 (linear scales: the coordinates are the values).
fn decay() -> Problem<ModelSystem> {
    let dir = std::env::temp_dir().join(format!("sysid-geodesic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut data = String::from("t,y\n");
    for (i, t) in TIMES.iter().enumerate() {
        let wobble = if i % 2 == 0 { 1.03 } else { 0.97 };
        data += &format!("{t},{}\n", 2.0 * (-0.7 * t).exp() * wobble);
    }
    std::fs::write(dir.join("data.csv"), data).unwrap();
    let model = r#"
states = ["y"]
parameters = ["k"]
[equations]
y = "-k * y"
[unknowns]
k = 1.2
y = 1.5
[data]
file = "data.csv"
[integrator]
rtol = 1e-10
atol = 1e-14
"#;
    std::fs::write(dir.join("model.toml"), model).unwrap();
    Model::load(&dir.join("model.toml")).unwrap_or_else(|e| panic!("{e}")).problem(None).unwrap()
}

#[test]
fn the_acceleration_is_the_residuals_second_derivative_along_the_step() {
    let problem = decay();
    let names = problem.names();
    let at = |name: &str| names.iter().position(|n| n == name).unwrap();
    let (ik, iy) = (at("k"), at("y"));
    let ev = Evaluations::new(&problem, 1_000);
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = ev.linearize(&z).unwrap();
    let mut curve = Curve::default();
    curve.rescale(&lin);
    for radius in [0.05, 0.2] {
        let v = curve.within(&problem, &lin, radius * curve.scaled_norm(&z), 1e12).unwrap();
        assert!(v.lambda > 0.0, "a damped step");
        let Accelerated::Step(step) =
            Geodesic::default().accelerate(&ev, &lin, &curve, &v, 1e12).unwrap()
        else {
            panic!("an accelerated step at radius {radius}");
        };
        // The exact r″ along v, weights 1 (no weights given).
        let (k, y0) = (z[ik], z[iy]);
        let (vk, vy) = (v.delta[ik], v.delta[iy]);
        let second = DVector::from_iterator(
            TIMES.len(),
            TIMES.iter().map(|t| {
                let e = (-k * t).exp();
                y0 * t * t * e * vk * vk - 2.0 * t * e * vk * vy
            }),
        );
        let rows = lin.residuals.as_ref().unwrap();
        let mut h: DMatrix<f64> = lin.normal.clone();
        for i in 0..2 {
            h[(i, i)] += v.lambda * curve.scale[i] * curve.scale[i];
        }
        let a = -h.lu().solve(&rows.jacobian.tr_mul(&second)).unwrap();
        let expected = &v.delta + &a * 0.5;
        let bent = &step.delta - &v.delta;
        // The bend is the acceleration's half, to within the difference's O(h‖v‖) error
        // (relative to the bend).
        let error = (&step.delta - &expected).norm() / (0.5 * a.norm());
        assert!(bent.norm() > 1e-3 * v.delta.norm(), "a bend to test: {bent}");
        // Measured: 0.042‖v‖ and 0.044‖v‖ at the two radii, linear in ‖v‖ as the third-order
        // term is; a wrong factor or sign in r″ would make it of order 1.
        assert!(error < 0.06 * v.delta.norm(), "radius {radius}: error {error:e}");
        assert!(step.predicted > 0.0 && step.predicted.is_finite());
    }
}
