//! Implicit steps with a sparse LU: a model file of 120 states, stiff, whose Jacobian has a
//! cycle that fills in, integrated with its sensitivities by Rodas5P through the sparse LU
//! (its symbolic Jacobian) and through the dense LU (the dual-number reference).

use std::fmt::Write as _;
use std::path::Path;

use sysid_model::{Model, ModelFile};
use sysid_ode::{Inputs, Integrator, IterationMatrix, Ivp, Wrt};

/// A model file's states x0…x{n−1} and parameters k0…k{n−1}, up to its `[equations]`.
fn header(n: usize) -> String {
    let names = |prefix: &str| (0..n).map(|i| format!("\"{prefix}{i}\"")).collect::<Vec<_>>();
    format!(
        "states = [{}]\nparameters = [{}]\n[equations]\n",
        names("x").join(", "),
        names("k").join(", ")
    )
}

/// A chain x_0 → x_1 → … → x_{n−1} → x_0 with rates spread over five decades, the last
/// step saturating: dx_i/dt = k_{i−1} x_{i−1} − k_i x_i (x_{n−1} feeding x_0).
fn ring(n: usize) -> String {
    let mut text = header(n);
    let flux = |i: usize| match i {
        0 => format!("k{i} * x{i} / (1 + x{i})"),
        _ => format!("k{i} * x{i}"),
    };
    for i in 0..n {
        let before = (i + n - 1) % n;
        let _ = writeln!(text, "x{i} = \"{} - {}\"", flux(before), flux(i));
    }
    let _ = writeln!(text, "[initial]");
    for i in 0..n {
        let _ = writeln!(text, "x{i} = {}", if i == 0 { 1.0 } else { 0.0 });
    }
    let _ = writeln!(text, "[unknowns]");
    for i in 0..n {
        let _ = writeln!(text, "k{i} = {:e}", 10f64.powf(-2.0 + 5.0 * i as f64 / n as f64));
    }
    text
}

/// Every state of n feeding every other: a Jacobian with no zero.
fn full(n: usize) -> String {
    let mut text = header(n);
    let all = (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>().join(" + ");
    for i in 0..n {
        let _ = writeln!(text, "x{i} = \"0.01 * ({all}) - k{i} * x{i}\"");
    }
    let _ = writeln!(text, "[initial]");
    for i in 0..n {
        let _ = writeln!(text, "x{i} = 1.0");
    }
    let _ = writeln!(text, "[unknowns]");
    for i in 0..n {
        let _ = writeln!(text, "k{i} = 1.0");
    }
    text
}

fn model_of(text: &str) -> Model {
    let file = ModelFile::parse(text, Path::new("model.toml")).unwrap_or_else(|e| panic!("{e}"));
    Model { file }
}

/// E is factorised sparse where its factors keep at most a quarter of n² entries
/// (`SPARSE_SHARE`): a ring of 30 states (2 entries a row, the cycle closing fills the last
/// row and column: about 3n of n²), not a ring of 6 (about 15 of 36) nor 30 states that all
/// feed each other (n² of n²).
#[test]
fn factors_are_sparse_where_they_fill_little() {
    let sparse = |text: &str| {
        let model = model_of(text);
        let p: Vec<f64> = model.file.unknowns.iter().map(|u| u.guess).collect();
        IterationMatrix::new(&model.system(Inputs::new(Vec::new())), &p, 1).is_sparse()
    };
    assert!(sparse(&ring(30)));
    assert!(!sparse(&ring(6)));
    assert!(!sparse(&full(30)));
}

/// With dense factors the Jacobian is read from the system's sparse Jacobian, its entries put
/// in place: the same matrix, entry for entry, as the dual numbers' products with the
/// identity give (to rounding: the two evaluate k x / (1 + x)'s derivative in another order).
#[test]
fn dense_factors_read_the_sparse_jacobian() {
    let n = 6;
    let model = model_of(&ring(n));
    let sparse = model.system(Inputs::new(Vec::new()));
    let duals = sparse.with_dual_numbers();
    let p: Vec<f64> = model.file.unknowns.iter().map(|u| u.guess).collect();
    let y: Vec<f64> = (0..n).map(|i| 0.3 + 0.1 * i as f64).collect();
    let mut a = IterationMatrix::new(&sparse, &p, 1);
    let mut b = IterationMatrix::new(&duals, &p, 1);
    assert!(!a.is_sparse() && !b.is_sparse());
    a.factor(&sparse, (0.5, &y, &p, &[]), 10.0).unwrap();
    b.factor(&duals, (0.5, &y, &p, &[]), 10.0).unwrap();
    let nonzero = b.jacobian().iter().filter(|v| **v != 0.0).count();
    assert_eq!(nonzero, 2 * n, "{:?}", b.jacobian());
    for (x, z) in a.jacobian().iter().zip(b.jacobian()) {
        assert!((x - z).abs() <= 4.0 * f64::EPSILON * z.abs(), "{x} against {z}");
    }
    // And the two factorisations solve alike.
    let mut r: Vec<f64> = (0..n).map(|i| i as f64 - 2.5).collect();
    let mut q = r.clone();
    a.solve(&mut r);
    b.solve(&mut q);
    for (x, z) in r.iter().zip(&q) {
        assert!((x - z).abs() <= 1e-14 * z.abs().max(1.0), "{r:?} against {q:?}");
    }
}

/// The sparse LU's integration gives the dense LU's states and sensitivities to 1e-10 with
/// the same steps, accepted and rejected: a wrong factor or solve changes the stages and with
/// them the error estimates (measured: 3.8e-13 apart, relative to values above 1e-6, the
/// same 33 steps; with L's multipliers 1e-4 off, 80 steps). The two are not equal to the
/// last bit: the dual-number reference evaluates the right-hand side and the Jacobian in
/// another order, and eliminates in another.
#[test]
fn sparse_and_dense_implicit_steps_integrate_alike() {
    let n = 120;
    let file = ModelFile::parse(&ring(n), Path::new("ring.toml")).unwrap_or_else(|e| panic!("{e}"));
    let model = Model { file };
    let sparse = model.system(Inputs::new(Vec::new()));
    let dense = sparse.with_dual_numbers();
    let p: Vec<f64> = model.file.unknowns.iter().map(|u| u.guess).collect();
    let (mut s, mut d) =
        (IterationMatrix::new(&sparse, &p, 1), IterationMatrix::new(&dense, &p, 1));
    assert!(s.is_sparse() && !d.is_sparse());
    // The sparse factors hold J by its entries alone; spread out, it is the dense J.
    let y: Vec<f64> = (0..n).map(|i| 0.3 + 0.01 * i as f64).collect();
    s.factor(&sparse, (0.5, &y, &p, &[]), 10.0).unwrap();
    d.factor(&dense, (0.5, &y, &p, &[]), 10.0).unwrap();
    for (x, z) in s.jacobian().iter().zip(d.jacobian()) {
        assert!((x - z).abs() <= 4.0 * f64::EPSILON * z.abs(), "{x} against {z}");
    }
    let y0: Vec<f64> = (0..n).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect();
    let wrt: Vec<Wrt> = [0, 7, 119].into_iter().map(Wrt::Parameter).collect();
    let times = [0.1, 1.0, 10.0, 100.0];
    let integrator = Integrator::rodas5p(1e-9, 1e-12);
    let a = Ivp::new(&sparse, 0.0, &y0, &p).solve_sensitivities(&integrator, &wrt, &times).unwrap();
    let b = Ivp::new(&dense, 0.0, &y0, &p).solve_sensitivities(&integrator, &wrt, &times).unwrap();
    let (ca, cb) = (a.counts(), b.counts());
    assert_eq!((ca.steps, ca.rejected_steps), (cb.steps, cb.rejected_steps));
    assert!(ca.steps > 20, "{ca:?}");
    let mut largest = 0.0f64;
    for m in 0..times.len() {
        for (x, z) in a.state(m).iter().zip(b.state(m)) {
            largest = largest.max((x - z).abs() / z.abs().max(1e-6));
        }
        let (sa, sb) = (a.sensitivity(m), b.sensitivity(m));
        for (x, z) in sa.iter().zip(sb.iter()) {
            largest = largest.max((x - z).abs() / z.abs().max(1e-6));
        }
    }
    assert!(largest <= 1e-10, "{largest:e}");
}

/// The adjoint of the same ring: its Jacobian read entry by entry from the compiled sparse
/// Jacobian, its implicit steps factorising I/(γh) + J_yᵀ in the transposed pattern, gives
/// Σ_m c_mᵀ S(t_m) as the forward sensitivities do (both at rtol 1e-10), and as the
/// dual-number system's adjoint does (a dense LU and every entry of the Jacobian).
#[test]
fn sparse_adjoint_agrees_with_forward_sensitivities() {
    let n = 120;
    let file = ModelFile::parse(&ring(n), Path::new("ring.toml")).unwrap_or_else(|e| panic!("{e}"));
    let model = Model { file };
    let sparse = model.system(Inputs::new(Vec::new()));
    let dense = sparse.with_dual_numbers();
    let p: Vec<f64> = model.file.unknowns.iter().map(|u| u.guess).collect();
    let y0: Vec<f64> = (0..n).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect();
    let mut wrt: Vec<Wrt> = [0, 7, 60, 119].into_iter().map(Wrt::Parameter).collect();
    wrt.push(Wrt::InitialValue(3));
    let times = [0.1, 1.0, 10.0, 100.0];
    // Every state seen at every time, with weights that change sign.
    let seeds: Vec<f64> = (0..n * times.len()).map(|i| ((i * 13) % 7) as f64 - 3.0).collect();
    let integrator = Integrator::rodas5p(1e-10, 1e-13);
    let ivp = Ivp::new(&sparse, 0.0, &y0, &p);
    let sol = ivp.solve_sensitivities(&integrator, &wrt, &times).unwrap();
    let forward: Vec<f64> = (0..wrt.len())
        .map(|j| {
            (0..times.len())
                .map(|m| (0..n).map(|i| seeds[m * n + i] * sol.sensitivity(m)[(i, j)]).sum::<f64>())
                .sum()
        })
        .collect();
    let adjoint = |ivp: &Ivp<'_, _>| {
        let (_, dense) = ivp.solve_dense(&integrator, &times).unwrap();
        ivp.adjoint(&integrator, &wrt, None, (&dense, &times, &seeds)).unwrap().0
    };
    let a = adjoint(&ivp);
    let b = adjoint(&Ivp::new(&dense, 0.0, &y0, &p));
    let size = forward.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for j in 0..wrt.len() {
        assert!((a[j] - forward[j]).abs() <= 1e-7 * size, "{a:?} against {forward:?}");
        assert!((a[j] - b[j]).abs() <= 1e-9 * size, "{a:?} against {b:?}");
    }
}
