//! The integration tests of sysid-cli, one binary: a module per file (one link instead of one
//! per file, and the generic methods instantiated once for all of them).

mod cli;
mod contract;
mod edges;
mod model_files;
mod petab;
mod signals;
mod study;
