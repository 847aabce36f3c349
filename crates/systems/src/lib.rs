//! # sysid-systems: the benchmark catalogue
//!
//! Every system is written once in Rust (generic over the scalar, so sensitivities come from
//! dual numbers), with its data, unknowns, default start and, where one exists, the answer a
//! fit must reproduce. Tests, benchmarks, studies and the command line all use this
//! catalogue.
//!
//! | name | model | measured | unknowns from |
//! |---|---|---|---|
//! | `falling-body` | y' = v, v' = g | y at t = 0..3, Goodman's Table I | (0, 0, 32); answer (−0.25, −0.25, 32.5), ε = 1.25 |
//! | `falling-body-continuous` | same | record 16.25t² − 0.25t − 0.25 + 0.5 sin 5t on [0, 3] | (0, 0, 32) |
//! | `van-der-pol` | x' = v, v' = −x + μ(1−x²)v | x every 0.2 on [0, 20], σ = 0.05 | μ, x, v from (1.5, 1.5, 0.5) |
//! | `lotka-volterra` | x' = ax − bxy, y' = dxy − gy | x, y every 0.1 on [0, 10], σ = 0.1 | a, b, g, d from (1.2, 0.8, 2.5, 0.8) |
//! | `fitzhugh-nagumo` | V' = c(V − V³/3 + R), R' = −(V − a + bR)/c | V, R every 0.05 on [0, 20], σ = 0.05 | a, b, c from (0.3, 0.3, 2.5) |
//! | `short-period` | α' = Zα α + q + Zδ δe, q' = Mα α + Mq q + Mδ δe | α (σ = 0.002), q (σ = 0.005) every 0.05 on [0, 10] | from (−1, −3, −1, −0.1, −6) |
//! | `van-der-pol-three-point` | van der Pol, t0 = 4 | x at t = 4, 6, 8 (no noise) | x, v, μ from (−1.5, 0.3, 1.5); ε = 0 |
//! | `robertson` (stiff) | y1' = −k1y1 + k3y2y3, y2' = k1y1 − k2y2² − k3y2y3, y3' = k2y2² | y1, y3 at 20 log-spaced t in [0.01, 100], 1 % relative noise | log k1, k2, k3 from truth + 0.3 decades |
//! | `compartment-chain` (bounded) | x1' = −(k1 + d1)x1, x_i' = k_{i−1}x_{i−1} − (k_i + d_i)x_i, x8' = k7x7 − d8x8 | all 8 states at t = 0..29, σ = 100, unweighted | 7 transfer and 8 loss rates ≥ 0, 8 initial values ≥ 0, 30 % off the truth; d1 = 0 on its bound at the optimum |
//!
//! Synthetic data are the truth integrated with rtol 1e-12 plus Gaussian noise drawn from
//! ChaCha8 seeded by the seed, series after series: the same data on every machine; each
//! noisy series is weighted by 1/σ² (Goodman's eq. 32), each sample by 1/σ_m² where the
//! noise is relative (σ_m = σ·|y(t_m)|). The stiff case's truth is integrated by Rodas4.
//!
//! A caller that works with any system implements [`Visit`] and calls [`visit`] with a name:
//!
//! ```
//! use sysid_ode::System;
//! use sysid_systems::{Case, Visit, visit};
//! struct CountStates;
//! impl Visit for CountStates {
//!     type Output = usize;
//!     fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> usize {
//!         case.system.signature().n_states()
//!     }
//! }
//! assert_eq!(visit("falling-body", CountStates), Some(2));
//! ```
#![warn(missing_docs)]

mod case;
pub mod compartment_chain;
pub mod falling_body;
pub mod fitzhugh_nagumo;
pub mod lotka_volterra;
pub mod robertson;
pub mod short_period;
pub mod stress;
pub mod van_der_pol;

pub use case::{Case, DataSource, Noise, Reference, grid, truth_integrator};
pub use compartment_chain::Chain;
pub use falling_body::FallingBody;
pub use fitzhugh_nagumo::FitzHughNagumo;
pub use lotka_volterra::LotkaVolterra;
pub use robertson::Robertson;
pub use short_period::ShortPeriod;
pub use van_der_pol::VanDerPol;

use sysid_ode::System;

/// Something to do with a catalogue case of any system type.
pub trait Visit {
    /// What it produces.
    type Output;
    /// Does it.
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output;
}

macro_rules! catalogue {
    ($($name:literal => $case:path),* $(,)?) => {
        /// Names of the catalogue systems, in catalogue order.
        pub const NAMES: &[&str] = &[$($name),*];

        /// Calls `visitor` with the case named `name`, or returns `None` if there is none.
        pub fn visit<V: Visit>(name: &str, visitor: V) -> Option<V::Output> {
            match name {
                $($name => Some(visitor.visit($case())),)*
                _ => None,
            }
        }
    };
}

catalogue! {
    "falling-body" => falling_body::falling_body,
    "falling-body-continuous" => falling_body::falling_body_continuous,
    "van-der-pol" => van_der_pol::van_der_pol,
    "lotka-volterra" => lotka_volterra::lotka_volterra,
    "fitzhugh-nagumo" => fitzhugh_nagumo::fitzhugh_nagumo,
    "short-period" => short_period::short_period,
    "van-der-pol-three-point" => van_der_pol::van_der_pol_three_point,
    "robertson" => robertson::robertson,
    "compartment-chain" => compartment_chain::compartment_chain,
}

/// The one-line summary of each catalogue system, in catalogue order.
pub fn summaries() -> Vec<(&'static str, &'static str)> {
    struct Summary;
    impl Visit for Summary {
        type Output = (&'static str, &'static str);
        fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
            (case.name, case.summary)
        }
    }
    NAMES.iter().filter_map(|n| visit(n, Summary)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_builds_its_problem_and_names_agree() {
        struct Build;
        impl Visit for Build {
            type Output = &'static str;
            fn visit<S: System + Clone + Send + Sync + 'static>(
                self,
                case: Case<S>,
            ) -> &'static str {
                case.problem(1).unwrap_or_else(|e| panic!("{}: {e}", case.name));
                case.name
            }
        }
        for name in NAMES {
            assert_eq!(visit(name, Build), Some(*name));
        }
        assert_eq!(summaries().len(), NAMES.len());
        assert!(visit("no-such-system", Build).is_none());
    }
}
