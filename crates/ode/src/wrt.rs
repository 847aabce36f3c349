//! The columns of a sensitivity matrix: what each is a derivative with respect to, and its
//! name. Its own module because both the sensitivity right-hand side (`ivp`) and the implicit
//! solve (`implicit`) seed dual numbers by column, and neither should import the other.

use crate::system::Signature;

/// What one sensitivity column is a derivative with respect to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wrt {
    /// The initial value y_i(t0) of state i: S(t0) = e_i, dS/dt = J_y S.
    InitialValue(usize),
    /// Parameter α_k: S(t0) = 0, dS/dt = J_y S + ∂g/∂α_k (Goodman's eq. 4 treats it as a
    /// state with zero derivative; the forcing term is the same thing written out).
    Parameter(usize),
}

/// The name of a sensitivity column: a parameter's name, or `y(t0)` for an initial value.
pub fn wrt_name(sig: &Signature, wrt: Wrt) -> String {
    match wrt {
        Wrt::InitialValue(i) => format!("{}(t0)", sig.states()[i]),
        Wrt::Parameter(k) => sig.parameters()[k].clone(),
    }
}

/// The n_α × k unit seeds of the parameter columns, row by row.
pub(crate) fn parameter_seeds(np: usize, wrt: &[Wrt]) -> Vec<f64> {
    let k = wrt.len();
    let mut seeds = vec![0.0; np * k];
    for (j, w) in wrt.iter().enumerate() {
        if let Wrt::Parameter(q) = *w {
            seeds[q * k + j] = 1.0;
        }
    }
    seeds
}
