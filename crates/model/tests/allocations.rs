//! A model file's sensitivity integration allocates nothing per step: its symbolic
//! Jacobian's work space and product plan are set up once (explicit steps), as are its
//! second derivatives (implicit steps).
#![allow(unsafe_code)] // a counting global allocator is the only way to observe allocations

use std::alloc::{GlobalAlloc, Layout, System as Heap};
use std::cell::Cell;
use std::path::Path;

use sysid_model::{Model, ModelFile};
use sysid_ode::{Inputs, Integrator, Ivp, Wrt};

struct Counting;

thread_local! {
    /// This thread's allocations (the harness's threads allocate at times of their own).
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
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
