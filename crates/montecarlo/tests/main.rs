//! The integration tests of sysid-montecarlo, one binary: a module per file (one link instead of one
//! per file, and the generic methods instantiated once for all of them).

mod multistart;
mod study;
