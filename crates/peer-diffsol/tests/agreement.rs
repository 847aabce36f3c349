//! Two independent codes on every catalogue system: sysid's integrators (DOPRI5, Rodas4)
//! and diffsol's (Tsit45, BDF) must give the same states and sensitivities at the truth, on
//! the case's output times, with sensitivities to the case's unknowns.

use sysid_ode::testing::scaled_difference;
use sysid_ode::{Integrator, Ivp, Scheme, System};
use sysid_peer_diffsol::{Peer, Solver};
use sysid_systems::{Case, NAMES, Visit, visit};

/// The largest difference between sysid and diffsol, each component scaled by its largest
/// magnitude over the output times (so a sensitivity of 1e5 and one of 1e-3 are judged
/// alike), for the states and for the sensitivities.
struct Disagreement {
    rtol: f64,
    solver: Solver,
}

impl Visit for Disagreement {
    type Output = (f64, f64);
    fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> (f64, f64) {
        let problem = case.problem(1).unwrap();
        let (y0, p) = case.true_point();
        let times = &problem.sampled().times;
        let wrt = problem.experiments()[0].slots();
        // The reference: sysid far tighter than the peer, with the case's own scheme.
        let atol = problem.integrator().atol.min(self.rtol * 1e-2);
        let tight = Integrator { rtol: 1e-13, atol: atol * 1e-3, ..*problem.integrator() };
        let tight = match tight.scheme {
            Scheme::Rodas4 => tight.with_max_steps(1_000_000),
            _ => tight,
        };
        let ours = Ivp::new(&case.system, case.t0, &y0, &p)
            .solve_sensitivities(&tight, wrt, times)
            .unwrap();
        let peer = Peer::new(&case.system, case.t0, &y0, &p, self.rtol, atol)
            .solve_sensitivities(self.solver, wrt, times)
            .unwrap_or_else(|e| panic!("{}: {e}", case.name));
        let states =
            scaled_difference(times.len(), |m| peer.state(m).to_vec(), |m| ours.state(m).to_vec());
        let sens = scaled_difference(
            times.len(),
            |m| peer.sensitivity(m).as_slice().to_vec(),
            |m| ours.sensitivity(m).iter().copied().collect(),
        );
        (states, sens)
    }
}

/// At rtol 1e-10 the global error of a fifth-order explicit method stays near rtol (measured:
/// at most 6e-10 over the catalogue, on short-period); BDF's variable order and Newton
/// iterations leave it larger (at most 3e-8, van der Pol's sensitivities). The bounds are a
/// factor ~3–10 above those. Sensitivities to initial values (van der Pol's x(0), v(0)) and
/// to parameters, inputs with jumps (short-period) and the stiff case (robertson) are all
/// covered.
#[test]
fn diffsol_agrees_with_sysid_on_every_catalogue_system() {
    for (solver, bound) in [(Solver::Tsit45, 3e-9), (Solver::Bdf, 1e-7)] {
        for name in NAMES {
            let (states, sens) = visit(name, Disagreement { rtol: 1e-10, solver }).unwrap();
            println!("{name:24} {:7} states {states:.1e} sensitivities {sens:.1e}", solver.name());
            assert!(
                states < bound && sens < bound,
                "{name}, {}: {states:e}, {sens:e}",
                solver.name()
            );
        }
    }
}

/// Plain integrations (no sensitivities) agree too, and diffsol is stopped on the input's
/// jumps: short-period's elevator doublet.
#[test]
fn states_alone_agree_across_input_jumps() {
    let case = sysid_systems::short_period::short_period();
    let (y0, p) = case.true_point();
    let times: Vec<f64> = (0..=200).map(|i| 0.05 * i as f64).collect();
    let ours = Ivp::new(&case.system, 0.0, &y0, &p)
        .solve(&Integrator::dopri5(1e-13, 1e-15), &times)
        .unwrap();
    for solver in Solver::ALL {
        let peer =
            Peer::new(&case.system, 0.0, &y0, &p, 1e-10, 1e-12).solve(solver, &times).unwrap();
        let d =
            scaled_difference(times.len(), |m| peer.state(m).to_vec(), |m| ours.state(m).to_vec());
        assert!(d < 1e-8, "{}: {d:e}", solver.name());
        assert!(peer.rhs_evaluations > 0);
    }
}

#[test]
fn times_before_t0_or_out_of_order_are_errors() {
    let case = sysid_systems::van_der_pol::van_der_pol();
    let (y0, p) = case.true_point();
    let peer = Peer::new(&case.system, 0.0, &y0, &p, 1e-8, 1e-10);
    for times in [&[-1.0, 1.0][..], &[2.0, 1.0], &[], &[0.0]] {
        let e = peer.solve(Solver::Tsit45, times).unwrap_err();
        assert!(e.to_string().starts_with("output times:"), "{e}");
    }
}
