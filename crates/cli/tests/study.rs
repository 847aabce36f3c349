//! `sysid study` and `sysid merge` as a user runs them: the files, the table, shards merged
//! into the unsharded study, resume, basin maps, and one-line errors with exit code 2.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sysid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sysid")).args(args).output().expect("the binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A scratch directory removed when the test ends.
struct Scratch(PathBuf);

impl Scratch {
    fn new(tag: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("sysid-cli-study-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a scratch directory");
        Scratch(dir)
    }

    fn path(&self, name: &str) -> String {
        self.0.join(name).display().to_string()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// trials.jsonl without the measured times: what must not depend on how the study ran.
fn untimed_trials(dir: &str) -> Vec<String> {
    let body = std::fs::read_to_string(Path::new(dir).join("trials.jsonl")).expect("trials.jsonl");
    body.lines()
        .map(|line| {
            let mut record: serde_json::Value = serde_json::from_str(line).expect("a JSON line");
            record.as_object_mut().expect("an object").remove("time_ms");
            record.to_string()
        })
        .collect()
}

const STUDY: [&str; 6] = ["study", "--system", "van-der-pol", "--trials", "12", "--perturb"];

fn study(out: &str, extra: &[&str]) -> Output {
    let mut args = STUDY.to_vec();
    args.extend(["0.1", "--out", out]);
    args.extend(extra);
    sysid(&args)
}

#[test]
fn a_study_writes_its_files_and_prints_the_table() {
    let scratch = Scratch::new("files");
    let out = scratch.path("vdp");
    let run = study(&out, &[]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let table = text(&run.stdout);
    for needle in [
        "# Study: van-der-pol",
        "| goodman |",
        "| quasilinearization |",
        "| gauss-newton-ls |",
        "Cramér–Rao σ",
    ] {
        assert!(table.contains(needle), "`{needle}` missing from\n{table}");
    }
    for file in ["study.json", "trials.jsonl", "summary.json", "summary.md"] {
        assert!(Path::new(&out).join(file).is_file(), "{file} missing");
    }
    // One line per trial and method (the reference fit included), in trial order.
    assert_eq!(untimed_trials(&out).len(), 12 * 4);
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(&out).join("summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(summary["trials"], 12);
    // A batch log gets plain progress lines (here after every trial), no bar.
    let logged = study(&scratch.path("logged"), &["--log-every", "1e-9"]);
    let lines = text(&logged.stderr);
    assert!(lines.contains("van-der-pol: 1/12 trials done") && !lines.contains('\r'), "{lines}");
    // No progress bar when stderr is not a terminal: one closing line only.
    assert_eq!(text(&run.stderr).lines().count(), 1, "{}", text(&run.stderr));
    // The table on stdout is summary.md.
    assert_eq!(table, std::fs::read_to_string(Path::new(&out).join("summary.md")).unwrap());
    // The settings as given, however small: the noise at the least the study takes was
    // printed as 150 decimal places ("noise 0.000…0001·σ").
    let tiny = sysid(&[
        "study",
        "--system",
        "falling-body",
        "--methods",
        "goodman",
        "--trials",
        "2",
        "--noise",
        "1e-150",
        "--out",
        &scratch.path("tiny"),
    ]);
    assert_eq!(tiny.status.code(), Some(0), "{}", text(&tiny.stderr));
    let table = text(&tiny.stdout);
    assert!(table.contains("2 trials, noise 1e-150·σ, starts perturbed by ρ = 0.2,"), "{table}");
}

#[test]
fn shards_merge_into_the_unsharded_study() {
    let scratch = Scratch::new("shards");
    let whole = scratch.path("whole");
    assert_eq!(study(&whole, &[]).status.code(), Some(0));
    let (one, two, merged) = (scratch.path("one"), scratch.path("two"), scratch.path("merged"));
    assert_eq!(study(&one, &["--shard", "1/2"]).status.code(), Some(0));
    assert_eq!(study(&two, &["--shard", "2/2"]).status.code(), Some(0));
    let merge = sysid(&["merge", &one, &two, "--out", &merged]);
    assert_eq!(merge.status.code(), Some(0), "{}", text(&merge.stderr));
    assert_eq!(untimed_trials(&merged), untimed_trials(&whole));
    // Merging again (a requeued merge job) rewrites the same files; a different study in
    // the directory is refused rather than mixed.
    let again = sysid(&["merge", &one, &two, "--out", &merged]);
    assert_eq!(again.status.code(), Some(0), "{}", text(&again.stderr));
    assert_eq!(untimed_trials(&merged), untimed_trials(&whole));
    let mixed = sysid(&["merge", &one, &two, "--out", &scratch.path("other")]);
    assert_eq!(mixed.status.code(), Some(0));
    let other = scratch.path("other");
    std::fs::write(Path::new(&other).join("study.json"), "{}").unwrap();
    let refused = sysid(&["merge", &one, &two, "--out", &other]);
    assert_eq!(refused.status.code(), Some(2));

    // merge --check tells each shard's count of trials, from the files alone.
    let check = sysid(&["merge", "--check", &one, &two]);
    assert_eq!(check.status.code(), Some(0), "{}", text(&check.stderr));
    let report = text(&check.stdout);
    assert!(
        report.contains("1/2          6/6 trials") && report.ends_with("complete\n"),
        "{report}"
    );
    let check = sysid(&["merge", "--check", &one]);
    assert_eq!(check.status.code(), Some(1), "one shard of two is not the study");
    let report = text(&check.stdout);
    assert!(
        report.contains("2/2          no directory given") && report.ends_with("incomplete: 2\n"),
        "{report}"
    );
    let lonely = sysid(&["merge", &one, "--out", &scratch.path("lonely")]);
    assert_eq!(lonely.status.code(), Some(2));
    let err = text(&lonely.stderr);
    assert!(
        err.contains("6 of 12 trials are in none of the shards")
            && err.contains("2/2 (no directory given)"),
        "{err}"
    );

    // Shards run with settings that change results do not merge: the setting is named.
    let steps = scratch.path("steps");
    assert_eq!(study(&steps, &["--shard", "2/2", "--max-steps", "700"]).status.code(), Some(0));
    let mixed = sysid(&["merge", &one, &steps, "--out", &scratch.path("never")]);
    assert_eq!(mixed.status.code(), Some(2));
    let err = text(&mixed.stderr);
    assert!(err.contains("integrator.max_steps 100000 vs 700"), "{err}");
    // The shards' own indices differ by design and are not named as a setting.
    assert!(!err.contains("shard.index"), "{err}");
    assert!(!Path::new(&scratch.path("never")).exists(), "a refused merge writes nothing");
    // Shards of two splits that overlap are named as such (it asked "the same shard twice?").
    let third = scratch.path("third");
    assert_eq!(study(&third, &["--shard", "1/3"]).status.code(), Some(0));
    let overlap = sysid(&["merge", &one, &third, "--out", &scratch.path("never")]);
    assert_eq!(overlap.status.code(), Some(2));
    let err = text(&overlap.stderr);
    assert!(
        err.contains("(shard 1/2) and")
            && err.contains("(shard 1/3): shards of different splits that overlap"),
        "{err}"
    );
    // A whole study that lacks trials is incomplete as a whole, not as shard "1".
    let cut = scratch.path("cut");
    std::fs::create_dir_all(&cut).unwrap();
    for f in ["study.json", "trials.jsonl"] {
        let text = std::fs::read_to_string(Path::new(&whole).join(f)).unwrap();
        let kept: String = match f {
            "trials.jsonl" => text.lines().take(5).map(|l| format!("{l}\n")).collect(),
            _ => text,
        };
        std::fs::write(Path::new(&cut).join(f), kept).unwrap();
    }
    let check = sysid(&["merge", "--check", &cut]);
    assert_eq!(check.status.code(), Some(1), "{}", text(&check.stderr));
    assert!(text(&check.stdout).ends_with("incomplete: whole study\n"), "{}", text(&check.stdout));
    // Nor do they make a complete study for --check (it said `complete`).
    let check = sysid(&["merge", "--check", &one, &steps]);
    assert_eq!(check.status.code(), Some(2), "{}", text(&check.stdout));
    let err = text(&check.stderr);
    assert!(err.contains("hold different studies: integrator.max_steps"), "{err}");
}

#[test]
fn settings_that_change_results_travel_with_the_study() {
    let scratch = Scratch::new("settings");
    let out = scratch.path("vdp");
    let short = ["study", "--system", "van-der-pol", "--trials", "2", "--out", &out];
    assert_eq!(sysid(&short).status.code(), Some(0));
    for (extra, needle) in [
        (vec!["--max-steps", "700"], "integrator.max_steps 100000 vs 700"),
        (vec!["--rtol", "1e-6"], "integrator.rtol 1e-8 vs 1e-6"),
        (vec!["--integrator", "rodas4"], "integrator.scheme dopri5 vs rodas4"),
        (vec!["--ql-start", "data"], "settings.ql_start guess vs data"),
        (vec!["--gtol", "1e-4"], "driver.gtol (not recorded) vs 0.0001"),
        (vec!["--max-iterations", "7"], "driver.max_iterations 3000 vs 7"),
    ] {
        let mut args = short.to_vec();
        args.push("--resume");
        args.extend(&extra);
        let run = sysid(&args);
        assert_eq!(run.status.code(), Some(2), "{extra:?}");
        let err = text(&run.stderr);
        assert!(
            err.contains(needle) && err.contains("holds a different study"),
            "{extra:?}: {err}"
        );
    }

    // Another build's trials are not mixed in: the study records the executable's SHA-256.
    let header_path = Path::new(&out).join("study.json");
    let header = std::fs::read_to_string(&header_path).unwrap();
    let recorded = "\"build\": \"sysid ";
    let at = header.find(recorded).expect("study.json records the build") + recorded.len();
    let (version, rest) = header[at..].split_once(", executable sha256:").unwrap();
    assert_eq!(version, env!("CARGO_PKG_VERSION"));
    let digest = &rest[..64];
    assert!(digest.bytes().all(|b| b.is_ascii_hexdigit()), "{header}");
    std::fs::write(&header_path, header.replace(digest, &"0".repeat(64))).unwrap();
    let mut args = short.to_vec();
    args.push("--resume");
    let other = sysid(&args);
    assert_eq!(other.status.code(), Some(2));
    assert!(
        text(&other.stderr)
            .contains(&format!("settings.build sysid {version}, executable sha256:000")),
        "{}",
        text(&other.stderr)
    );

    // A model file's study records the model's and the data's SHA-256.
    let dir = Path::new(&scratch.0).join("model");
    std::fs::create_dir_all(&dir).unwrap();
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/falling-body");
    for entry in std::fs::read_dir(&example).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
    }
    let model = dir.join("model.toml").display().to_string();
    let out = scratch.path("model-study");
    let args = ["study", "--model", &model, "--trials", "2", "--resume", "--out", &out];
    let first = sysid(&args);
    assert_eq!(first.status.code(), Some(0), "{}", text(&first.stderr));
    let header = std::fs::read_to_string(Path::new(&out).join("study.json")).unwrap();
    assert!(
        header.contains("\"model\": \"sha256:") && header.contains("\"data\": \"sha256:"),
        "{header}"
    );
    // The same file by another path (as from another folder) is the same study: the path
    // was compared as written (`system model.toml vs /work/model.toml`).
    let elsewhere = dir.join("..").join("model").join("model.toml").display().to_string();
    let again = ["study", "--model", &elsewhere, "--trials", "2", "--resume", "--out", &out];
    let again = sysid(&again);
    assert_eq!(again.status.code(), Some(0), "{}", text(&again.stderr));
    let text_model = std::fs::read_to_string(&model).unwrap();
    std::fs::write(&model, format!("{text_model}\n# edited\n")).unwrap();
    let edited = sysid(&args);
    assert_eq!(edited.status.code(), Some(2));
    assert!(text(&edited.stderr).contains("settings.model sha256:"), "{}", text(&edited.stderr));
}

#[test]
fn user_files_are_never_replaced() {
    let scratch = Scratch::new("owned");
    let out = scratch.path("mine");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(Path::new(&out).join("summary.md"), "my notes").unwrap();
    let run = study(&out, &[]);
    assert_eq!(run.status.code(), Some(2));
    let err = text(&run.stderr);
    assert!(
        err.contains("holds files sysid did not write (summary.md)") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(Path::new(&out).join("summary.md")).unwrap(), "my notes");
    std::fs::write(Path::new(&out).join("keep.txt"), "mine").unwrap();
    let forced = study(&out, &["--force"]);
    assert_eq!(forced.status.code(), Some(0), "{}", text(&forced.stderr));
    assert_eq!(std::fs::read_to_string(Path::new(&out).join("keep.txt")).unwrap(), "mine");

    // The report replaces what a report wrote, and nothing else.
    let reports = scratch.path("reports");
    let report = |extra: &[&str]| {
        let mut args = vec!["report", "--out", &reports, "--systems", "falling-body"];
        args.extend(["--trials", "4", "--grid", "3"]);
        args.extend(extra);
        sysid(&args)
    };
    std::fs::create_dir_all(Path::new(&reports).join("falling-body")).unwrap();
    std::fs::write(Path::new(&reports).join("falling-body/data.csv"), "mine").unwrap();
    std::fs::write(Path::new(&reports).join("falling-body/notes.md"), "mine").unwrap();
    let refused = report(&[]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(text(&refused.stderr).contains("falling-body/data.csv"), "{}", text(&refused.stderr));
    assert_eq!(
        std::fs::read_to_string(Path::new(&reports).join("falling-body/data.csv")).unwrap(),
        "mine"
    );
    let forced = report(&["--force"]);
    assert_eq!(forced.status.code(), Some(0), "{}", text(&forced.stderr));
    let again = report(&[]);
    assert_eq!(
        again.status.code(),
        Some(0),
        "a report replaces its own files: {}",
        text(&again.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(Path::new(&reports).join("falling-body/notes.md")).unwrap(),
        "mine"
    );
}

#[test]
fn resume_completes_a_cut_study() {
    let scratch = Scratch::new("resume");
    let whole = scratch.path("whole");
    assert_eq!(study(&whole, &[]).status.code(), Some(0));
    // A study killed after five trials, the sixth half written.
    let cut = scratch.path("cut");
    assert_eq!(study(&cut, &[]).status.code(), Some(0));
    let lines = std::fs::read_to_string(Path::new(&cut).join("trials.jsonl")).unwrap();
    let mut kept: String = lines.lines().take(5 * 4 + 2).map(|l| format!("{l}\n")).collect();
    kept.push_str(&lines.lines().nth(5 * 4 + 2).unwrap()[..40]);
    std::fs::write(Path::new(&cut).join("trials.jsonl"), kept).unwrap();
    std::fs::remove_file(Path::new(&cut).join("summary.json")).unwrap();
    std::fs::remove_file(Path::new(&cut).join("summary.md")).unwrap();
    // The temporary file of a write the kill cut short: the next run there removes it.
    let partial = Path::new(&cut).join(".summary.json.4242.partial");
    std::fs::write(&partial, "{\"half").unwrap();
    let without = study(&cut, &[]);
    assert_eq!(without.status.code(), Some(2), "a study directory needs --resume");
    assert!(text(&without.stderr).contains("--resume"), "{}", text(&without.stderr));
    let resumed = study(&cut, &["--resume"]);
    assert_eq!(resumed.status.code(), Some(0), "{}", text(&resumed.stderr));
    assert_eq!(untimed_trials(&cut), untimed_trials(&whole));
    assert!(!partial.exists(), "a killed run's temporary file stays behind");
}

#[test]
fn basin_map_over_two_unknowns() {
    let scratch = Scratch::new("basin");
    let out = scratch.path("basin");
    let run = sysid(&[
        "study",
        "--system",
        "van-der-pol",
        "--methods",
        "goodman",
        "--basin",
        "mu,x",
        "--grid",
        "5",
        "--perturb",
        "0.5",
        "--out",
        &out,
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let map: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(&out).join("basin.json")).unwrap())
            .unwrap();
    let text_map = serde_json::to_string(&map).unwrap();
    assert!(text_map.contains("mu") && text_map.contains("\"x\""), "{text_map}");
    assert!(Path::new(&out).join("basin.md").is_file());
    // The centre of the grid is the truth: Goodman converges there.
    assert!(text(&run.stdout).contains("goodman"), "{}", text(&run.stdout));
    // The markdown's rows as drawn: the second unknown's largest value on top.
    let md = std::fs::read_to_string(Path::new(&out).join("basin.md")).unwrap();
    assert!(md.contains("at the top") && md.contains("at the bottom"), "{md}");
    // A second map into the same folder is refused before the work (it replaced the first
    // silently), and the first stays.
    let again = sysid(&["study", "--system", "van-der-pol", "--basin", "mu,v", "--out", &out]);
    assert_eq!(again.status.code(), Some(2), "{}", text(&again.stdout));
    assert!(text(&again.stderr).contains("already holds a basin map"), "{}", text(&again.stderr));
    let kept = std::fs::read_to_string(Path::new(&out).join("basin.json")).unwrap();
    assert_eq!(serde_json::from_str::<serde_json::Value>(&kept).unwrap(), map);
}

#[test]
fn bad_study_input_exits_2_with_one_line() {
    let scratch = Scratch::new("bad");
    let out = scratch.path("never");
    for (args, needle) in [
        (vec!["study", "--system", "nope", "--out", &out], "unknown system `nope`"),
        (
            vec!["study", "--system", "van-der-pol", "--methods", "goodman,newton", "--out", &out],
            "newton",
        ),
        (vec!["study", "--system", "van-der-pol", "--shard", "3/2", "--out", &out], "3/2"),
        (
            vec!["study", "--system", "van-der-pol", "--noise", "0", "--out", &out],
            "--noise must be a positive multiple of σ, got 0",
        ),
        (
            vec!["study", "--system", "van-der-pol", "--basin", "mu,k", "--out", &out],
            "`k` is not an unknown",
        ),
        (vec!["study", "--system", "van-der-pol", "--basin", "mu", "--out", &out], "two unknowns"),
        // Sizes are checked before anything is allocated (these aborted, or ran out of
        // memory).
        (
            vec![
                "study",
                "--system",
                "van-der-pol",
                "--basin",
                "mu,x",
                "--grid",
                "4294967297",
                "--out",
                &out,
            ],
            "--grid must be from 2 to 1000 points per axis",
        ),
        (
            vec![
                "study",
                "--system",
                "van-der-pol",
                "--basin",
                "mu,x",
                "--grid",
                "20000",
                "--out",
                &out,
            ],
            "--grid must be from 2 to 1000 points per axis",
        ),
        (
            vec!["study", "--system", "van-der-pol", "--trials", "1000000000", "--out", &out],
            "--trials 1000000000 is above the limit of 1000000",
        ),
        (vec!["merge", "--out", &out, &out], "never"),
    ] {
        let run = sysid(&args);
        assert_eq!(run.status.code(), Some(2), "{args:?}: {}", text(&run.stderr));
        let err = text(&run.stderr);
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
        assert!(run.stdout.is_empty(), "{args:?}");
    }
    assert!(!Path::new(&out).exists(), "a failed study leaves no directory");
}

/// `report --scaling`: one NLL + gradient per problem folder, `<name>.yaml` or
/// `problem.yaml`, into OUT/scaling; the gradient's length is `evaluate`'s, the size n·p its
/// product with the states (Boehm: 8); a folder that does not import is listed with the
/// reason, and a directory that is not one exits 2.
#[test]
fn report_scaling_times_every_problem_and_names_the_ones_it_cannot() {
    let scratch = Scratch::new("scaling");
    let problems = Path::new(&scratch.path("problems")).to_path_buf();
    let boehm =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/petab/Boehm_JProteomeRes2014");
    for (folder, yaml) in
        [("Boehm_JProteomeRes2014", "Boehm_JProteomeRes2014.yaml"), ("Boehm_copy", "problem.yaml")]
    {
        let into = problems.join(folder);
        std::fs::create_dir_all(&into).unwrap();
        for entry in std::fs::read_dir(&boehm).unwrap() {
            let from = entry.unwrap().path();
            let name = from.file_name().unwrap().to_string_lossy().to_string();
            let name = if name.ends_with(".yaml") { yaml.to_string() } else { name };
            std::fs::copy(&from, into.join(name)).unwrap();
        }
    }
    std::fs::create_dir_all(problems.join("Broken_one")).unwrap();
    std::fs::write(problems.join("Broken_one/Broken_one.yaml"), "format_version: 1\n").unwrap();
    let out = scratch.path("reports");
    let dir = problems.display().to_string();
    let run = sysid(&[
        "report",
        "--scaling",
        &dir,
        "--out",
        &out,
        "--scaling-repeat",
        "2",
        "--scaling-seconds",
        "1",
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let written = Path::new(&out).join("scaling");
    for file in ["README.md", "scaling.png", "scaling.svg", "scaling.csv"] {
        assert!(written.join(file).is_file(), "{file} missing");
    }
    let yaml = boehm.join("Boehm_JProteomeRes2014.yaml").display().to_string();
    let evaluated = sysid(&["evaluate", "--petab", &yaml, "--gradient", "--format", "json"]);
    let evaluated: serde_json::Value = serde_json::from_slice(&evaluated.stdout).unwrap();
    let p = evaluated["gradient"].as_object().expect("a gradient").len();
    let csv = std::fs::read_to_string(written.join("scaling.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2, "{csv}");
    for row in &rows {
        assert!(row[0].starts_with("Boehm"), "{csv}");
        assert_eq!((row[1], row[2]), ("8", p.to_string().as_str()), "{csv}");
        assert_eq!(row[3], (8 * p).to_string(), "{csv}");
        let ms: f64 = row[7].parse().unwrap();
        assert!(ms > 0.0 && ms.is_finite(), "{csv}");
    }
    let readme = std::fs::read_to_string(written.join("README.md")).unwrap();
    assert!(readme.contains("| Broken_one | not measured: "), "{readme}");
    assert!(readme.contains("![ms per NLL + gradient"), "{readme}");
    let svg = std::fs::read_to_string(written.join("scaling.svg")).unwrap();
    assert!(svg.contains("states × parameters"), "axis label missing");
    let bad = sysid(&["report", "--scaling", &scratch.path("nowhere"), "--out", &out]);
    assert_eq!(bad.status.code(), Some(2));
    let err = text(&bad.stderr);
    assert!(err.lines().count() == 1 && err.contains("--scaling"), "{err}");
}

#[test]
fn report_writes_figures_data_and_readme() {
    let scratch = Scratch::new("report");
    let out = scratch.path("reports");
    let run = sysid(&[
        "report",
        "--out",
        &out,
        "--systems",
        "falling-body,falling-body-continuous",
        "--trials",
        "6",
        "--grid",
        "3",
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    let fb = Path::new(&out).join("falling-body");
    for file in [
        "convergence.png",
        "convergence.svg",
        "convergence.csv",
        "prediction.png",
        "prediction.svg",
        "prediction.csv",
        "data.csv",
        "accuracy.png",
        "accuracy.svg",
        "cost.png",
        "cost.svg",
        "basin.png",
        "basin.svg",
        "study/trials.jsonl",
        "study/summary.json",
        "basin/basin.json",
    ] {
        assert!(fb.join(file).is_file(), "{file} missing");
    }
    // PNGs are PNGs; SVGs carry their text.
    let png = std::fs::read(fb.join("convergence.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let svg = std::fs::read_to_string(fb.join("convergence.svg")).unwrap();
    assert!(svg.contains("iteration") && svg.contains("goodman"), "axis label or legend missing");
    let readme = std::fs::read_to_string(Path::new(&out).join("README.md")).unwrap();
    assert!(readme.contains("## falling-body\n"), "{readme}");
    assert!(readme.contains("![convergence](falling-body/convergence.png)"), "{readme}");
    // The continuous record has no study, and the report says why.
    assert!(readme.contains("No Monte-Carlo study for this system"), "{readme}");
    let bad = sysid(&["report", "--out", &out, "--systems", "nope"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(text(&bad.stderr).contains("unknown system `nope`"));
}
