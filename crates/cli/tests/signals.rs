//! Ctrl-C and SIGTERM in the long commands (docs/terminations.md, "Stopping a run"): the run
//! stops at its next iteration, prints what it has, keeps what it wrote, and then ends by the
//! signal. Unix only: the signals are sent with kill(1).
#![cfg(unix)]

use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn spawn(args: &[&str]) -> Child {
    spawn_from(Command::new(env!("CARGO_BIN_EXE_sysid")).args(args))
}

fn spawn_from(command: &mut Command) -> Child {
    command
        .env("RAYON_NUM_THREADS", "2")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs")
}

fn send(child: &Child, signal: &str) {
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("kill(1) runs");
    assert!(status.success(), "kill {signal} failed");
}

/// Waits until `ready` holds (polled every 20 ms), at most a minute.
fn wait_for(what: &str, ready: impl Fn() -> bool) {
    let began = Instant::now();
    while !ready() {
        assert!(began.elapsed() < Duration::from_secs(60), "waited a minute for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn petab(name: &str) -> String {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/petab");
    root.join(name).join(format!("{name}.yaml")).display().to_string()
}

/// The fit's progress line on stderr (`--log-every`), read as it comes: the signal is sent
/// once the fit is iterating, not while the problem is being imported.
fn stopped_after_a_progress_line(args: &[&str], signal: &str) -> Output {
    stopped_after_a_progress_line_of(spawn(args), &[signal])
}

/// As above, for a child already started; the signals sent in turn, a second apart.
fn stopped_after_a_progress_line_of(mut child: Child, signals: &[&str]) -> Output {
    use std::io::{BufRead, BufReader};
    let stderr = child.stderr.take().expect("stderr piped");
    let mut lines = BufReader::new(stderr).lines().map_while(Result::ok);
    let mut seen: Vec<String> = Vec::new();
    for line in lines.by_ref() {
        let progress = line.contains(": iteration ") || line.contains(" starts done");
        seen.push(line);
        if progress {
            break;
        }
    }
    for (k, signal) in signals.iter().enumerate() {
        if k > 0 {
            std::thread::sleep(Duration::from_secs(1));
            assert!(child.try_wait().expect("the child").is_none(), "ended on {}", signals[k - 1]);
        }
        send(&child, signal);
    }
    seen.extend(lines);
    let mut out = child.wait_with_output().expect("the run ends");
    out.stderr = seen.join("\n").into_bytes();
    out
}

/// Borghans' default fit from nominal takes 3 000 iterations (about 30 s); Ctrl-C after its
/// first progress line ends it with its best point, printed as JSON, the termination
/// `interrupted`, and the process ends by SIGINT (a shell's 130).
#[test]
fn ctrl_c_ends_a_fit_with_its_best_point_printed() {
    let problem = petab("Borghans_BiophysChem1997");
    let args = ["fit", "--petab", &problem, "--format", "json", "--log-every", "0.2"];
    let out = stopped_after_a_progress_line(&args, "-INT");
    let stderr = text(&out.stderr);
    assert_eq!(out.status.signal(), Some(2), "{:?}: {stderr}", out.status);
    assert!(
        stderr.contains("Ctrl-C (SIGINT) received: stopping at the next iteration"),
        "{stderr}"
    );
    let record: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the fit's JSON");
    assert_eq!(record["termination_code"], "interrupted", "{record}");
    assert_eq!(record["converged"], false);
    let iterations = record["iterations"].as_u64().expect("iterations");
    assert!((1..3000).contains(&iterations), "{iterations}");
    // The best point, not the start: its NLL below the nominal one (−83.3).
    let nll = record["nll"].as_f64().expect("an NLL");
    assert!(nll < -83.3, "{nll}");
    let estimates = record["estimates"].as_object().expect("estimates");
    assert!(
        !estimates.is_empty() && estimates.values().all(|v| v.as_f64().is_some_and(f64::is_finite))
    );
}

/// A second Ctrl-C ends the process at once, by SIGINT, printing nothing more (the first's
/// stop would print the fit after its iteration and the certificate's reference
/// integration, tens of milliseconds; the second comes a few milliseconds after it).
#[test]
fn a_second_ctrl_c_quits_at_once() {
    use std::io::{BufRead, BufReader};
    let problem = petab("Borghans_BiophysChem1997");
    let mut child = spawn(&["fit", "--petab", &problem, "--format", "json", "--log-every", "0.2"]);
    let stderr = child.stderr.take().expect("stderr piped");
    let mut lines = BufReader::new(stderr).lines().map_while(Result::ok);
    assert!(lines.by_ref().any(|l| l.contains(": iteration ")), "no progress line");
    send(&child, "-INT");
    send(&child, "-INT");
    let _rest: Vec<String> = lines.collect();
    let out = child.wait_with_output().expect("the run ends");
    assert_eq!(out.status.signal(), Some(2), "{:?}", out.status);
    assert!(out.stdout.is_empty(), "{}", text(&out.stdout));
}

/// A SIGINT ignored as sysid starts (as a shell starts a script's background job) stays
/// ignored: the fit goes on past it, and SIGTERM then stops it as usual.
#[test]
fn an_ignored_sigint_stays_ignored() {
    let problem = petab("Borghans_BiophysChem1997");
    let child = spawn_from(Command::new("sh").args([
        "-c",
        "trap '' INT; exec \"$0\" fit --petab \"$1\" --format json --log-every 0.2",
        env!("CARGO_BIN_EXE_sysid"),
        &problem,
    ]));
    let out = stopped_after_a_progress_line_of(child, &["-INT", "-TERM"]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.signal(), Some(15), "{:?}: {stderr}", out.status);
    assert!(!stderr.contains("SIGINT") && stderr.contains("SIGTERM received"), "{stderr}");
    let record: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the fit's JSON");
    assert_eq!(record["termination_code"], "interrupted", "{record}");
}

/// SIGTERM (a batch job's time limit) stops a multistart: no start is begun after it, the
/// JSON says `stopped` and counts the starts not begun, and the process ends by SIGTERM.
#[test]
fn sigterm_stops_a_multistart_and_says_so() {
    let problem = petab("Borghans_BiophysChem1997");
    let args = [
        "fit",
        "--petab",
        &problem,
        "--starts",
        "400",
        "--starts-without-guess",
        "--format",
        "json",
        "--log-every",
        "0.2",
    ];
    let out = stopped_after_a_progress_line(&args, "-TERM");
    let stderr = text(&out.stderr);
    assert_eq!(out.status.signal(), Some(15), "{:?}: {stderr}", out.status);
    let record: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the fit's JSON");
    let starts = &record["starts"];
    assert_eq!(starts["stopped"], true, "{starts}");
    let (count, not_started) = (starts["count"].as_u64(), starts["not_started"].as_u64());
    let (count, not_started) = (count.expect("count"), not_started.expect("not_started"));
    assert_eq!(count + not_started, 400);
    assert!(not_started > 0, "{count} fitted");
    assert_eq!(starts["waterfall"].as_array().expect("waterfall").len() as u64, count);
}

/// A study stopped by Ctrl-C keeps its complete trials, each the same as an uninterrupted
/// study's (but for the measured times); the trials running when the signal came are not
/// written, no summary is written, and the message says how many are kept.
#[test]
fn ctrl_c_keeps_a_studys_complete_trials_and_only_those() {
    let dir = std::env::temp_dir().join(format!("sysid-cli-signals-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (stopped, whole) = (dir.join("stopped"), dir.join("whole"));
    let trials = |d: &PathBuf| std::fs::read_to_string(d.join("trials.jsonl")).unwrap_or_default();
    let args = |out: &PathBuf, n: &str| {
        let out = out.display().to_string();
        let list = ["study", "--system", "van-der-pol", "--methods", "goodman", "--trials", n];
        let mut v: Vec<String> = list.iter().map(|s| s.to_string()).collect();
        v.extend(["--out".to_string(), out]);
        v
    };
    let big = args(&stopped, "200000");
    let child = spawn(&big.iter().map(String::as_str).collect::<Vec<_>>());
    wait_for("40 lines in trials.jsonl", || trials(&stopped).lines().count() >= 40);
    send(&child, "-INT");
    let out = child.wait_with_output().expect("the study ends");
    let stderr = text(&out.stderr);
    assert_eq!(out.status.signal(), Some(2), "{:?}: {stderr}", out.status);
    assert!(out.stdout.is_empty(), "{}", text(&out.stdout));
    assert!(!stopped.join("summary.json").exists() && !stopped.join("summary.md").exists());
    // The records without their measured times, each line whole JSON.
    let untimed = |d: &PathBuf| -> Vec<serde_json::Value> {
        let lines = trials(d);
        let record = |l: &str| {
            let mut r: serde_json::Value = serde_json::from_str(l).expect("a whole JSON line");
            r.as_object_mut().expect("an object").remove("time_ms");
            r
        };
        lines.lines().map(record).collect()
    };
    let kept = untimed(&stopped);
    // Two lines a trial (the reference fit and goodman), each trial whole.
    assert_eq!(kept.len() % 2, 0, "{} lines", kept.len());
    let count = kept.len() / 2;
    assert!(
        stderr.contains(&format!("stopped: {count} of the 200000 trials are complete")),
        "{count}: {stderr}"
    );
    let cut_short = |r: &serde_json::Value| {
        r["termination"].as_str().is_none_or(|t| t.starts_with("interrupted"))
    };
    assert!(!kept.iter().any(cut_short), "a trial cut short was written");
    // rayon splits the trials' range between the threads, so the kept trials are runs of
    // numbers from 0 and from further on: those below 200 are checked against 200 trials run
    // whole (the records of a trial do not depend on the study's size).
    let ran = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .args(args(&whole, "200"))
        .output()
        .expect("the binary runs");
    assert!(ran.status.success(), "{}", text(&ran.stderr));
    let reference = untimed(&whole);
    let early: Vec<&serde_json::Value> =
        kept.iter().filter(|r| r["trial"].as_u64() < Some(200)).collect();
    assert!(!early.is_empty(), "no kept trial below 200");
    for r in early {
        assert!(reference.contains(r), "a kept trial differs from the uninterrupted study's: {r}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
