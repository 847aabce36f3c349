//! A study's directory: `study.json` (the settings and the truth), `trials.jsonl` (one line
//! per trial and method, appended as trials finish), `summary.json` and `summary.md`.
//!
//! A killed study loses nothing already written: each trial's lines go out in one write, and
//! `--resume` keeps every complete trial (a torn last line is dropped) and runs the rest. At
//! the end `trials.jsonl` is rewritten in trial order, so a study's files do not depend on
//! the thread count, on interruptions, or on how it was split into shards and merged; only
//! the measured times differ.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sysid_ode::System;

use crate::error::StudyError;
use crate::stats::{Summary, summarise};
use crate::trial::{REFERENCE, Study, StudySpec, TrialRecord};

/// The settings file of a study directory.
pub const STUDY_FILE: &str = "study.json";
/// One line per trial and method.
pub const TRIALS_FILE: &str = "trials.jsonl";
/// The statistics.
pub const SUMMARY_FILE: &str = "summary.json";
/// The statistics as tables.
pub const SUMMARY_MD: &str = "summary.md";

/// Part i of n of a study's trials (1 ≤ i ≤ n): the trials t with t mod n = i − 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which part, from 1.
    pub index: usize,
    /// Of how many.
    pub count: usize,
}

impl FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("a shard is written i/n with 1 ≤ i ≤ n, got `{s}`");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) =
            (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

impl Shard {
    /// Whether trial t belongs to this shard.
    pub fn contains(&self, t: usize) -> bool {
        t % self.count == self.index - 1
    }
}

/// `study.json`: the settings, the shard, and what the statistics compare against.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The settings.
    pub spec: StudySpec,
    /// The shard this directory holds, if it is one.
    pub shard: Option<Shard>,
    /// Names of the unknowns.
    pub unknowns: Vec<String>,
    /// Their true values.
    pub truth: Vec<f64>,
    /// Cramér–Rao standard deviations at the truth, for the study's noise level.
    pub crb_sd: Vec<f64>,
}

impl Header {
    /// The header of `study` (computes the Cramér–Rao bound).
    pub fn of<S: System + Clone + Send + Sync>(
        study: &Study<S>,
        shard: Option<Shard>,
    ) -> Result<Self, StudyError> {
        let crb = study.scenario().cramer_rao(study.spec().noise)?;
        Ok(Self {
            spec: study.spec().clone(),
            shard,
            unknowns: study.scenario().problem().names(),
            truth: study.scenario().truth().to_vec(),
            crb_sd: (0..crb.nrows()).map(|i| crb[(i, i)].sqrt()).collect(),
        })
    }

    /// The trials this directory is responsible for.
    pub fn trials(&self) -> Vec<usize> {
        (0..self.spec.trials).filter(|&t| self.shard.is_none_or(|s| s.contains(t))).collect()
    }

    /// Method names in the order of a trial's lines.
    fn line_order(&self) -> Vec<&str> {
        std::iter::once(REFERENCE).chain(self.spec.methods.iter().map(String::as_str)).collect()
    }

    fn summary(&self, records: &[TrialRecord]) -> Summary {
        summarise(&self.spec, &self.unknowns, &self.truth, &self.crb_sd, records)
    }
}

/// Runs `study` (or one shard of it) into `dir` and returns its summary. With `resume`, a
/// directory that holds a study must hold the same one, and its complete trials are kept; one
/// without a study starts it. Without `resume`, a directory that holds a study is refused. `progress(done, total)`
/// is called as trials finish.
pub fn run<S: System + Clone + Send + Sync>(
    study: &Study<S>,
    dir: &Path,
    shard: Option<Shard>,
    resume: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Summary, StudyError> {
    let header = Header::of(study, shard)?;
    std::fs::create_dir_all(dir).map_err(StudyError::io(dir))?;
    let study_file = dir.join(STUDY_FILE);
    let mut records = Vec::new();
    if study_file.exists() {
        if !resume {
            return Err(StudyError::Mismatch(format!(
                "{} already holds a study: give --resume to continue it, or another --out",
                dir.display()
            )));
        }
        let existing = read_header(&study_file)?;
        if existing != header {
            return Err(StudyError::Mismatch(format!(
                "{} holds a different study ({}); resume it with its own settings",
                dir.display(),
                difference(&existing, &header)
            )));
        }
        records = read_complete(dir, &header)?;
        // Start from the complete trials only: a torn line of a killed run goes.
        write_lines(&dir.join(TRIALS_FILE), &records)?;
    } else {
        // Nothing to resume starts the study: a requeued batch job runs with --resume always.
        write_atomically(&study_file, &json(&header))?;
        write_lines(&dir.join(TRIALS_FILE), &[])?;
    }
    let done: std::collections::BTreeSet<usize> = records.iter().map(|r| r.trial).collect();
    let todo: Vec<usize> = header.trials().into_iter().filter(|t| !done.contains(t)).collect();
    let trials_path = dir.join(TRIALS_FILE);
    let file =
        OpenOptions::new().append(true).open(&trials_path).map_err(StudyError::io(&trials_path))?;
    let out = Mutex::new(file);
    let finished = AtomicUsize::new(0);
    progress(0, todo.len());
    let new: Vec<Vec<TrialRecord>> = todo
        .par_iter()
        .map(|&t| {
            let lines = study.trial(t)?;
            let mut text = String::new();
            for r in &lines {
                text += &serde_json::to_string(r).expect("records serialise");
                text.push('\n');
            }
            // One write per trial: a kill tears at most the last line.
            let mut file = out.lock().unwrap_or_else(|e| e.into_inner());
            file.write_all(text.as_bytes()).map_err(StudyError::io(&trials_path))?;
            file.flush().map_err(StudyError::io(&trials_path))?;
            drop(file);
            progress(finished.fetch_add(1, Ordering::Relaxed) + 1, todo.len());
            Ok(lines)
        })
        .collect::<Result<_, StudyError>>()?;
    records.extend(new.into_iter().flatten());
    finish(dir, &header, records)
}

/// Sorts the records into trial order, rewrites `trials.jsonl`, writes the summary.
fn finish(
    dir: &Path,
    header: &Header,
    mut records: Vec<TrialRecord>,
) -> Result<Summary, StudyError> {
    let order = header.line_order();
    let rank = |m: &str| order.iter().position(|o| *o == m).unwrap_or(usize::MAX);
    records.sort_by(|a, b| a.trial.cmp(&b.trial).then(rank(&a.method).cmp(&rank(&b.method))));
    write_lines(&dir.join(TRIALS_FILE), &records)?;
    let summary = header.summary(&records);
    write_atomically(&dir.join(SUMMARY_FILE), &json(&summary))?;
    let mut md = summary.markdown();
    if let Some(s) = header.shard {
        md = format!(
            "Shard {}/{} of the study: its trials only; `sysid merge` combines the shards.\n\n{md}",
            s.index, s.count
        );
    }
    write_atomically(&dir.join(SUMMARY_MD), &md)?;
    Ok(summary)
}

/// Merges the shard directories `dirs` of one study into `out`: the same files an unsharded
/// run writes.
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<Summary, StudyError> {
    let Some(first) = dirs.first() else {
        return Err(StudyError::Setup("no shard directories to merge".into()));
    };
    let mut headers = Vec::new();
    for dir in dirs {
        headers.push(read_header(&dir.join(STUDY_FILE))?);
    }
    let whole = Header { shard: None, ..headers[0].clone() };
    let mut records = Vec::new();
    let mut seen = BTreeMap::new();
    for (dir, header) in dirs.iter().zip(&headers) {
        if (Header { shard: None, ..header.clone() }) != whole {
            return Err(StudyError::Mismatch(format!(
                "{} and {} hold different studies ({})",
                first.display(),
                dir.display(),
                difference(&headers[0], header)
            )));
        }
        let complete = read_complete(dir, header)?;
        let expected = header.trials().len();
        let got: std::collections::BTreeSet<usize> = complete.iter().map(|r| r.trial).collect();
        if got.len() != expected {
            return Err(StudyError::Mismatch(format!(
                "{} is incomplete: {} of its {expected} trials; finish it with --resume first",
                dir.display(),
                got.len()
            )));
        }
        for t in got {
            if let Some(other) = seen.insert(t, dir.clone()) {
                return Err(StudyError::Mismatch(format!(
                    "trial {t} is in both {} and {}: the same shard twice?",
                    other.display(),
                    dir.display()
                )));
            }
        }
        records.extend(complete);
    }
    if seen.len() != whole.spec.trials {
        let missing = (0..whole.spec.trials).filter(|t| !seen.contains_key(t)).count();
        return Err(StudyError::Mismatch(format!(
            "{missing} of {} trials are in none of the shards: is a shard missing?",
            whole.spec.trials
        )));
    }
    if out.join(STUDY_FILE).exists() {
        return Err(StudyError::Mismatch(format!(
            "{} already holds a study: merge into a new directory",
            out.display()
        )));
    }
    std::fs::create_dir_all(out).map_err(StudyError::io(out))?;
    write_atomically(&out.join(STUDY_FILE), &json(&whole))?;
    finish(out, &whole, records)
}

/// Reads a directory's `study.json`.
pub fn read_header(path: &Path) -> Result<Header, StudyError> {
    let text = std::fs::read_to_string(path).map_err(StudyError::io(path))?;
    serde_json::from_str(&text).map_err(|e| StudyError::Format {
        path: path.into(),
        line: e.line(),
        message: format!("not a study header: {e}"),
    })
}

/// The records of every complete trial in `dir` that belongs to `header`'s shard: all of
/// its lines present. A torn or incomplete last trial (a killed run) is left out; a bad
/// line anywhere else is an error.
pub fn read_complete(dir: &Path, header: &Header) -> Result<Vec<TrialRecord>, StudyError> {
    let path = dir.join(TRIALS_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(StudyError::Io { path, source: e }),
    };
    let order = header.line_order();
    let lines: Vec<&str> = text.lines().collect();
    let mut by_trial: BTreeMap<usize, Vec<TrialRecord>> = BTreeMap::new();
    for (i, line) in lines.iter().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let record: TrialRecord = match serde_json::from_str(line) {
            Ok(r) => r,
            // The last line of a killed run may be cut short.
            Err(_) if i + 1 == lines.len() && !text.ends_with('\n') => break,
            Err(e) => {
                return Err(StudyError::Format {
                    path: path.clone(),
                    line: i + 1,
                    message: format!("not a trial record: {e}"),
                });
            }
        };
        if !order.contains(&record.method.as_str()) || record.trial >= header.spec.trials {
            return Err(StudyError::Format {
                path: path.clone(),
                line: i + 1,
                message: format!(
                    "trial {} of `{}` does not belong to this study",
                    record.trial, record.method
                ),
            });
        }
        by_trial.entry(record.trial).or_default().push(record);
    }
    let mut out = Vec::new();
    for (t, lines) in by_trial {
        let complete = order.iter().all(|m| lines.iter().filter(|r| r.method == *m).count() == 1)
            && lines.len() == order.len();
        if complete && header.shard.is_none_or(|s| s.contains(t)) {
            out.extend(lines);
        }
    }
    Ok(out)
}

fn json<T: Serialize>(value: &T) -> String {
    serde_json::to_string_pretty(value).expect("serialisable") + "\n"
}

fn write_lines(path: &Path, records: &[TrialRecord]) -> Result<(), StudyError> {
    let mut text = String::new();
    for r in records {
        text += &serde_json::to_string(r).expect("records serialise");
        text.push('\n');
    }
    write_atomically(path, &text)
}

/// Writes through a temporary file and a rename: the file is either old or new, never half.
fn write_atomically(path: &Path, text: &str) -> Result<(), StudyError> {
    let tmp = path.with_extension("partial");
    let mut file = File::create(&tmp).map_err(StudyError::io(&tmp))?;
    file.write_all(text.as_bytes()).map_err(StudyError::io(&tmp))?;
    file.sync_all().map_err(StudyError::io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(StudyError::io(path))
}

/// Which setting differs between two headers, for messages.
fn difference(a: &Header, b: &Header) -> String {
    let (x, y) = (&a.spec, &b.spec);
    let mut diffs = Vec::new();
    let mut note = |what: &str, p: String, q: String| {
        if p != q {
            diffs.push(format!("{what} {p} vs {q}"));
        }
    };
    note("system", x.system.clone(), y.system.clone());
    note("methods", x.methods.join(","), y.methods.join(","));
    note("reference", x.reference.clone(), y.reference.clone());
    note("trials", x.trials.to_string(), y.trials.to_string());
    note("noise", x.noise.to_string(), y.noise.to_string());
    note("perturb", x.perturb.to_string(), y.perturb.to_string());
    note("seed", x.seed.to_string(), y.seed.to_string());
    let shard = |s: Option<Shard>| s.map_or("none".into(), |s| format!("{}/{}", s.index, s.count));
    note("shard", shard(a.shard), shard(b.shard));
    if diffs.is_empty() {
        diffs.push("the truth or the Cramér–Rao bound".into());
    }
    diffs.join(", ")
}
