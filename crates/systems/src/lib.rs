//! # sysid-systems: the benchmark catalogue
//!
//! Every system is written once in Rust (generic over the scalar, so sensitivities come from
//! dual numbers), with its data, unknowns, default start and, where one exists, the answer a
//! fit must reproduce. Tests, benchmarks, studies and the command line all use this
//! catalogue.
//!
//! | name | what |
//! |---|---|
//! | `falling-body` | Goodman 1966, Section IV, Table I: answer (−0.25, −0.25, 32.5), ε = 1.25 |
//! | `falling-body-continuous` | the continuous case on [0, 3] |
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
pub mod falling_body;
mod van_der_pol;

pub use case::{Case, Reference};
pub use falling_body::FallingBody;
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
