//! Ctrl-C (SIGINT) and SIGTERM (a batch job's time limit) in the long commands.
//!
//! `fit`, `compare`, `predict`, `profile`, `study` and `report` run within a stop flag
//! ([`sysid_core::observer::stop_when`]) that the first of these signals sets: the fits
//! running end at their next iteration with their best point (termination `interrupted`),
//! no start, trial, profile or method is begun, and the command prints what it has (a study
//! keeps its complete trials for `--resume`). A notice on stderr says so when the signal
//! comes. A second signal ends the process at once, as the signal's default action would,
//! printing nothing more. After the output the process ends by the first signal, so that a
//! shell reports it (130 for Ctrl-C, 143 for SIGTERM) and a shell loop around sysid stops
//! too. A signal ignored as sysid starts (SIGINT in a shell script's background job) stays
//! ignored; SIGHUP keeps its default action (a closed terminal takes the output with it, and
//! `nohup` still protects a run). Elsewhere than on Unix the signals keep their default
//! actions.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
#[cfg(unix)]
use std::sync::atomic::{AtomicUsize, Ordering};

/// The flag the signals set, for [`requested`] on any thread.
static FLAG: std::sync::OnceLock<Arc<AtomicBool>> = std::sync::OnceLock::new();

/// Whether a signal asked the run to stop, from any thread (the observer's flags are the
/// threads' own: a rayon worker reporting progress does not see them).
pub fn requested() -> bool {
    FLAG.get().is_some_and(|f| f.load(std::sync::atomic::Ordering::Relaxed))
}

/// Whether the notice of the first signal was printed.
#[cfg(unix)]
static NOTICED: AtomicBool = AtomicBool::new(false);

/// Which signal came first (the flag they set is [`FLAG`]).
pub struct Signals {
    #[cfg(unix)]
    first: Arc<AtomicUsize>,
}

#[cfg(unix)]
impl Signals {
    /// Installs the handlers (None where the system refuses them: the signals then keep
    /// their default actions).
    pub fn install() -> Option<Self> {
        use signal_hook::consts::signal::{SIGINT, SIGTERM};
        use signal_hook::flag;
        let stop = Arc::new(AtomicBool::new(false));
        let first = Arc::new(AtomicUsize::new(0));
        let signals: Vec<i32> = [SIGINT, SIGTERM].into_iter().filter(|&s| !ignored(s)).collect();
        if signals.is_empty() {
            return None;
        }
        for &signal in &signals {
            // In this order: a signal that finds the flag set (the second) takes the default
            // action; the first only records itself and sets the flag.
            flag::register_conditional_default(signal, Arc::clone(&stop)).ok()?;
            // Overwritten only by a second signal, which ends the process first: the first.
            flag::register_usize(signal, Arc::clone(&first), signal as usize).ok()?;
            flag::register(signal, Arc::clone(&stop)).ok()?;
        }
        // The notice, printed from a thread of its own (a handler cannot print safely); the
        // handlers above stand without it.
        if let Ok(mut heard) = signal_hook::iterator::Signals::new(&signals) {
            let _ = std::thread::Builder::new().name("sysid-signals".into()).spawn(move || {
                if let Some(signal) = heard.forever().next() {
                    eprintln!(
                        "\nsysid: {} received: stopping at the next iteration and printing what is done (a second signal ends sysid at once)",
                        name(signal)
                    );
                    NOTICED.store(true, Ordering::SeqCst);
                }
            });
        }
        FLAG.set(stop).ok()?;
        Some(Signals { first })
    }

    /// The first signal received, if any.
    pub fn received(&self) -> Option<i32> {
        match self.first.load(Ordering::SeqCst) {
            0 => None,
            s => i32::try_from(s).ok(),
        }
    }

    /// Ends the process by `signal`, as its default action would, after the output is
    /// flushed (exit status 128 + signal where the default action cannot be emulated).
    pub fn end_by(signal: i32) -> ! {
        use std::io::Write;
        // The notice first, where its thread has not printed it yet (a tenth of a second).
        for _ in 0..100 {
            if NOTICED.load(Ordering::SeqCst) {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        let _ = std::io::stdout().flush();
        let _ = std::io::stderr().flush();
        let _ = signal_hook::low_level::emulate_default_handler(signal);
        std::process::exit(128 + signal)
    }
}

#[cfg(not(unix))]
impl Signals {
    /// No handlers: the signals keep their default actions.
    pub fn install() -> Option<Self> {
        None
    }

    /// Never a signal.
    pub fn received(&self) -> Option<i32> {
        None
    }

    /// Never called.
    pub fn end_by(signal: i32) -> ! {
        std::process::exit(128 + signal)
    }
}

impl Signals {
    /// The flag the first signal sets, for [`sysid_core::observer::stop_when`].
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(FLAG.get().expect("set where the handlers are installed"))
    }
}

/// The signal as a user knows it.
#[cfg(unix)]
fn name(signal: i32) -> &'static str {
    use signal_hook::consts::signal::{SIGINT, SIGTERM};
    match signal {
        SIGINT => "Ctrl-C (SIGINT)",
        SIGTERM => "SIGTERM",
        _ => "a signal",
    }
}

/// Whether `signal` was ignored (SIG_IGN) as the process started: a shell starts a script's
/// background jobs with SIGINT ignored, and such a job must not stop on it.
#[cfg(unix)]
#[allow(unsafe_code)]
fn ignored(signal: i32) -> bool {
    // SAFETY: sigaction with a null new action only reads the current one into `old`, a
    // plain C struct for which all zeroes is a valid value.
    unsafe {
        let mut old: libc::sigaction = std::mem::zeroed();
        libc::sigaction(signal, std::ptr::null(), &mut old) == 0
            && old.sa_sigaction == libc::SIG_IGN
    }
}
