//! One method on your own ODE: logistic growth x' = r x (1 − x/K), x(0) known, r and K
//! fitted to six measurements by the default method, nl2sol, with a smaller iteration budget.
//!
//!     cargo run --release --example logistic

use sysid::prelude::*;

/// The model, written once, generic over the scalar: f64 for the states, dual numbers for
/// the sensitivities.
#[derive(Clone, Debug)]
struct Logistic;

impl Ode for Logistic {
    const STATES: &[&str] = &["x"];
    const PARAMETERS: &[&str] = &["r", "K"];
    fn rhs<T: Scalar>(&self, _t: f64, y: &[T], p: &[T], dy: &mut [T]) {
        dy[0] = p[0] * y[0] * (-(y[0] / p[1]) + 1.0);
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (t, x) = ([0.0, 1.0, 2.0, 4.0, 6.0, 8.0], [0.5, 1.3, 2.7, 7.5, 9.5, 10.0]);
    let problem = Problem::ode(Logistic)
        .known("x", 0.5)
        .unknown("r", 0.8)
        .unknown("K", 8.0)
        .data(Data::discrete().series("x", &t, &x))
        .build()?;
    let method =
        LevenbergMarquardt::adaptive(LevenbergMarquardtOptions::default().with_max_iterations(100));
    let fit = method.fit(&problem)?;
    println!("{fit}");
    Ok(())
}
