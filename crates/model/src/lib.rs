//! # sysid-model: model files and data files
//!
//! Identify a system without writing Rust: a TOML model file names the states, parameters
//! and inputs, gives the equations as expressions, says what is known and what is unknown,
//! and points at a CSV data file.
//!
//! ```toml
//! states = ["y1", "y2"]                 # order = state order
//! parameters = ["k1", "k2"]
//! inputs = []                           # signals u(t), read from data columns of that name
//! [equations]                           # d(state)/dt: + - * / ^, parentheses, numbers,
//! y1 = "-k1 * y1"                       # exp log sqrt sin cos tan tanh abs min max, t
//! y2 = "k1 * y1 - k2 * y2"
//! [initial]                             # known initial values at t0
//! y1 = 1.0
//! y2 = 0.0
//! [unknowns]                            # parameters or states (= unknown initial values)
//! k1 = 1.0
//! k2 = { guess = 0.5, min = 0.0, log = true }
//! [data]
//! file = "data.csv"                     # relative to this file; time column first
//! t0 = 0.0
//! record = "discrete"                   # or "continuous"
//! [data.weights]
//! y2 = 100.0                            # 1/σ² of the column (default 1)
//! ```
//!
//! Extensions of the contract: `inputs` may be a table `{ names = [...], mode = "step" }` for
//! piecewise-constant inputs (default linear), `[outputs]` name measured expressions, and
//! `[integrator]` sets `method` ("dopri5" | "rk4" | "rodas4" or "rodas5p" for stiff models | "auto"),
//! `rtol`, `atol`, `step`, `max_steps`.
//!
//! Expressions are compiled once ([`expr::Program`]) and evaluated for any scalar. At load
//! time they are also differentiated symbolically ([`symbolic`]): the right-hand side, the
//! outputs and their sparse Jacobians become one straight-line program over f64, from which
//! the sensitivities are formed. The dual-number evaluation stays as the reference
//! ([`ModelSystem::with_dual_numbers`]); the two agree to rounding.
//! Every error names the file, the line and the column.
#![warn(missing_docs)]

pub mod data;
mod error;
pub mod expr;
pub mod file;
#[cfg(feature = "jit")]
mod jit;
mod problem;
pub mod simulate;
mod steady;
pub mod symbolic;
mod system;
pub mod table;
mod tape;

use std::path::{Path, PathBuf};

use sysid_ode::{Inputs, Signature};

pub use error::{ModelError, line_column};
pub use file::{
    DataSpec, EventSpec, ExperimentSpec, Expression, ModelFile, NoiseSpec, OutputSpec, RecordKind,
    SetValue,
};
pub use system::ModelSystem;

/// A model file, read and compiled.
#[derive(Clone, Debug)]
pub struct Model {
    /// The checked file.
    pub file: ModelFile,
}

impl Model {
    /// Reads and checks a model file.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        Ok(Self { file: ModelFile::read(path)? })
    }

    fn signature(&self) -> Signature {
        let f = &self.file;
        Signature::try_new(
            f.states.clone(),
            f.parameters.clone(),
            f.inputs.clone(),
            f.outputs.iter().map(|o| o.name.clone()).collect(),
        )
        .expect("names were checked when the file was read")
    }

    /// The system, with input signals.
    pub fn system(&self, inputs: Inputs) -> ModelSystem {
        let outputs = self.file.outputs.iter().map(|o| o.value.clone()).collect();
        ModelSystem::new(self.signature(), self.file.equations.clone(), outputs, inputs)
            .with_events(self.file.events.clone())
    }

    fn located(&self, message: String) -> ModelError {
        ModelError::file(&self.file.path.display().to_string(), message)
    }

    /// Every file the model is read from: the model file (or an imported problem's files)
    /// and its data files, those held in memory left out.
    pub fn inputs(&self) -> Vec<PathBuf> {
        let f = &self.file;
        let held = |p: &Path| f.tables.iter().any(|t| t.0 == p);
        std::iter::once(f.path.clone())
            .chain(f.sources.iter().cloned())
            .chain(f.data.file.iter().cloned())
            .chain(f.experiments.iter().map(|e| e.file.clone()))
            .filter(|p| !held(p))
            .collect()
    }

    /// The data file named in `[data] file`.
    pub fn data_path(&self) -> Result<&Path, ModelError> {
        self.file.data.file.as_deref().ok_or_else(|| {
            self.located("no data file: give `[data] file = \"...\"` or --data".into())
        })
    }
}
