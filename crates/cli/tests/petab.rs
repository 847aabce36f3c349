//! PEtab problems from the command line: `--petab` on the commands that read a problem,
//! the NLL at nominal in the JSON, refusals with exit 2 and one line.

use std::path::PathBuf;
use std::process::{Command, Output};

fn sysid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sysid")).args(args).output().expect("the binary runs")
}

fn problem(name: &str) -> String {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/petab");
    root.join(name).join(format!("{name}.yaml")).display().to_string()
}

/// `fit --max-iterations 0` evaluates at the nominal parameters: Boehm's NLL is AMICI's
/// reference to 1e-3 (AMICI's own check; 8.4e-7 here).
#[test]
fn fit_at_nominal_prints_the_nll() {
    let boehm = problem("Boehm_JProteomeRes2014");
    let out = sysid(&["fit", "--petab", &boehm, "--max-iterations", "0", "--format", "json"]);
    let json: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("JSON on standard output");
    let nll = json["nll"].as_f64().expect("an nll");
    assert!((nll - 138.22199693517703).abs() <= 1e-3, "{nll}");
    assert_eq!(json["iterations"].as_u64(), Some(0));
}

/// A start whose sensitivities cannot be integrated (Smith's switch on a state), a missing
/// file, and --petab with --model or --data: exit 2, one line naming it. Smith itself, with
/// its events, simulates: its event-set species is the state `Ins_before_events`, and its
/// CSV keeps every digit in at most 24 characters a value.
#[test]
fn refusals_exit_2_with_one_line() {
    let smith = problem("Smith_BMCSystBiol2013");
    let boehm = problem("Boehm_JProteomeRes2014");
    let out = sysid(&["simulate", "--petab", smith.as_str(), "--times", "0:30:10"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(csv.lines().next().is_some_and(|h| h.contains(",Ins_before_events,")), "{csv}");
    // Every value reads back, and a tiny one (Ins_InR falls to 1e-196 by t = 30) is written
    // in exponent form, not as two hundred digits.
    for line in csv.lines().skip(1) {
        for cell in line.split(',').skip(1) {
            assert!(cell.parse::<f64>().is_ok() && cell.len() <= 24, "`{cell}` in {line}");
        }
    }
    for (args, expected) in [
        (
            vec!["fit", "--petab", smith.as_str()],
            "the model alone integrates there, its sensitivities do not",
        ),
        (vec!["fit", "--petab", "no/such.yaml"], "no/such.yaml: cannot be read"),
        (vec!["fit", "--petab", boehm.as_str(), "--model", "m.toml"], "cannot be used with"),
        (vec!["fit", "--petab", boehm.as_str(), "--data", "d.csv"], "cannot be used with"),
    ] {
        let out = sysid(&args);
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(out.stdout.is_empty());
    }
}

/// Every command that reads a problem reads a PEtab problem: `compare` runs every method on
/// Boehm's (each certifies, fails or refuses by name, and the ones that certify agree on the
/// NLL to 1e-6), `predict` writes the fitted trajectory.
#[test]
fn compare_and_predict_read_a_petab_problem() {
    let boehm = problem("Boehm_JProteomeRes2014");
    let out = sysid(&["compare", "--petab", &boehm, "--format", "json"]);
    assert!(out.status.code().is_some_and(|c| c <= 1), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let records = json.as_array().expect("an array");
    assert_eq!(records.len(), sysid_registry::ENTRIES.len(), "{json}");
    let certified: Vec<f64> = records
        .iter()
        .filter(|r| r["converged"].as_bool() == Some(true))
        .filter_map(|r| r["nll"].as_f64())
        .collect();
    assert!(!certified.is_empty(), "{json}");
    for nll in &certified {
        assert!((nll - certified[0]).abs() <= 1e-6, "{certified:?}");
    }
    let out =
        sysid(&["predict", "--petab", &boehm, "--method", "levenberg-marquardt", "--until", "300"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().next().is_some_and(|h| h.contains("STAT5A")), "{text}");
}
