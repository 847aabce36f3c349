//! The integration tests of sysid-model, one binary: a module per file (one link instead of one
//! per file, and the generic methods instantiated once for all of them).

mod common;

mod adjoint;
mod allocations;
mod document;
mod events;
mod experiments;
mod expressions;
mod kinks;
mod laplace;
mod model_file;
mod profile;
mod sparse;
mod symbolic;
