//! The step loop of a sensitivity integration allocates nothing: the number of heap
//! allocations of an integration does not grow with its number of steps, explicit or
//! implicit.
#![allow(unsafe_code)] // a counting global allocator is the only way to observe allocations

use std::alloc::{GlobalAlloc, Layout, System as Heap};
use std::cell::Cell;

use sysid_ode::{Integrator, Ivp, Wrt};
use sysid_systems::VanDerPol;

struct Counting;

thread_local! {
    /// This thread's allocations: the test harness's own threads allocate too (capturing
    /// output, reporting), at times that vary from run to run.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // `try_with`: the thread's local storage may already be gone while it exits.
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        unsafe { Heap.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { Heap.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn allocations_do_not_grow_with_the_number_of_steps() {
    let sys = VanDerPol::default();
    let wrt = [Wrt::Parameter(0), Wrt::InitialValue(0), Wrt::InitialValue(1)];
    let ivp = Ivp::new(&sys, 0.0, &[2.0, 0.0], &[1.0]);
    let integrators = [
        Integrator::dopri5(1e-8, 1e-10),
        Integrator::dop853(1e-8, 1e-10),
        Integrator::rodas4(1e-6, 1e-8),
        Integrator::rodas5p(1e-6, 1e-8),
        // DOPRI5 with the stiffness tests of the automatic choice, the spectral radius's
        // power iteration among them; DOP853 with them at tight tolerances.
        Integrator::auto(1e-8, 1e-10),
        Integrator::auto(1e-12, 1e-14),
    ];
    for integrator in integrators {
        let run = |t_end: f64| {
            let before = ALLOCATIONS.with(Cell::get);
            let sol = ivp.solve_sensitivities(&integrator, &wrt, &[t_end]).unwrap();
            (ALLOCATIONS.with(Cell::get) - before, sol.counts().steps)
        };
        let (short, short_steps) = run(2.0);
        let (long, long_steps) = run(200.0);
        assert!(long_steps > 20 * short_steps, "{short_steps} vs {long_steps} steps");
        assert_eq!(
            short, long,
            "{:?} allocations: {short} for {short_steps} steps, {long} for {long_steps}",
            integrator.scheme
        );
    }
}
