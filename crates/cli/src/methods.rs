//! The methods the command line offers, by name.

use sysid_core::Method;
use sysid_goodman::{Goodman, GoodmanOptions};
use sysid_ode::System;

/// Method names and what they are.
pub const METHODS: &[(&str, &str)] = &[
    ("goodman", "Goodman 1966: Newton iteration on the initial values, full steps"),
    ("goodman-halving", "Goodman 1966 with step halving while the cost rises"),
];

/// Options shared by every method, from the command line.
#[derive(Clone, Copy, Debug, Default)]
pub struct Common {
    /// Iteration budget, if given.
    pub max_iterations: Option<usize>,
}

/// The method called `name`.
pub fn method<S: System>(name: &str, common: Common) -> anyhow::Result<Box<dyn Method<S>>> {
    let mut goodman = GoodmanOptions::default();
    if let Some(m) = common.max_iterations {
        goodman.max_iterations = m;
    }
    match name {
        "goodman" => Ok(Box::new(Goodman::new(goodman))),
        "goodman-halving" => Ok(Box::new(Goodman::new(goodman.with_step_halving(true)))),
        _ => anyhow::bail!(
            "unknown method `{name}` (methods: {})",
            METHODS.iter().map(|m| m.0).collect::<Vec<_>>().join(", ")
        ),
    }
}
