//! Every method of the registry on one catalogue system, from the same start: converged or
//! not, iterations, cost and time, as `sysid compare --system van-der-pol` prints them.
//!
//!     cargo run --release --example compare_methods

use sysid::registry::{Registry, Settings};
use sysid::systems::van_der_pol::van_der_pol;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let case = van_der_pol();
    let problem = case.problem(1)?;
    println!("{}: {}", case.name, case.summary);
    for (name, method) in Registry::standard().build_all(&Settings::default()) {
        let fit = method.fit(&problem)?;
        println!(
            "{name:24} {:>9} {:>4} iterations  ε {:<14.10} {:>8.2} ms  {}",
            if fit.converged() { "converged" } else { "not" },
            fit.iterations,
            fit.cost,
            fit.elapsed.as_secs_f64() * 1e3,
            fit.termination.code()
        );
    }
    Ok(())
}
