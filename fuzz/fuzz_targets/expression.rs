//! Any text: parsing never panics, and whatever parses compiles and evaluates without
//! panicking (NaN and infinities are values, not failures).
#![no_main]

use libfuzzer_sys::fuzz_target;
use sysid_model::expr::{Program, Slot, parse};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(expr) = parse(text) else { return };
    let resolve = |name: &str| match name {
        "x" => Some(Slot::State(0)),
        "k" => Some(Slot::Parameter(0)),
        "u" => Some(Slot::Input(0)),
        "t" => Some(Slot::Time),
        _ => None,
    };
    if let Ok(program) = Program::compile(&expr, &resolve) {
        let _ = program.eval::<f64>(0.5, &[1.5], &[-2.0], &[0.25]);
    }
});
