//! The report's directory: the files a report owns there (its manifest), and writing them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use sysid_montecarlo::files;

/// The report's README, at the top of its directory.
pub(crate) const README: &str = "README.md";

/// `.sysid-report`: what reports wrote into their directory, a relative path a line. A report
/// removes and replaces these files and no others, so whatever else the directory holds is
/// never touched.
const MANIFEST: &str = ".sysid-report";

/// The files a report may write for one system, relative to the report's directory.
fn system_files(system: &str) -> Vec<String> {
    let figures = ["convergence", "minima", "prediction", "profiles", "accuracy", "cost", "basin"];
    let mut paths: Vec<String> = figures
        .iter()
        .flat_map(|f| ["png", "svg"].map(|ext| format!("{system}/{f}.{ext}")))
        .collect();
    paths.extend(["convergence", "prediction", "data"].map(|f| format!("{system}/{f}.csv")));
    paths.push(format!("{system}/multistart.json"));
    paths.push(format!("{system}/profiles.json"));
    for sub in ["study", "basin"] {
        paths.extend(files::OWNED.iter().map(|f| format!("{system}/{sub}/{f}")));
    }
    paths
}

/// The report directory's ledger of its own files, open while a report writes.
pub(crate) struct Manifest {
    out: PathBuf,
    /// What earlier reports wrote and this one does not replace.
    kept: std::collections::BTreeSet<String>,
    /// What this report may write.
    planned: Vec<String>,
    pub(crate) started: Instant,
}

impl Manifest {
    /// Checks that the report replaces only files a report wrote (or `force`), and removes
    /// those of the systems it is about to write, stale figures included.
    pub(crate) fn prepare(
        out: &Path,
        systems: &[String],
        petab: &[String],
        force: bool,
    ) -> anyhow::Result<Self> {
        let mut planned = vec![README.to_string()];
        planned.extend(systems.iter().flat_map(|s| system_files(s)));
        if !petab.is_empty() {
            planned.push("petab/petab.json".into());
        }
        for problem in petab {
            for f in
                ["profiles.json", "profiles.png", "profiles.svg", "waterfall.png", "waterfall.svg"]
            {
                planned.push(format!("petab/{problem}/{f}"));
            }
        }
        Self::prepare_files(out, planned, force)
    }

    /// [`prepare`](Self::prepare) for the files `planned` (relative to `out`).
    pub(crate) fn prepare_files(
        out: &Path,
        planned: Vec<String>,
        force: bool,
    ) -> anyhow::Result<Self> {
        let path = out.join(MANIFEST);
        let earlier: std::collections::BTreeSet<String> = match std::fs::read_to_string(&path) {
            Ok(text) => text.lines().map(str::to_string).collect(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Default::default(),
            Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
        };
        let foreign: Vec<&String> =
            planned.iter().filter(|f| out.join(f).exists() && !earlier.contains(*f)).collect();
        if !foreign.is_empty() && !force {
            let shown: Vec<&str> = foreign.iter().take(4).map(|f| f.as_str()).collect();
            let more = foreign.len().saturating_sub(shown.len());
            anyhow::bail!(
                "{} holds files that no report wrote at the report's paths ({}{}): choose \
                 another --out, or give --force to replace them",
                out.display(),
                shown.join(", "),
                if more > 0 { format!(" and {more} more") } else { String::new() }
            );
        }
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
        for f in &planned {
            match std::fs::remove_file(out.join(f)) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => {
                    return Err(e)
                        .with_context(|| format!("cannot replace {}", out.join(f).display()));
                }
            }
        }
        let kept = earlier.into_iter().filter(|f| !planned.contains(f)).collect();
        Ok(Self { out: out.into(), kept, planned, started: Instant::now() })
    }

    /// Records what the report wrote (also after a failure: what exists is the report's).
    pub(crate) fn close(&self) -> anyhow::Result<()> {
        let mut lines: Vec<&str> = self.kept.iter().map(String::as_str).collect();
        lines.extend(self.planned.iter().filter(|f| self.out.join(f).exists()).map(String::as_str));
        lines.sort_unstable();
        write(&self.out.join(MANIFEST), &(lines.join("\n") + "\n"))
    }
}

/// Writes `text` to `path`, naming the path when it cannot.
pub(crate) fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}
