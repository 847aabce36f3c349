//! A catalogue entry: a model with its data, unknowns, start and reference answer.

use sysid_core::{Data, Problem, ProblemError, Unknown};
use sysid_ode::{Integrator, System};

/// A published or exact answer a fit must reproduce, with the tolerance that applies.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    /// Estimated values by unknown name.
    pub values: Vec<(&'static str, f64)>,
    /// ε at the answer.
    pub cost: f64,
    /// Relative tolerance a fit is held to.
    pub tolerance: f64,
    /// Where the answer comes from.
    pub source: &'static str,
}

/// A benchmark system: everything needed to pose its identification problem.
pub struct Case<S> {
    /// The name used on the command line.
    pub name: &'static str,
    /// One line: what it is.
    pub summary: &'static str,
    /// The model.
    pub system: S,
    /// Time of the initial values.
    pub t0: f64,
    /// Known initial values and parameters.
    pub known: Vec<(&'static str, f64)>,
    /// The unknowns with their default starting guesses.
    pub unknowns: Vec<Unknown>,
    /// The integrator the problem uses.
    pub integrator: Integrator,
    /// The data for a seed (fixed data ignore it).
    pub data: fn(u64) -> Data,
    /// The true values of the unknowns, where the data are synthetic.
    pub truth: Vec<(&'static str, f64)>,
    /// The answer to reproduce, where one is known.
    pub reference: Option<Reference>,
}

impl<S: System + Clone> Case<S> {
    /// The identification problem on the data for `seed`, from the default start.
    pub fn problem(&self, seed: u64) -> Result<Problem<S>, ProblemError> {
        let mut builder = Problem::builder(self.system.clone())
            .t0(self.t0)
            .knowns(&self.known)
            .integrator(self.integrator)
            .data((self.data)(seed));
        for u in &self.unknowns {
            builder = builder.unknown_with(u.clone());
        }
        builder.build()
    }

    /// The reference value or the truth of an unknown, for tables.
    pub fn expected(&self, name: &str) -> Option<f64> {
        let find = |list: &[(&str, f64)]| list.iter().find(|(n, _)| *n == name).map(|p| p.1);
        self.reference.as_ref().and_then(|r| find(&r.values)).or_else(|| find(&self.truth))
    }
}
