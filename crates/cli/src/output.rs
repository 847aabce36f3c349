//! What the commands write: standard output that tolerates a closed pipe, files written
//! whole and announced, progress bars and lines, the times of CSV rows, and the multistart line.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail};
use indicatif::{ProgressBar, ProgressFinish, ProgressStyle};
use sysid_core::format::shortest;
use sysid_core::observer::{IterateReport, TrialReport};
use sysid_model::simulate::decimal_within;

/// Writes `text` to standard output. A reader that has gone away (`sysid ... | head`) is not
/// an error: there is nobody left to tell.
pub fn emit(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Writes CSV `text` to standard output, or to `out` ([`write_atomically`]: through a
/// temporary file of our own beside it, never a user's `out.partial`, renamed, so that the
/// file is old or new, never half; into a device, a FIFO or an open descriptor such as
/// `/dev/stdout`) and then says on stderr what was written where.
///
/// [`write_atomically`]: sysid_montecarlo::files::write_atomically
pub fn write_output(out: Option<&Path>, text: &str) -> anyhow::Result<()> {
    let Some(path) = out else { return emit(text) };
    sysid_montecarlo::files::write_atomically(path, text)?;
    let rows = text.lines().count().saturating_sub(1);
    let columns = text.lines().next().map_or(0, |h| h.split(',').count());
    eprintln!("wrote {rows} rows of {columns} columns (CSV) to {}", path.display());
    Ok(())
}

/// Refuses to write `out` (given by the option `option`) over one of `inputs`, the files
/// the command reads: same path, or the same file under another name (a link).
pub fn not_an_input(out: &Path, inputs: &[PathBuf], option: &str) -> anyhow::Result<()> {
    for input in inputs {
        if same_file(out, input) {
            bail!(
                "{option} {}: that is {}, which this command reads; write the output elsewhere",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Whether `a` and `b` name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) else { return false };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if (x.dev(), x.ino()) == (y.dev(), y.ino()) {
            return true;
        }
    }
    let _ = (x, y);
    matches!((a.canonicalize(), b.canonicalize()), (Ok(p), Ok(q)) if p == q)
}

/// Checks that a file can be written at `path` before the work that produces it: its folder
/// exists, is a folder and takes a new file (one is made and removed), and `path` is not a
/// folder. `option` names the option that gave it. Errors name the path as given, or the
/// link's target where `path` is a link.
pub fn writable(path: &Path, option: &str) -> anyhow::Result<()> {
    // A device, a FIFO, a terminal or an open descriptor (`/dev/stdout`) is written into, not
    // replaced: its folder need not take a file (`/dev/stdout`'s is /proc/self/fd).
    if sysid_montecarlo::files::written_into(path) {
        return Ok(());
    }
    // Through a link, the folder its target is made in.
    let target = sysid_montecarlo::files::link_target(path)
        .map_err(|e| anyhow!("{option} {}: {e}", path.display()))?;
    let path = target.as_path();
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        bail!(
            "{option} {}: the folder {} does not exist (create it first)",
            path.display(),
            folder.display()
        );
    }
    if path.is_dir() {
        bail!("{option} {}: that is a folder, not a file", path.display());
    }
    // A folder that exists but cannot be written (`/proc`) was found only after the work,
    // its results printed and the exit 2: a file made and removed again tells now.
    let probe = folder.join(format!(".sysid-write-check-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => bail!(
            "{option} {}: the folder {} cannot be written: {e}",
            path.display(),
            folder.display()
        ),
    }
    Ok(())
}

/// Checks a figure's stem (`--figure`, `--waterfall`) before the work: its two files
/// ([`sysid_report::figure_paths`]) can be written and are none of `inputs`. A stem that ends
/// in a folder's separator (`figs/`) names no figure and is refused: its figures
/// were `figs/.png` and `figs/.svg`, hidden files that the drawing then failed to write, after
/// the whole run. (`figs` beside a folder `figs` is `figs.png` and `figs.svg`.)
pub fn figure_writable(stem: &Path, inputs: &[PathBuf], option: &str) -> anyhow::Result<()> {
    let text = stem.as_os_str().to_string_lossy();
    if text.ends_with(std::path::MAIN_SEPARATOR) || text.ends_with('/') {
        bail!(
            "{option} {}: that is a folder; give the figures' name in it (`{}`), and .png and .svg are added",
            stem.display(),
            stem.join("figure").display()
        );
    }
    for path in sysid_report::figure_paths(stem) {
        writable(&path, option)?;
        not_an_input(&path, inputs, option)?;
    }
    Ok(())
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(total: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    let template = format!("{{bar:40}} {{pos}}/{{len}} {unit}, {{per_sec}}, {{eta}} left");
    bar.set_style(ProgressStyle::with_template(&template).expect("a valid template"));
    bar
}

/// What a long run says on stderr while it goes: on a terminal, one line redrawn in place
/// ([`say`](Self::say)); otherwise (a batch job's log) a plain line at the first news once
/// `every` seconds have passed since the last (never when 0), so that a fit of hours shows
/// where it is either way.
pub struct Watch {
    label: String,
    line: ProgressBar,
    every: Option<Duration>,
    started: Instant,
    last: Mutex<Instant>,
    /// Where the fit's iterates and trials are written as they come (`fit --trace`).
    trace: OnceLock<Trace>,
}

impl Watch {
    /// A watch whose lines begin with `label`.
    pub fn new(label: impl Into<String>, every: f64) -> Self {
        use std::io::IsTerminal;
        let on = every > 0.0 && !std::io::stderr().is_terminal();
        let now = Instant::now();
        let line = ProgressBar::new_spinner().with_finish(ProgressFinish::AndClear);
        line.set_style(ProgressStyle::with_template("{wide_msg}").expect("a valid template"));
        Self {
            label: label.into(),
            line,
            // Longer than a Duration holds: never.
            every: on.then(|| Duration::try_from_secs_f64(every).ok()).flatten(),
            started: now,
            last: Mutex::new(now),
            trace: OnceLock::new(),
        }
    }

    /// Writes the iterates and trials of the fits watched from now on to `trace` (a watch
    /// has one trace at most; a second is refused).
    pub fn set_trace(&self, trace: Trace) -> anyhow::Result<()> {
        self.trace.set(trace).map_err(|t| anyhow!("--trace {}: already traced", t.path.display()))
    }

    /// The trace, where one was set.
    pub fn trace(&self) -> Option<&Trace> {
        self.trace.get()
    }

    /// `text` on the terminal's line, and in the log where `every` seconds have passed since
    /// its last line; both with the seconds since the watch began.
    pub fn say(&self, text: &str) {
        self.line.set_message(self.stamped(text));
        self.log(text);
    }

    /// `text` in the log only, where `every` seconds have passed since its last line.
    pub fn log(&self, text: &str) {
        let Some(every) = self.every else { return };
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if last.elapsed() >= every {
            *last = Instant::now();
            eprintln!("{}", self.stamped(text));
        }
    }

    /// "label: text, 12 s": with the seconds since the watch began.
    fn stamped(&self, text: &str) -> String {
        format!("{}: {text}, {:.0} s", self.label, self.started.elapsed().as_secs_f64())
    }

    /// Clears the terminal's line.
    pub fn finish(&self) {
        self.line.finish_and_clear();
    }
}

/// The trace of one fit (`fit --trace`): every iterate the driver records and every trial
/// step a trust-region method judges, one JSON object a line, written as the fit runs (a
/// fit that is stopped keeps what it wrote). The keys: docs/json.md, "sysid fit --trace
/// FILE".
pub struct Trace {
    path: PathBuf,
    /// The writer, and the first error writing to it (reported by [`Trace::finish`]).
    out: Mutex<(std::io::BufWriter<std::fs::File>, Option<std::io::Error>)>,
}

impl Trace {
    /// A new trace at `path`, checked before the work: its folder takes a file, and it is
    /// none of `inputs`.
    pub fn create(path: &Path, inputs: &[PathBuf]) -> anyhow::Result<Self> {
        writable(path, "--trace")?;
        not_an_input(path, inputs, "--trace")?;
        let file =
            std::fs::File::create(path).map_err(|e| anyhow!("--trace {}: {e}", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            out: Mutex::new((std::io::BufWriter::new(file), None)),
        })
    }

    /// The file it writes.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// One line: `value` as compact JSON (non-finite numbers as null).
    fn line(&self, value: &serde_json::Value) {
        use std::io::Write;
        let mut out = self.out.lock().unwrap_or_else(|e| e.into_inner());
        let (writer, error) = &mut *out;
        if error.is_none()
            && let Err(e) = writeln!(writer, "{value}")
        {
            *error = Some(e);
        }
    }

    /// An iterate: `{"event": "iterate", "method", "iteration", "cost", "objective",
    /// "optimality", "coarse"}`.
    pub fn iterate(&self, p: &IterateReport<'_>) {
        self.line(&serde_json::json!({
            "event": "iterate",
            "method": p.method,
            "iteration": p.iteration,
            "cost": p.cost,
            "objective": p.objective,
            "optimality": p.optimality,
            "coarse": p.coarse,
        }));
    }

    /// A trial: `{"event": "trial", "method", "model", "from", "radius", "step", "lambda",
    /// "predicted", "actual", "ratio", "accepted"}`.
    pub fn trial(&self, t: &TrialReport<'_>) {
        self.line(&serde_json::json!({
            "event": "trial",
            "method": t.method,
            "model": t.model,
            "from": t.from,
            "radius": t.radius,
            "step": t.step,
            "lambda": t.lambda,
            "predicted": t.predicted,
            "actual": t.actual,
            "ratio": t.ratio,
            "accepted": t.accepted,
        }));
    }

    /// Flushes the file; the first error writing it, naming the file.
    pub fn finish(&self) -> anyhow::Result<()> {
        use std::io::Write;
        let mut out = self.out.lock().unwrap_or_else(|e| e.into_inner());
        let (writer, error) = &mut *out;
        let result = match error.take() {
            Some(e) => Err(e),
            None => writer.flush(),
        };
        result.map_err(|e| anyhow!("--trace {}: {e}", self.path.display()))
    }
}

/// The most output times (CSV rows) a command writes. More is a step given in the wrong
/// unit, and would not fit in memory (predict asked for 40 TB at --step 1e-12).
pub const MAX_TIMES: usize = 10_000_000;

/// Parses `a:b:step` into the times a, a + step, …, up to b (inclusive within rounding).
pub fn parse_times(spec: &str) -> anyhow::Result<Vec<f64>> {
    let parts: Vec<&str> = spec.split(':').collect();
    let [a, b, h] = parts[..] else { bail!("--times must be a:b:step, got `{spec}`") };
    let number = |s: &str| -> anyhow::Result<f64> {
        let v: f64 = s.trim().parse().map_err(|_| anyhow!("--times: `{s}` is not a number"))?;
        if !v.is_finite() {
            bail!("--times: `{s}` is not a finite number");
        }
        Ok(v)
    };
    let (a, b, h) = (number(a)?, number(b)?, number(h)?);
    if h <= 0.0 || b < a {
        bail!("--times a:b:step needs a ≤ b and step > 0, got {spec}");
    }
    spaced(a, b, h, &format!("--times {spec}"))
}

/// The times a, a + h, …, up to b (inclusive within rounding), for a ≤ b and h > 0; `what`
/// names the options that asked for them in the error when they are more than [`MAX_TIMES`],
/// or when h is too small for a float to tell a time from the next. Each time is the decimal
/// a user would write where that moves it by at most a millionth of h ([`decimal_within`]):
/// 0 + 3·0.1 is 0.3, and 1.7e9 + 1e-6 is not 1.7e9.
pub fn spaced(a: f64, b: f64, h: f64, what: &str) -> anyhow::Result<Vec<f64>> {
    // "Within rounding" is the rounding of b − a (a few units in the last place of |a| + |b|)
    // and of the division, counted in steps: 2.3 − 2.2 is 0.0999999999999996, and
    // 2.2:2.3:0.1 still ends at 2.3. (A slack of 1e-9 steps had put a time 1e-10 past b =
    // 0.9999999999 at h = 0.1.)
    let count = (b - a) / h;
    // (Near the float's resolution, a step of a few units in the last place of a, the first
    // term is a good part of a step: 1.7e9:1.7e9 + 3e-6:1e-6 has 0.75.)
    let slack = f64::EPSILON * (a.abs() + b.abs()) / h + 4.0 * f64::EPSILON * (count + 1.0);
    let n = intervals(count + slack, what)?;
    // Within a few units in the last place the times would repeat or be spaced unevenly.
    let largest = a.abs().max((a + h * n as f64).abs());
    if n > 0 && h <= largest * f64::EPSILON {
        bail!(
            "{what}: a step of {h:e} is below the resolution of a float near {}: the times would repeat",
            shortest(largest)
        );
    }
    // No time past b: a + n·h may round above it (0 + 3·0.1).
    Ok((0..=n).map(|i| decimal_within(a + h * i as f64, h).min(b)).collect())
}

/// The number of intervals `count` (rounded down), refused when the times would be more
/// than [`MAX_TIMES`]; `what` names the options that asked for them.
pub fn intervals(count: f64, what: &str) -> anyhow::Result<usize> {
    if count.is_nan() || count >= MAX_TIMES as f64 {
        bail!(
            "{what} asks for {:.1e} times, more than the {MAX_TIMES} a command writes",
            count + 1.0
        );
    }
    Ok(count.floor() as usize)
}
