//! The integration tests of sysid-ode, one binary: a module per file (one link instead of one
//! per file, and the generic methods instantiated once for all of them).

mod common;

mod adjoint;
mod allocations;
mod bdf;
mod events;
mod integrators;
mod sensitivities;
mod stiff;
