//! A PEtab problem fitted from Rust: Boehm et al. (2014), imported from its YAML file, fitted
//! by the default method from its nominal parameters and from 10 starts drawn uniformly on
//! each parameter's scale within its bounds.
//!
//!     cargo run --release --example petab [path/to/problem.yaml]

use sysid::montecarlo::{MultistartOptions, multistart};
use sysid::registry::{Registry, Role, Settings};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).unwrap_or_else(|| {
        "tests/data/petab/Boehm_JProteomeRes2014/Boehm_JProteomeRes2014.yaml".into()
    });
    let problem = sysid::petab::import(std::path::Path::new(&path))?.model.problem(None)?;
    let method = Registry::standard().build(Role::Default.method(), &Settings::default())?;
    let fit = method.fit(&problem)?;
    println!("{path}");
    println!(
        "from nominal: NLL {:.6}, {}, {} iterations",
        fit.nll.unwrap_or(f64::NAN),
        if fit.converged() { "converged" } else { "not converged" },
        fit.iterations
    );
    for (name, value) in fit.names.iter().zip(&fit.values) {
        println!("  {name:24} {value:.6e}");
    }
    // Each start with a start's budget (1 000 iterations) rather than one fit's (3 000), as
    // `sysid fit --starts` runs them: another start costs less than a long crawl.
    let mut settings = Settings::default();
    settings.driver.max_iterations = sysid::core::START_MAX_ITERATIONS;
    let per_start = Registry::standard().build(Role::Default.method(), &settings)?;
    let options = MultistartOptions { starts: 10, ..Default::default() };
    let run = multistart(&*per_start, &problem, &options)?;
    let s = &run.starts;
    println!(
        "10 starts: best NLL {:.6}, {} converged, {} within 0.1 of the best, {:.1} s",
        run.best.nll.unwrap_or(f64::NAN),
        s.converged,
        s.reached_best,
        s.elapsed_ms / 1e3
    );
    Ok(())
}
