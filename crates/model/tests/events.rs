//! `[[events]]` in a model file: a sawtooth against its closed form (states and
//! sensitivities, through the compiled right-hand side), and every mistake located.

use std::path::Path;

use sysid_model::{Model, ModelFile};
use sysid_ode::testing::assert_close;
use sysid_ode::{Inputs, Integrator, Ivp, Wrt};

/// x' = −k x; where x falls below a it jumps up by d.
const SAWTOOTH: &str = r#"states = ["x"]
parameters = ["k", "a", "d"]
[equations]
x = "-k * x"
[initial]
x = 3.0
[unknowns]
k = 0.7
a = 1.0
d = 1.5

[[events]]
trigger = "lt(x, a)"
set = { x = "x + d" }
"#;

/// With N(t) firings up to t, x = x0·e^{−kt}·((a + d)/a)^N: the model file's events give
/// the closed form's states and derivatives in k, a and d to 1e-8.
#[test]
fn a_sawtooth_in_a_model_file_matches_its_closed_form() {
    let file = ModelFile::parse(SAWTOOTH, Path::new("saw.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(file.events.len(), 1);
    let sys = Model { file }.system(Inputs::new(Vec::new()));
    let (x0, k, a, d): (f64, f64, f64, f64) = (3.0, 0.7, 1.0, 1.5);
    let times = [1.0, 2.0, 4.0, 7.3];
    let wrt = [Wrt::Parameter(0), Wrt::Parameter(1), Wrt::Parameter(2)];
    let sol = Ivp::new(&sys, 0.0, &[x0], &[k, a, d])
        .solve_sensitivities(&Integrator::rodas5p(1e-10, 1e-12), &wrt, &times)
        .unwrap();
    let (first, period) = ((x0 / a).ln() / k, ((a + d) / a).ln() / k);
    for (m, &t) in times.iter().enumerate() {
        let n = if t < first { 0.0 } else { ((t - first) / period).floor() + 1.0 };
        let x = x0 * (-k * t).exp() * ((a + d) / a).powf(n);
        assert_close(sol.state(m)[0], x, 1e-8);
        let s = sol.sensitivity(m);
        assert_close(s[(0, 0)], -t * x, 1e-8);
        if n > 0.0 {
            assert_close(s[(0, 1)], n * x * (1.0 / (a + d) - 1.0 / a), 1e-8);
            assert_close(s[(0, 2)], n * x / (a + d), 1e-8);
        }
    }
}

/// Each mistake in `[[events]]`, with its message, line and column.
#[test]
fn mistakes_in_events_are_located() {
    let head = SAWTOOTH.split("[[events]]").next().expect("a head");
    for (events, expected) in [
        (
            "[events]\ntrigger = \"lt(x, a)\"\n",
            "saw.toml:12:1: `events` must be an array of tables: write each as [[events]]",
        ),
        (
            "[[events]]\nset = { x = \"0\" }\n",
            "saw.toml:12:1: [[events]] event 1: `trigger` is missing: the comparison that fires it, like \"lt(x, 1e-8)\"",
        ),
        (
            "[[events]]\ntrigger = \"x - a\"\nset = { x = \"0\" }\n",
            "saw.toml:13:11: event 1: trigger must be a comparison, lt(a, b), le(a, b), gt(a, b) or ge(a, b): the event fires where it turns true",
        ),
        (
            "[[events]]\ntrigger = \"lt(x, b)\"\nset = { x = \"0\" }\n",
            "saw.toml:13:18: event 1: trigger: unknown name `b` (names: x, k, a, d, t)",
        ),
        (
            "[[events]]\ntrigger = \"lt(x, a)\"\n",
            "saw.toml:12:1: [[events]] event 1: `set` is missing: the states it resets, like { x = \"0\" }",
        ),
        (
            "[[events]]\ntrigger = \"lt(x, a)\"\nset = { k = \"0\" }\n",
            "saw.toml:14:9: [[events]] event 1: `k` is not a state: an event resets states (states: x)",
        ),
        (
            "[[events]]\ntrigger = \"lt(x, a)\"\nset = { x = \"0\" }\ndelay = 1\n",
            "saw.toml:15:1: [[events]] event 1: unknown key `delay` (keys: trigger, set)",
        ),
    ] {
        let text = format!("{head}{events}");
        match ModelFile::parse(&text, Path::new("saw.toml")) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => assert_eq!(e.to_string(), expected, "model:\n{text}"),
        }
    }
}
