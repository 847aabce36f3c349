//! A study's directory: `study.json` (the settings and the truth), `trials.jsonl` (one line
//! per trial and method, appended as trials finish), `summary.json` and `summary.md`, and
//! `.sysid.lock`, held while a run writes there.
//!
//! sysid writes and replaces only these files (and `basin.json`, `basin.md` of a basin map):
//! a directory that holds anything else is refused unless the caller forces it, and a
//! second run into a directory another run holds is refused at once, naming the holder.
//! `study.json` records every setting that decides a trial's result (the integrator, the
//! driver's budgets, method options, the model and data files' SHA-256); `--resume` and
//! `merge` compare them and name the setting that differs.
//!
//! A killed study loses nothing already written: each trial's lines go out in one write, and
//! `--resume` keeps every complete trial (a torn last line is dropped) and runs the rest. At
//! the end `trials.jsonl` is rewritten in trial order, so a study's files do not depend on
//! the thread count, on interruptions, or on how it was split into shards and merged; only
//! the measured times differ.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use sysid_ode::{Integrator, System};

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
/// A basin map's numbers.
pub const BASIN_FILE: &str = "basin.json";
/// A basin map as text.
pub const BASIN_MD: &str = "basin.md";
/// Held (flock) by the run that writes the directory; names it.
pub const LOCK_FILE: &str = ".sysid.lock";
/// Every file sysid writes into a study directory (besides its own temporary files).
pub const OWNED: [&str; 7] =
    [STUDY_FILE, TRIALS_FILE, SUMMARY_FILE, SUMMARY_MD, BASIN_FILE, BASIN_MD, LOCK_FILE];

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
    /// The integrator every trial's fits ran with (absent in studies written before it was
    /// recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrator: Option<Integrator>,
    /// Names of the unknowns.
    pub unknowns: Vec<String>,
    /// Their true values.
    pub truth: Vec<f64>,
    /// Cramér–Rao standard deviations at the truth, for the study's noise level.
    pub crb_sd: Vec<f64>,
}

impl Header {
    /// This header under `other`'s name where both record the same model by its content
    /// (settings `model`, a digest of the file): a model file's study is named by its path as
    /// given, and `m.toml` run from its folder is `/work/m.toml` from elsewhere (a batch job's
    /// folder, a shard's). Another system is another study.
    fn named_as(&self, other: &Header) -> Header {
        let digest = |h: &Header| h.spec.settings.get("model").cloned();
        let mut header = self.clone();
        if digest(self).is_some() && digest(self) == digest(other) {
            header.spec.system = other.spec.system.clone();
        }
        header
    }

    /// The header of `study` (computes the Cramér–Rao bound).
    pub fn of<S: System + Clone + Send + Sync>(
        study: &Study<S>,
        shard: Option<Shard>,
    ) -> Result<Self, StudyError> {
        let crb = study.scenario().cramer_rao(study.spec().noise)?;
        Ok(Self {
            spec: study.spec().clone(),
            shard,
            integrator: Some(*study.scenario().problem().integrator()),
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

/// Where and how a study run writes.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunOptions {
    /// Run only this part of the trials.
    pub shard: Option<Shard>,
    /// Continue the study the directory holds, keeping its complete trials (or start it, if
    /// it holds none: batch jobs can always pass it).
    pub resume: bool,
    /// Write into a directory that holds files sysid did not write (sysid still replaces
    /// only the files it names in [`OWNED`]).
    pub force: bool,
}

/// Runs `study` (or one shard of it) into `dir` and returns its summary. With `resume`, a
/// directory that holds a study must hold the same one, and its complete trials are kept; one
/// without a study starts it. Without `resume`, a directory that holds a study is refused.
/// `progress(done, total)` is called as trials finish.
pub fn run<S: System + Clone + Send + Sync>(
    study: &Study<S>,
    dir: &Path,
    options: RunOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Summary, StudyError> {
    let header = Header::of(study, options.shard)?;
    check_owned(dir, options.force)?;
    let _lock = DirLock::acquire(dir)?;
    let study_file = dir.join(STUDY_FILE);
    let mut records = Vec::new();
    if study_file.exists() {
        if !options.resume {
            return Err(StudyError::Mismatch(format!(
                "{} already holds a study: give --resume to continue it, or another --out",
                dir.display()
            )));
        }
        let existing = read_header(&study_file)?;
        let header = header.named_as(&existing);
        if existing != header {
            return Err(StudyError::Mismatch(format!(
                "{} holds a different study: {} (its setting first); resume it with its own \
                 settings, or give another --out",
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
    let done: BTreeSet<usize> = records.iter().map(|r| r.trial).collect();
    let todo: Vec<usize> = header.trials().into_iter().filter(|t| !done.contains(t)).collect();
    let trials_path = dir.join(TRIALS_FILE);
    let file =
        OpenOptions::new().append(true).open(&trials_path).map_err(StudyError::io(&trials_path))?;
    let out = Mutex::new(file);
    let finished = AtomicUsize::new(0);
    progress(0, todo.len());
    // The caller's stop flag: once set, no trial is begun, and a trial that ends after it is
    // not written (a fit of it may have been cut short); --resume runs those again.
    let stop = sysid_core::observer::current_stop();
    let stopped = || stop.as_ref().is_some_and(|s| s.requested());
    let new: Vec<Option<Vec<TrialRecord>>> = todo
        .par_iter()
        .map(|&t| {
            if stopped() {
                return Ok(None);
            }
            let lines = sysid_core::observer::stop_within(stop.clone(), || study.trial(t))?;
            if stopped() {
                return Ok(None);
            }
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
            Ok(Some(lines))
        })
        .collect::<Result<_, StudyError>>()?;
    if new.iter().any(Option::is_none) {
        let kept = new.iter().flatten().count();
        return Err(StudyError::Interrupted(format!(
            "stopped: {} of the {} trials{} are complete in {} ({kept} of them this run), {} \
             not run",
            done.len() + kept,
            header.trials().len(),
            if header.shard.is_some() { " of this shard" } else { "" },
            trials_path.display(),
            todo.len() - kept
        )));
    }
    records.extend(new.into_iter().flatten().flatten());
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
/// run writes. Merging again into an `out` that holds the same study rewrites the same
/// files, so a repeated merge job succeeds; one holding another study is refused. `force`
/// as in [`RunOptions`].
pub fn merge(dirs: &[PathBuf], out: &Path, force: bool) -> Result<Summary, StudyError> {
    let Some(first) = dirs.first() else {
        return Err(StudyError::Setup("no shard directories to merge".into()));
    };
    // The merge reads the shards' files and writes the same names in `out`.
    if let Ok(target) = out.canonicalize()
        && let Some(dir) = dirs.iter().find(|d| d.canonicalize().is_ok_and(|d| d == target))
    {
        return Err(StudyError::Setup(format!(
            "{} is one of the shards being merged ({}): merge into a new directory, or the shard's files would be overwritten",
            out.display(),
            dir.display()
        )));
    }
    let mut headers = Vec::new();
    let mut locks = BTreeMap::new();
    for dir in dirs {
        headers.push(read_header(&dir.join(STUDY_FILE))?);
        // A shard still being written is not merged (a shard given twice is locked once,
        // and refused below).
        let key = dir.canonicalize().map_err(StudyError::io(dir))?;
        if let std::collections::btree_map::Entry::Vacant(slot) = locks.entry(key) {
            slot.insert(DirLock::acquire(dir)?);
        }
    }
    let whole = Header { shard: None, ..headers[0].clone() };
    for (dir, header) in dirs.iter().zip(&headers) {
        let header = Header { shard: None, ..header.named_as(&whole) };
        if header != whole {
            return Err(StudyError::Mismatch(format!(
                "{} and {} hold different studies: {}",
                first.display(),
                dir.display(),
                difference(&whole, &header)
            )));
        }
    }
    let mut records = Vec::new();
    let mut seen: BTreeMap<usize, (PathBuf, Option<Shard>)> = BTreeMap::new();
    let mut lacking = Vec::new();
    for (dir, header) in dirs.iter().zip(&headers) {
        let complete = read_complete(dir, header)?;
        let got: BTreeSet<usize> = complete.iter().map(|r| r.trial).collect();
        let expected = header.trials().len();
        if got.len() != expected {
            lacking.push(format!(
                "{} ({} of {expected} trials in {})",
                shard_name(header.shard),
                got.len(),
                dir.display()
            ));
        }
        for t in got {
            if let Some((other, shard)) = seen.insert(t, (dir.clone(), header.shard)) {
                // Shards of one split never share a trial; of two splits (1/4 beside 2/3)
                // they may.
                let why = match (shard == header.shard, shard.is_none() || header.shard.is_none()) {
                    (true, _) => "the same shard twice?",
                    (false, true) => {
                        "a whole study holds every trial: merge its shards or take it alone"
                    }
                    (false, false) => "shards of different splits that overlap",
                };
                let of = |s: Option<Shard>| match s {
                    Some(s) => format!("shard {}/{}", s.index, s.count),
                    None => "the whole study".into(),
                };
                return Err(StudyError::Mismatch(format!(
                    "trial {t} is in both {} ({}) and {} ({}): {why}",
                    other.display(),
                    of(shard),
                    dir.display(),
                    of(header.shard)
                )));
            }
        }
        records.extend(complete);
    }
    for index in missing_shards(headers.iter().map(|h| h.shard)) {
        let count = headers[0].shard.map_or(1, |s| s.count);
        lacking.push(format!("{index}/{count} (no directory given)"));
    }
    if !lacking.is_empty() || seen.len() != whole.spec.trials {
        let missing = (0..whole.spec.trials).filter(|t| !seen.contains_key(t)).count();
        return Err(StudyError::Incomplete(format!(
            "{missing} of {} trials are in none of the shards; shards missing or incomplete: \
             {}. Finish them (study --resume with the same --shard) and merge again",
            whole.spec.trials,
            lacking.join(", ")
        )));
    }
    check_owned(out, force)?;
    let _lock = DirLock::acquire(out)?;
    drop(locks);
    let out_file = out.join(STUDY_FILE);
    if out_file.exists() {
        let existing = read_header(&out_file)?;
        if existing != whole {
            return Err(StudyError::Mismatch(format!(
                "{} already holds another study: {} (its setting first); merge into a new \
                 directory",
                out.display(),
                difference(&existing, &whole)
            )));
        }
    }
    write_atomically(&out_file, &json(&whole))?;
    finish(out, &whole, records)
}

/// How far one shard directory has come, from its files alone.
#[derive(Clone, Debug)]
pub struct ShardProgress {
    /// The directory.
    pub dir: PathBuf,
    /// Its shard (None for a whole study).
    pub shard: Option<Shard>,
    /// Complete trials written.
    pub done: usize,
    /// Trials it is responsible for.
    pub expected: usize,
}

/// The progress of each of `dirs` (shards of one study, or any studies), read without
/// locking: a running shard shows what it has written so far.
pub fn progress(dirs: &[PathBuf]) -> Result<Vec<ShardProgress>, StudyError> {
    let mut out = Vec::new();
    for dir in dirs {
        let header = read_header(&dir.join(STUDY_FILE))?;
        let done: BTreeSet<usize> = read_complete(dir, &header)?.iter().map(|r| r.trial).collect();
        out.push(ShardProgress {
            dir: dir.clone(),
            shard: header.shard,
            done: done.len(),
            expected: header.trials().len(),
        });
    }
    Ok(out)
}

/// The shard indices of the study that none of `given` (the shards at hand, of one study) is:
/// 1..=n less those given, n from the first; none for a whole study.
pub fn missing_shards(mut given: impl Iterator<Item = Option<Shard>>) -> Vec<usize> {
    let Some(Some(first)) = given.next() else { return Vec::new() };
    let present: BTreeSet<usize> =
        std::iter::once(first.index).chain(given.flatten().map(|s| s.index)).collect();
    (1..=first.count).filter(|i| !present.contains(i)).collect()
}

/// What `sysid merge --check` prints for the shard directories `dirs`: a line per shard
/// with its trials done, a line per shard of the study that was not given, and a last line
/// `complete` or `incomplete: 3,7` (shard indices); with whether the study is complete.
pub fn check(dirs: &[PathBuf]) -> Result<(String, bool), StudyError> {
    // Shards of different studies never make one complete study, whatever their counts.
    let headers =
        dirs.iter().map(|d| read_header(&d.join(STUDY_FILE))).collect::<Result<Vec<_>, _>>()?;
    if let (Some(first), Some(dir)) = (headers.first(), dirs.first()) {
        let whole = Header { shard: None, ..first.clone() };
        for (other, header) in dirs.iter().zip(&headers) {
            if (Header { shard: None, ..header.clone() }) != whole {
                return Err(StudyError::Mismatch(format!(
                    "{} and {} hold different studies: {}",
                    dir.display(),
                    other.display(),
                    difference(&whole, &Header { shard: None, ..header.clone() })
                )));
            }
        }
    }
    let shards = progress(dirs)?;
    let mut text = String::new();
    let mut incomplete = BTreeSet::new();
    for s in &shards {
        let name = shard_name(s.shard);
        text += &format!("{name:<12} {}/{} trials  {}\n", s.done, s.expected, s.dir.display());
        if s.done < s.expected {
            incomplete.insert(s.shard.map_or(1, |s| s.index));
        }
    }
    for index in missing_shards(shards.iter().map(|s| s.shard)) {
        let count = shards[0].shard.map_or(1, |s| s.count);
        text += &format!("{:<12} no directory given\n", format!("{index}/{count}"));
        incomplete.insert(index);
    }
    if incomplete.is_empty() {
        return Ok((text + "complete\n", true));
    }
    // A whole study is no shard "1".
    let list: Vec<String> = match shards.iter().all(|s| s.shard.is_none()) {
        true => vec![shard_name(None)],
        false => incomplete.iter().map(usize::to_string).collect(),
    };
    Ok((text + &format!("incomplete: {}\n", list.join(",")), false))
}

/// "3/16", or "whole study".
pub fn shard_name(shard: Option<Shard>) -> String {
    shard.map_or("whole study".into(), |s| format!("{}/{}", s.index, s.count))
}

/// Refuses `dir` when it holds files sysid did not write, unless `force`. A directory is
/// sysid's when it holds a study, a basin map or a lock file; then the files of [`OWNED`]
/// (and sysid's temporary files) are its own. A missing or empty directory is fine.
pub fn check_owned(dir: &Path, force: bool) -> Result<(), StudyError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(StudyError::io(dir)(e)),
    };
    let mut names = Vec::new();
    for entry in entries {
        names.push(entry.map_err(StudyError::io(dir))?.file_name().to_string_lossy().into_owned());
    }
    let ours = names.iter().any(|n| [STUDY_FILE, BASIN_FILE, LOCK_FILE].contains(&n.as_str()));
    let mut foreign: Vec<String> = names.into_iter().filter(|n| !(ours && is_owned(n))).collect();
    if force || foreign.is_empty() {
        return Ok(());
    }
    foreign.sort();
    Err(StudyError::Foreign { dir: dir.into(), files: foreign })
}

/// A file sysid writes into a study directory, or one of its temporary files.
fn is_owned(name: &str) -> bool {
    if OWNED.contains(&name) {
        return true;
    }
    // `.summary.json.123.partial` (and the `summary.partial` of earlier versions).
    let Some(stem) = name.strip_suffix(".partial") else { return false };
    let stem = stem.trim_start_matches('.');
    OWNED.iter().any(|o| stem.starts_with(o) || o.split('.').next() == Some(stem))
}

/// An exclusive hold on a directory for as long as it lives: a second sysid that wants to
/// write there is refused at once, naming the holder. The lock is the operating system's
/// (`flock`), so it goes with the process however that ends. The lock file is removed when
/// the hold ends normally; after a crash or a kill it stays, unlocked, and the next run takes
/// it over.
pub struct DirLock {
    file: File,
    path: PathBuf,
}

impl DirLock {
    /// Creates `dir` if needed and takes its lock, or says who holds it.
    pub fn acquire(dir: &Path) -> Result<Self, StudyError> {
        std::fs::create_dir_all(dir).map_err(StudyError::io(dir))?;
        let path = dir.join(LOCK_FILE);
        let mut file = loop {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(StudyError::io(&path))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    let mut holder = String::new();
                    // The holder's line is informative only: an unreadable one still refuses.
                    let _ = file.read_to_string(&mut holder);
                    return Err(StudyError::Busy { dir: dir.into(), holder: describe(&holder) });
                }
                Err(TryLockError::Error(e)) => return Err(StudyError::io(&path)(e)),
            }
            // The holder before us may have removed the file between our open and our lock:
            // then we hold a file nobody else can find, and must lock the one at the path.
            if same_file(&file, &path) {
                break file;
            }
        };
        let now = unix_seconds();
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
        let command: Vec<String> = std::env::args().collect();
        let line =
            format!("{}\t{now}\t{}\t{}\n", std::process::id(), host.trim(), command.join(" "));
        file.set_len(0).map_err(StudyError::io(&path))?;
        file.write_all(line.as_bytes()).map_err(StudyError::io(&path))?;
        remove_stale_partials(dir);
        Ok(Self { file, path })
    }
}

/// Removes the temporary files of [`write_atomically`] that a killed run left in `dir`: only
/// the holder of the directory's lock writes there, so while we hold it none is in use.
fn remove_stale_partials(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') && name.ends_with(".partial") && is_owned(&name) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

impl Drop for DirLock {
    /// Removes the lock file while still holding it, so that no run finds it left behind.
    fn drop(&mut self) {
        if same_file(&self.file, &self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Whether `file` is the file at `path` (same device and inode).
#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Elsewhere an open file cannot be removed: the path is the file.
#[cfg(not(unix))]
fn same_file(_: &File, path: &Path) -> bool {
    path.exists()
}

/// Seconds since 1970 (0 for a clock before it).
fn unix_seconds() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs())
}

/// "pid 123 on node7, for 42 s: sysid study …" from a lock file's line.
fn describe(line: &str) -> String {
    let fields: Vec<&str> = line.trim_end().splitn(4, '\t').collect();
    let [pid, since, host, command] = fields[..] else {
        return "a process that has not written its name yet".into();
    };
    let now = unix_seconds();
    let age = since
        .parse::<u64>()
        .map_or(String::new(), |s| format!(", for {} s", now.saturating_sub(s)));
    let host = if host.is_empty() { String::new() } else { format!(" on {host}") };
    format!("pid {pid}{host}{age}: {command}")
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
        Err(e) => return Err(StudyError::Io { path, error: e }),
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
/// The temporary file's name carries the process id, and errors name the file written (a
/// link's target).
///
/// A symbolic link is written through, as the shell's `>` writes: its target takes the text
/// (made where the link points, if it does not exist yet) and the link stays. A path that is
/// not a regular file (a device such as `/dev/null` or a terminal, a FIFO) or that reaches an
/// open file descriptor (`/dev/stdout`, `/dev/fd/N`, `/proc/self/fd/N`, whatever they lead to)
/// is written into, appending as the descriptor's own writes would: a rename would put a file
/// in its place, or replace the file standard output was sent to.
pub fn write_atomically(path: &Path, text: &str) -> Result<(), StudyError> {
    if written_into(path) {
        return std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .and_then(|mut file| file.write_all(text.as_bytes()))
            .map_err(StudyError::io(path));
    }
    let target = link_target(path).map_err(|e| StudyError::io(path)(std::io::Error::other(e)))?;
    let path = target.as_path();
    let name = path.file_name().map_or_else(Default::default, |n| n.to_string_lossy());
    let tmp = path.with_file_name(format!(".{name}.{}.partial", std::process::id()));
    let written = File::create(&tmp).and_then(|mut file| {
        file.write_all(text.as_bytes())?;
        file.sync_all()
    });
    let renamed = written.and_then(|()| std::fs::rename(&tmp, path));
    if renamed.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    renamed.map_err(StudyError::io(path))
}

/// The hops of a path's symbolic links: the path, then where each link leads, until one is
/// not a link (at most 40 links, as the kernel follows).
fn link_chain(path: &Path) -> Vec<PathBuf> {
    let mut chain = vec![path.to_path_buf()];
    while chain.len() <= 40 {
        let at = chain.last().expect("the path");
        let Ok(link) = std::fs::read_link(at) else { break };
        // A relative link is read from the folder holding it; an absolute one replaces it.
        let next = match at.parent() {
            Some(folder) => folder.join(link),
            None => link,
        };
        chain.push(next);
    }
    chain
}

/// Where a path's symbolic links lead (the path itself where it is none): the file a write
/// through it reaches, existing or not; an error where the links do not end (a loop, or more
/// than 40).
pub fn link_target(path: &Path) -> Result<PathBuf, String> {
    let chain = link_chain(path);
    let last = chain.last().expect("the path").clone();
    if std::fs::symlink_metadata(&last).is_ok_and(|m| m.file_type().is_symlink()) {
        return Err("too many levels of symbolic links".into());
    }
    Ok(last)
}

/// Whether a write to `path` goes into what is there rather than through a new file and a
/// rename ([`write_atomically`]): a device, a FIFO or a socket, or an open file descriptor
/// reached by name (`/dev/stdout`, `/dev/fd/N`, `/proc/…/fd/N`, any hop of the links).
pub fn written_into(path: &Path) -> bool {
    let descriptor = |p: &Path| {
        let p = p.to_string_lossy();
        ["/dev/stdout", "/dev/stderr", "/dev/stdin"].contains(&p.as_ref())
            || p.starts_with("/dev/fd/")
            || (p.starts_with("/proc/") && p.contains("/fd/"))
    };
    link_chain(path).iter().any(|p| descriptor(p))
        || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// Which settings differ between two headers, for messages: "perturb 0.3 vs 0.5,
/// integrator.rtol 1e-8 vs 1e-6". The truth and the Cramér–Rao bound follow from the
/// settings and the data, so they are named only when nothing else differs.
fn difference(a: &Header, b: &Header) -> String {
    let value = |h: &Header| serde_json::to_value(h).expect("headers serialise");
    let mut diffs = Vec::new();
    differ("", &value(a), &value(b), &mut diffs);
    let derived = |d: &String| ["unknowns ", "truth ", "crb_sd "].iter().any(|k| d.starts_with(k));
    let settings: Vec<&String> = diffs.iter().filter(|d| !derived(d)).collect();
    if settings.is_empty() {
        "the truth or the Cramér–Rao bound (the data or the model differ)".into()
    } else {
        settings.iter().map(|d| d.as_str()).collect::<Vec<_>>().join(", ")
    }
}

/// Appends "key x vs y" for every leaf where `x` and `y` differ (`spec.` left out of keys).
fn differ(key: &str, x: &Value, y: &Value, out: &mut Vec<String>) {
    let empty = Value::Object(Default::default());
    let (x, y) = match (x, y) {
        (Value::Null, Value::Object(_)) => (&empty, y),
        (Value::Object(_), Value::Null) => (x, &empty),
        _ => (x, y),
    };
    match (x, y) {
        (Value::Object(p), Value::Object(q)) => {
            let keys: BTreeSet<&String> = p.keys().chain(q.keys()).collect();
            for k in keys {
                let child = match key {
                    "" | "spec" => k.clone(),
                    _ => format!("{key}.{k}"),
                };
                differ(
                    &child,
                    p.get(k).unwrap_or(&Value::Null),
                    q.get(k).unwrap_or(&Value::Null),
                    out,
                );
            }
        }
        _ if x != y => {
            let show = |v: &Value| match v {
                Value::Null => "(not recorded)".to_string(),
                Value::String(s) => s.clone(),
                v => v.to_string(),
            };
            out.push(format!("{key} {} vs {}", show(x), show(y)));
        }
        _ => {}
    }
}
