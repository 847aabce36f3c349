//! The order conditions of Rosenbrock methods up to order four (Hairer & Wanner, Solving
//! ODE II, Table IV.7.1), checked against a scheme's coefficients in the transformed form
//! the code uses (a, c, and the weights m of x_new = x + Σ m_j k_j): the conditions are
//! stated for the original coefficients (α, Γ, b), recovered from them first. A mistyped
//! digit fails these. Conditions of order five are checked by the observed order instead
//! (crates/ode/tests/stiff.rs).

use nalgebra::{DMatrix, DVector};

/// A Rosenbrock scheme's coefficients as its code uses them: a_ij and c_ij (strictly lower
/// triangular, s × s), the weights m, and γ, the nodes c_i and the d_i.
pub(crate) struct Transformed {
    pub(crate) gamma: f64,
    pub(crate) a: DMatrix<f64>,
    pub(crate) c: DMatrix<f64>,
    pub(crate) m: DVector<f64>,
    pub(crate) nodes: Vec<f64>,
    pub(crate) d: Vec<f64>,
}

/// Asserts the conditions of orders one to four, and that the nodes and the d_i are the row
/// sums of α and Γ.
pub(crate) fn assert_order_four(t: &Transformed) {
    let s = t.a.nrows();
    let g = t.gamma;
    // C = diag(1/γ) − Γ⁻¹, A = α Γ⁻¹, m = Γᵀ⁻¹ b.
    let gamma_inv = DMatrix::from_diagonal_element(s, s, 1.0 / g) - &t.c;
    let gamma_m = gamma_inv.try_inverse().expect("Γ is invertible");
    let alpha = &t.a * &gamma_m;
    let b = gamma_m.transpose() * &t.m;
    // B' = β − γI = α + Γ − γI, strictly lower triangular.
    let bl = &alpha + &gamma_m - DMatrix::from_diagonal_element(s, s, g);
    let one = DVector::repeat(s, 1.0);
    let ai = &alpha * &one;
    let bi = &bl * &one;
    let sq = ai.component_mul(&ai);
    let checks = [
        ("b·1", b.sum(), 1.0),
        ("b·B'1", b.dot(&bi), 0.5 - g),
        ("b·(α1)²", b.dot(&sq), 1.0 / 3.0),
        ("b·B'B'1", b.dot(&(&bl * &bi)), 1.0 / 6.0 - g + g * g),
        ("b·(α1)³", b.dot(&sq.component_mul(&ai)), 0.25),
        ("b·(α1)(αB'1)", b.dot(&ai.component_mul(&(&alpha * &bi))), 1.0 / 8.0 - g / 3.0),
        ("b·B'(α1)²", b.dot(&(&bl * &sq)), 1.0 / 12.0 - g / 3.0),
        ("b·B'B'B'1", b.dot(&(&bl * &bl * &bi)), 1.0 / 24.0 - g / 2.0 + 1.5 * g * g - g * g * g),
    ];
    for (name, lhs, rhs) in checks {
        assert!((lhs - rhs).abs() < 1e-12, "order condition {name}: {lhs} vs {rhs}");
    }
    for (ci, x) in t.nodes.iter().zip(ai.iter()) {
        assert!((ci - x).abs() < 1e-12, "c {ci} vs α row sum {x}");
    }
    for (di, x) in t.d.iter().zip((&gamma_m * &one).iter()) {
        assert!((di - x).abs() < 1e-12, "d {di} vs Γ row sum {x}");
    }
}
