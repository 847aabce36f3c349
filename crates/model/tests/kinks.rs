//! Kinks where a switch time that moves with an unknown passes a sample time
//! (`Problem::kinks`), and the certificate's test of one: held where the slopes on both
//! sides point at it, let go where the other side's slope leads on.
//!
//! x' = if(lt(t, tau), 0, 1) from x(0) = 0 is x(t) = max(0, t − τ), sampled at t = 0…4 with
//! data 0, 0, −1.5, 1.5, 2.5 (σ = 1). The residuals at t = 2, 3, 4 (those at 0 and 1 are 0)
//! are 3.5 − τ, 1.5 − τ, 1.5 − τ on 1 ≤ τ ≤ 2; 1.5, 1.5 − τ, 1.5 − τ on 2 ≤ τ ≤ 3; and
//! 1.5, −1.5, 1.5 − τ on 3 ≤ τ ≤ 4.

use std::path::PathBuf;

use sysid_core::method::{certify, optimality, other_side};
use sysid_core::{Bound, SLIVER};
use sysid_model::Model;

fn model(name: &str, log: bool) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sysid-kinks-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("data.csv"), "t,x\n0,0\n1,0\n2,-1.5\n3,1.5\n4,2.5\n").unwrap();
    let unknown = match log {
        true => "tau = { guess = 2.5, log = true }",
        false => "tau = 2.5",
    };
    let text = format!(
        "states = [\"x\"]\nparameters = [\"tau\"]\n[equations]\nx = \"if(lt(t, tau), 0, 1)\"\n\
         [initial]\nx = 0.0\n[unknowns]\n{unknown}\n[data]\nfile = \"data.csv\"\n"
    );
    let path = dir.join("m.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// The kinks next to τ = 2.5 are the sample times 2 and 3, on its own scale (linear or ln),
/// and a step may go over each by 1e-9 of its time; on a sample time, both kinks are it.
#[test]
fn the_kinks_are_the_sample_times_next_to_the_switch() {
    for log in [false, true] {
        let problem = Model::load(&model("around", log)).unwrap().problem(None).unwrap();
        let z = |v: f64| if log { v.ln() } else { v };
        let around = problem.kinks(&[z(2.5)])[0].expect("a kink");
        assert!((around.below - z(2.0)).abs() <= 1e-15, "{log}: {around:?}");
        assert!((around.above - z(3.0)).abs() <= 1e-15, "{log}: {around:?}");
        // The sliver in z: 1e-9 of the time, over dτ/dz (1, or τ on a log scale).
        let (below, above) = if log { (2e-9 / 2.0, 3e-9 / 3.0) } else { (2e-9, 3e-9) };
        // (To the rounding of z ± the sliver.)
        let rounding = |z: f64| 4.0 * f64::EPSILON * z.abs().max(1.0);
        let (lo, hi) = (around.below - around.lo, around.hi - around.above);
        assert!((lo - below).abs() <= rounding(around.below), "{log}: {around:?}");
        assert!((hi - above).abs() <= rounding(around.above), "{log}: {around:?}");
        let on = problem.kinks(&[z(3.0)])[0].expect("a kink");
        assert_eq!((on.below.to_bits(), on.above.to_bits()), (z(3.0).to_bits(), z(3.0).to_bits()));
        // Past the last sample there is no kink above.
        let past = problem.kinks(&[z(4.5)])[0].expect("a kink below");
        assert!(past.above.is_infinite() && (past.below - z(4.0)).abs() <= 1e-15);
    }
}

/// Just above the kink at τ = 3 the cost 4.5 + (1.5 − τ)² rises with τ, so the measure holds τ
/// there; below it the cost 2.25 + 2(1.5 − τ)² still falls as τ falls, at the half gradient
/// g = 2(τ − 1.5) = 3 with a = 2 and ‖r‖² = 6.75: the verdict lets τ go, its measure the
/// cosine 3/√(2·6.75) = √(2/3). At the kink τ = 2, the minimum (g = 1 above it, 3τ − 6.5 =
/// −0.5 below), both sides point at it and it stays held.
#[test]
fn a_kink_is_held_only_where_both_sides_point_at_it() {
    let problem = Model::load(&model("held", false)).unwrap().problem(None).unwrap();
    let gtol = 1e-6;
    let linearize = |z: &[f64]| problem.linearize(z).ok();
    // Above the kink at 3 by half the sliver.
    let lin = problem.linearize(&[3.0 + 0.5 * SLIVER * 3.0]).unwrap();
    let measure = optimality(&problem, &lin, gtol);
    assert_eq!(measure.active[0], Some(Bound::SwitchOnSample));
    assert!(measure.value <= 1e-8, "{measure:?}");
    let mut certificate = certify(&problem, &lin, gtol, 1e12);
    let counts = other_side(&problem, &lin, &mut certificate, &linearize);
    assert_eq!(counts.integrations, 1);
    assert_eq!(certificate.active[0], None);
    let cosine = (2.0_f64 / 3.0).sqrt();
    assert!((certificate.optimality - cosine).abs() <= 1e-6, "{certificate:?}");
    assert!(!certificate.holds());
    // At the kink 2 from above: held, and the other side agrees.
    let lin = problem.linearize(&[2.0 + SLIVER * 2.0]).unwrap();
    let mut certificate = certify(&problem, &lin, gtol, 1e12);
    assert_eq!(certificate.active[0], Some(Bound::SwitchOnSample));
    other_side(&problem, &lin, &mut certificate, &linearize);
    assert_eq!(certificate.active[0], Some(Bound::SwitchOnSample));
    assert!(certificate.holds(), "{certificate:?}");
    // 2.25 + 2(0.5 + 2e-9)²: 2.75 to 1e-8.
    assert!((lin.cost - 2.75).abs() <= 1e-8, "{}", lin.cost);
}

/// A switch time that falls as the unknown grows, τ = 10 − u (set by the experiment): at
/// u = 7.5 (τ = 2.5) the kink below is u = 7 (τ = 3) and the one above u = 8 (τ = 2), each
/// overstepped by 1e-9 of its time (dτ/du = −1).
#[test]
fn a_switch_time_that_falls_as_its_unknown_grows_has_its_kinks_swapped() {
    let dir = std::env::temp_dir().join(format!("sysid-kinks-falls-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("data.csv"), "t,x\n0,0\n1,0\n2,-1.5\n3,1.5\n4,2.5\n").unwrap();
    let text = "states = [\"x\"]\nparameters = [\"tau\"]\n[equations]\nx = \"if(lt(t, tau), 0, 1)\"\n\
         [initial]\nx = 0.0\n[unknowns]\nu = 7.5\n[[experiments]]\nname = \"e\"\nfile = \"data.csv\"\n\
         set = { tau = \"10 - u\" }\n";
    std::fs::write(dir.join("m.toml"), text).unwrap();
    let problem = Model::load(&dir.join("m.toml")).unwrap().problem(None).unwrap();
    let around = problem.kinks(&[7.5])[0].expect("a kink");
    let rounding = 4.0 * f64::EPSILON * 8.0;
    assert!((around.below - 7.0).abs() <= rounding, "{around:?}");
    assert!((around.above - 8.0).abs() <= rounding, "{around:?}");
    assert!((around.below - around.lo - 3e-9).abs() <= rounding, "{around:?}");
    assert!((around.hi - around.above - 2e-9).abs() <= rounding, "{around:?}");
}
