//! A model file's sensitivity integration allocates nothing per step: its symbolic
//! Jacobian's work space and product plan are set up once (explicit steps), as are its
//! second derivatives (implicit steps). Its symbolic derivatives take memory in proportion
//! to their entries, not to states².
#![allow(unsafe_code)] // a counting global allocator is the only way to observe allocations

use std::alloc::{GlobalAlloc, Layout, System as Heap};
use std::cell::Cell;
use std::path::Path;

use sysid_model::{Model, ModelFile};
use sysid_ode::{Inputs, Integrator, Ivp, Wrt};

struct Counting;

thread_local! {
    /// This thread's allocations (the harness's threads allocate at times of their own),
    /// and the bytes they asked for.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
    static BYTES: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        let _ = BYTES.try_with(|n| n.set(n.get() + layout.size()));
        unsafe { Heap.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { Heap.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const MODEL: &str = r#"states = ["V", "R"]
parameters = ["a", "b", "c"]
[equations]
V = "c * (V - V^3 / 3 + R)"
R = "-(V - a + b * R) / c"
[initial]
V = -1.0
R = 1.0
[unknowns]
a = 0.2
b = 0.2
c = 3.0
"#;

#[test]
fn allocations_do_not_grow_with_the_number_of_steps() {
    let file = ModelFile::parse(MODEL, Path::new("fhn.toml")).expect("a valid model");
    let sys = Model { file }.system(Inputs::new(Vec::new()));
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(2), Wrt::InitialValue(0)];
    let ivp = Ivp::new(&sys, 0.0, &[-1.0, 1.0], &[0.2, 0.2, 3.0]);
    for integrator in [Integrator::dopri5(1e-8, 1e-10), Integrator::rodas4(1e-6, 1e-8)] {
        let run = |t_end: f64| {
            let before = ALLOCATIONS.with(Cell::get);
            let sol = ivp.solve_sensitivities(&integrator, &wrt, &[t_end]).unwrap();
            (ALLOCATIONS.with(Cell::get) - before, sol.counts().steps)
        };
        let (short, short_steps) = run(1.0);
        let (long, long_steps) = run(100.0);
        assert!(long_steps > 20 * short_steps, "{short_steps} vs {long_steps} steps");
        assert_eq!(
            short, long,
            "{:?} allocations: {short} for {short_steps} steps, {long} for {long_steps}",
            integrator.scheme
        );
    }
}

/// The symbolic Jacobian of n uncoupled states x_i′ = −k x_i has n + n entries (and its
/// second derivatives n): built column by column, it asks for bytes in proportion to n.
/// Its columns were held dense, n² term ids each for the first and the second derivatives:
/// a model file of 20 000 such states took 3.2 GB and 51 s before its first fit, now 49 MB and
/// 4.6 s (`/usr/bin/time sysid fit`). Four times the states asked 10.9 times the bytes then
/// (25.8 MB for 1 000, 280 MB for 4 000), 2.6 times now (10.9 MB, 28.6 MB): the parts that
/// grow faster than n, such as hash tables that double, stay well below the bound of 6.
#[test]
fn symbolic_derivatives_take_memory_in_proportion_to_their_entries() {
    let bytes = |n: usize| {
        let names: Vec<String> = (0..n).map(|i| format!("\"x{i}\"")).collect();
        let mut text =
            format!("states = [{}]\nparameters = [\"k\"]\n[equations]\n", names.join(", "));
        text.extend((0..n).map(|i| format!("x{i} = \"-k * x{i}\"\n")));
        text += "[initial]\n";
        text.extend((0..n).map(|i| format!("x{i} = 1.0\n")));
        text += "[unknowns]\nk = 1.0\n";
        let file = ModelFile::parse(&text, Path::new("uncoupled.toml")).expect("a valid model");
        let model = Model { file };
        let before = BYTES.with(Cell::get);
        let sys = model.system(Inputs::new(Vec::new()));
        let asked = BYTES.with(Cell::get) - before;
        drop(sys);
        asked
    };
    let (small, large) = (bytes(1_000), bytes(4_000));
    assert!(large < 6 * small, "{small} bytes for 1 000 states, {large} for 4 000");
}
