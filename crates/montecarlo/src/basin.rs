//! Basins of convergence: a grid of starting guesses for two unknowns (the others at the
//! truth), every method from every grid point on one data set (trial 0's), each point judged
//! against the reference fit from the truth on the same data.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sysid_ode::System;

use crate::error::StudyError;
use crate::files;
use crate::stats::significant;
use crate::trial::{Study, StudySpec, TrialRecord, perturb};

/// A basin map's settings and results, written to `basin.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Basin {
    /// The study's settings (the trial count is not used: the data are trial 0's).
    pub spec: StudySpec,
    /// The two unknowns on the axes.
    pub axes: [String; 2],
    /// Grid values of the first unknown (columns).
    pub x: Vec<f64>,
    /// Grid values of the second unknown (rows).
    pub y: Vec<f64>,
    /// The reference fit's cost (none if it failed: then no point counts as a success).
    pub reference_cost: Option<f64>,
    /// One map per method.
    pub maps: Vec<BasinMap>,
}

/// One method's map: row j (second unknown), column i (first unknown).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BasinMap {
    /// The method.
    pub method: String,
    /// Whether it reached the reference fit's minimum from each start.
    pub success: Vec<Vec<bool>>,
    /// Its outcome from each start (as in `trials.jsonl`).
    pub outcome: Vec<Vec<String>>,
    /// Its iterations from each start.
    pub iterations: Vec<Vec<usize>>,
    /// Fraction of the grid it converges from.
    pub success_rate: f64,
}

/// The most points per axis of a basin map.
pub const MAX_GRID: usize = 1000;

/// The grid of `grid` × `grid` starts for the unknowns `axes` (indices), spread as the
/// study's ρ spreads starts: truth·(1 + ρu), u from −1 to 1 in equal steps.
pub fn basin<S: System + Clone + Send + Sync>(
    study: &Study<S>,
    axes: (usize, usize),
    grid: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Basin, StudyError> {
    let scenario = study.scenario();
    let problem0 = scenario.problem();
    let k = problem0.unknowns().len();
    let names = problem0.names();
    if axes.0 >= k || axes.1 >= k || axes.0 == axes.1 {
        return Err(StudyError::Setup("a basin needs two different unknowns".into()));
    }
    if !(2..=MAX_GRID).contains(&grid) {
        return Err(StudyError::Setup(format!(
            "--grid must be from 2 to {MAX_GRID} points per axis (a million starts), got {grid}"
        )));
    }
    let spec = study.spec();
    let truth = scenario.truth();
    let list = problem0.unknowns().list();
    let axis = |a: usize| -> Vec<f64> {
        (0..grid)
            .map(|i| {
                let u = -1.0 + 2.0 * i as f64 / (grid - 1) as f64;
                perturb(&list[a], truth[a], spec.perturb, u)
            })
            .collect()
    };
    let (x, y) = (axis(axes.0), axis(axes.1));
    let (_, data) = study.draw(0);
    let points: Vec<(usize, usize)> =
        (0..grid).flat_map(|j| (0..grid).map(move |i| (i, j))).collect();
    let problem = scenario.with_data(data)?;
    let reference = study.reference_fit(&problem);
    let finished = AtomicUsize::new(0);
    // The caller's stop flag: once set, no start is begun, and the map is not made (a fit of
    // the starts running may have been cut short).
    let stop = sysid_core::observer::current_stop();
    let stopped = || stop.as_ref().is_some_and(|s| s.requested());
    let results: Vec<Option<Vec<TrialRecord>>> = points
        .par_iter()
        .map(|&(i, j)| {
            if stopped() {
                return None;
            }
            let mut start = truth.to_vec();
            start[axes.0] = x[i];
            start[axes.1] = y[j];
            let fits = sysid_core::observer::stop_within(stop.clone(), || {
                study.fit_methods(&problem, 0, &start, reference)
            });
            progress(finished.fetch_add(1, Ordering::Relaxed) + 1, points.len());
            Some(fits)
        })
        .collect();
    if stopped() {
        return Err(StudyError::Interrupted(format!(
            "stopped: {} of the {} starts of the basin map were begun; no map is written",
            finished.load(Ordering::Relaxed),
            points.len()
        )));
    }
    let results: Vec<Vec<TrialRecord>> = results.into_iter().flatten().collect();
    let maps = spec
        .methods
        .iter()
        .enumerate()
        .map(|(m, method)| {
            let cell = |i: usize, j: usize| &results[j * grid + i][m];
            let rows = |f: &dyn Fn(&TrialRecord) -> _| -> Vec<Vec<_>> {
                (0..grid).map(|j| (0..grid).map(|i| f(cell(i, j))).collect()).collect()
            };
            let success: Vec<Vec<bool>> = rows(&|r| r.success == Some(true));
            let count = success.iter().flatten().filter(|s| **s).count();
            BasinMap {
                method: method.clone(),
                outcome: (0..grid)
                    .map(|j| (0..grid).map(|i| cell(i, j).outcome.clone()).collect())
                    .collect(),
                iterations: (0..grid)
                    .map(|j| (0..grid).map(|i| cell(i, j).iterations).collect())
                    .collect(),
                success,
                success_rate: count as f64 / (grid * grid) as f64,
            }
        })
        .collect();
    Ok(Basin {
        spec: spec.clone(),
        axes: [names[axes.0].clone(), names[axes.1].clone()],
        x,
        y,
        reference_cost: reference,
        maps,
    })
}

impl Basin {
    /// Each method's map in characters: `#` converged to the reference minimum, `o` converged
    /// elsewhere, `.` failed; the truth's row and column marked.
    pub fn markdown(&self) -> String {
        let s = &self.spec;
        let mut out = format!(
            "# Basin of convergence: {}\n\n{} × {} starts of {} (columns, {} … {} from the left) and {} (rows, {} at the top … {} at the bottom, as on a plot; basin.json's rows run the other way), the \
             other unknowns at the truth; data of trial 0 (noise {}·σ, seed {}). `#` reaches the \
             reference fit's minimum, `o` converges elsewhere, `.` fails.\n",
            s.system,
            self.x.len(),
            self.y.len(),
            self.axes[0],
            significant(self.x[0]),
            significant(self.x[self.x.len() - 1]),
            self.axes[1],
            significant(self.y[self.y.len() - 1]),
            significant(self.y[0]),
            sysid_core::format::shortest(s.noise),
            s.seed
        );
        for map in &self.maps {
            out += &format!(
                "\n## {}: {:.1} % of the starts\n\n```text\n",
                map.method,
                100.0 * map.success_rate
            );
            // Highest value of the second unknown on top.
            for j in (0..self.y.len()).rev() {
                let row: String = (0..self.x.len())
                    .map(|i| match (map.success[j][i], map.outcome[j][i].as_str()) {
                        (true, _) => '#',
                        (false, "other_minimum") => 'o',
                        _ => '.',
                    })
                    .collect();
                out += &row;
                out.push('\n');
            }
            out += "```\n";
        }
        out
    }

    /// Whether `dir` can take a new basin map: none there yet (a second one replaced the
    /// first silently, after a run that may take hours), and `force` as in
    /// [`RunOptions`](crate::files::RunOptions). `sysid study --basin` checks it before the
    /// work; the report, which regenerates its own, does not.
    pub fn check_dir(dir: &Path, force: bool) -> Result<(), StudyError> {
        files::check_owned(dir, force)?;
        let existing = dir.join(files::BASIN_FILE);
        if existing.exists() {
            return Err(StudyError::Mismatch(format!(
                "{} already holds a basin map: give another --out, or remove {} and {}",
                dir.display(),
                files::BASIN_FILE,
                files::BASIN_MD
            )));
        }
        Ok(())
    }

    /// Writes `basin.json` and `basin.md` into `dir`, under its lock, replacing a map there;
    /// `force` as in [`RunOptions`](crate::files::RunOptions).
    pub fn write(&self, dir: &Path, force: bool) -> Result<(), StudyError> {
        files::check_owned(dir, force)?;
        let _lock = files::DirLock::acquire(dir)?;
        let json = serde_json::to_string_pretty(self).expect("serialisable") + "\n";
        files::write_atomically(&dir.join(files::BASIN_FILE), &json)?;
        files::write_atomically(&dir.join(files::BASIN_MD), &self.markdown())
    }
}
