//! The catalogue's model-file twins: five catalogue systems written as model files, as a
//! user would write them, and the catalogue's identification problems posed through them.
//! Shared by `tests/model_twins.rs` and `benches/model.rs`.

use std::path::Path;

use sysid::core::Problem;
use sysid::model::{Model, ModelFile, ModelSystem};
use sysid::ode::{Inputs, System};
use sysid::systems::Case;
use sysid::systems::short_period::ShortPeriod;
use sysid::systems::{fitzhugh_nagumo, lotka_volterra, robertson, short_period, van_der_pol};

/// The twins by catalogue name.
pub const TWINS: [(&str, &str); 5] = [
    ("van-der-pol", include_str!("van-der-pol.toml")),
    ("lotka-volterra", include_str!("lotka-volterra.toml")),
    ("fitzhugh-nagumo", include_str!("fitzhugh-nagumo.toml")),
    ("short-period", include_str!("short-period.toml")),
    ("robertson", include_str!("robertson.toml")),
];

/// The twin model file of a catalogue system.
pub fn model(name: &str) -> Model {
    let (_, text) = TWINS.iter().find(|t| t.0 == name).expect("a twin of that name");
    let path = format!("tests/twins/{name}.toml");
    Model { file: ModelFile::parse(text, Path::new(&path)).expect("a valid twin") }
}

/// The case's problem on the seed's data (its t0, known values, unknowns with their
/// starts, integrator and data) with `system` as the model.
fn pose<S: System + Clone, M: System>(case: &Case<S>, system: M, seed: u64) -> Problem<M> {
    let mut builder = Problem::builder(system)
        .t0(case.t0)
        .knowns(&case.known)
        .integrator(case.integrator)
        .data(case.data(seed).expect("catalogue data"));
    for u in &case.unknowns {
        builder = builder.unknown_with(u.clone());
    }
    builder.build().expect("a valid problem")
}

/// The model-file twin of the catalogue problem `name` on the data of `seed`, with the
/// system's symbolic Jacobians or, if `dual`, differentiated by dual numbers.
pub fn file_problem(name: &str, seed: u64, dual: bool) -> Problem<ModelSystem> {
    let model = model(name);
    let derivatives = |s: ModelSystem| if dual { s.with_dual_numbers() } else { s };
    let plain = || derivatives(model.system(Inputs::new(Vec::new())));
    match name {
        "van-der-pol" => pose(&van_der_pol::van_der_pol(), plain(), seed),
        "lotka-volterra" => pose(&lotka_volterra::lotka_volterra(), plain(), seed),
        "fitzhugh-nagumo" => pose(&fitzhugh_nagumo::fitzhugh_nagumo(), plain(), seed),
        "short-period" => {
            let doublet = Inputs::new(vec![ShortPeriod::doublet()]);
            pose(&short_period::short_period(), derivatives(model.system(doublet)), seed)
        }
        "robertson" => pose(&robertson::robertson(), plain(), seed),
        other => panic!("no twin of {other}"),
    }
}
