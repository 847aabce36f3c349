//! The integration tests of sysid, one binary: a module per file (one link instead of one
//! per file, and the generic methods instantiated once for all of them).

mod twins;

mod agreement;
mod bounded;
mod budget;
mod certificate;
mod docs;
mod experiments;
mod geodesic;
mod hard;
mod model_twins;
mod options;
mod paper_goodman_1966;
