//! # sysid-montecarlo: how often, from how far, how accurately, at what cost
//!
//! A study repeats one identification problem many times. Each trial draws a noise
//! realisation (the model at the truth plus noise of the system's σ times a chosen
//! multiple) and a start (each unknown perturbed around the truth by a factor up to 1 ± ρ),
//! fits a reference from the truth, and runs every method from the start on the same data.
//! A method succeeds when it reports convergence to the reference fit's cost (within
//! [`SUCCESS_RTOL`] relative). Trials run in parallel on rayon; each draws from its own
//! random stream (ChaCha8 seeded by the study's seed, stream = trial index), so results do
//! not depend on the thread count, on interruptions or on sharding.
//!
//! The statistics ([`Summary`]) compare the successful estimates with the Cramér–Rao bound
//! at the truth ([`Scenario::cramer_rao`]): bias, standard deviation, RMSE, efficiency
//! (CRB variance / observed variance), coverage of each fit's own 95 % interval, and
//! percentiles of iterations and time. [`basin`] maps convergence over a grid of starts for
//! two unknowns. [`files`] writes a study to a directory (`trials.jsonl` as trials finish,
//! `summary.json`, `summary.md`), resumes a killed one and merges shards.
//!
//! ```no_run
//! use sysid_montecarlo::{Scenario, Study, StudySpec, files};
//! use sysid_registry::{Registry, Settings};
//!
//! let case = sysid_systems::van_der_pol::van_der_pol();
//! let spec = StudySpec {
//!     system: "van-der-pol".into(),
//!     methods: vec!["goodman".into()],
//!     reference: "goodman-halving".into(),
//!     trials: 1000,
//!     noise: 1.0,
//!     perturb: 0.2,
//!     seed: 1,
//!     fixed: Vec::new(),
//!     driver: Default::default(),
//!     settings: Default::default(),
//! };
//! let registry = Registry::standard();
//! let method = |name| registry.build(name, &Settings::default()).expect("a registered name");
//! let study = Study::new(
//!     spec,
//!     Scenario::from_case(&case)?,
//!     vec![method("goodman")],
//!     method("goodman-halving"),
//! )?;
//! let summary = files::run(&study, "vdp-study".as_ref(), Default::default(), &|_, _| {})?;
//! println!("{}", summary.markdown());
//! # Ok::<(), sysid_montecarlo::StudyError>(())
//! ```
#![warn(missing_docs)]

mod basin;
mod error;
pub mod files;
pub mod multistart;
mod scenario;
mod stats;
mod trial;

pub use basin::{Basin, BasinMap, basin};
pub use error::StudyError;
pub use multistart::{
    Multistart, MultistartOptions, Outcome, REACHED, Sampling, StartDone, multistart,
    multistart_observed,
};
pub use scenario::Scenario;
pub use stats::{
    Accuracy, Count, MethodSummary, Percentiles, Summary, Z95, quantile, summarise, wilson,
};
pub use trial::{
    REFERENCE, SUCCESS_ATOL, SUCCESS_RTOL, SharedMethod, Study, StudySpec, TrialRecord, perturb,
};
