//! Ctrl-C (SIGINT) and SIGTERM (what a batch scheduler sends at a job's time limit or on
//! preemption) for work that can end cleanly (`splat fit` saves its checkpoint). While a run
//! listens, the first such signal sets its flag and a second ends the process; when nothing
//! listens, either ends the process at once, as without a handler. SIGHUP keeps its effect
//! (`nohup` still works), and a signal the process was started with ignored (SIGINT in a
//! background job) stays ignored.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicPtr, Ordering};
use std::sync::{Arc, OnceLock};

static LISTENING: AtomicBool = AtomicBool::new(false);
/// The listening run's flag (set once, never freed), for the SIGTERM handler.
static FLAG: AtomicPtr<AtomicBool> = AtomicPtr::new(std::ptr::null_mut());
/// The signal that set the flag.
static RECEIVED: AtomicI32 = AtomicI32::new(0);

/// A run listening for Ctrl-C and SIGTERM until dropped.
pub struct Listening(Arc<AtomicBool>);

impl Listening {
    /// Set once a signal asked the run to stop.
    pub fn flag(&self) -> Arc<AtomicBool> {
        self.0.clone()
    }

    /// What asked the run to stop, in words ("Ctrl-C", "SIGTERM"), if anything did.
    pub fn stopped_by(&self) -> Option<&'static str> {
        match RECEIVED.load(Ordering::SeqCst) {
            0 => None,
            SIGTERM => Some("SIGTERM"),
            _ => Some("Ctrl-C"),
        }
    }
}

impl Drop for Listening {
    fn drop(&mut self) {
        LISTENING.store(false, Ordering::SeqCst);
    }
}

/// Listens for Ctrl-C and SIGTERM (the handlers are installed on first use, the flag
/// cleared); `None` where neither can be taken (both ignored, or handlers of the program's
/// own).
pub fn listen() -> Option<Listening> {
    static INSTALLED: OnceLock<Option<Arc<AtomicBool>>> = OnceLock::new();
    let flag = INSTALLED.get_or_init(|| {
        // Stored before the handlers can run; kept (in this static) whether or not they could
        // be installed, so the pointer never dangles.
        static KEPT: OnceLock<Arc<AtomicBool>> = OnceLock::new();
        let flag = KEPT
            .get_or_init(|| Arc::new(AtomicBool::new(false)))
            .clone();
        FLAG.store(Arc::as_ptr(&flag).cast_mut(), Ordering::SeqCst);
        let interrupt = !ignored(libc::SIGINT)
            && ctrlc::set_handler(|| stop(libc::SIGINT, || std::process::exit(128 + libc::SIGINT)))
                .is_ok();
        let terminate = !ignored(SIGTERM) && on_sigterm();
        (interrupt || terminate).then_some(flag)
    });
    let flag = flag.clone()?;
    flag.store(false, Ordering::SeqCst);
    RECEIVED.store(0, Ordering::SeqCst);
    LISTENING.store(true, Ordering::SeqCst);
    Some(Listening(flag))
}

const SIGTERM: i32 = libc::SIGTERM;

/// A signal's effect: set the listening run's flag, or, when nothing listens or the flag was
/// already set, `exit`. Only atomics, so it may run inside a signal handler.
fn stop(signal: i32, exit: impl Fn()) {
    if !LISTENING.load(Ordering::SeqCst) {
        exit();
    }
    let _ = RECEIVED.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
    // SAFETY: FLAG points into an Arc that a static holds for the rest of the process.
    let flag = unsafe { FLAG.load(Ordering::SeqCst).as_ref() };
    if flag.is_none_or(|f| f.swap(true, Ordering::SeqCst)) {
        exit();
    }
}

/// Installs the SIGTERM handler; false where it could not be.
#[cfg(unix)]
fn on_sigterm() -> bool {
    extern "C" fn handler(_: libc::c_int) {
        // SAFETY: _exit is async-signal-safe.
        stop(SIGTERM, || unsafe { libc::_exit(128 + SIGTERM) });
    }
    // SAFETY: installs a handler that only touches atomics and calls _exit.
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = handler as *const () as usize;
        action.sa_flags = libc::SA_RESTART;
        libc::sigemptyset(&mut action.sa_mask);
        libc::sigaction(SIGTERM, &action, std::ptr::null_mut()) == 0
    }
}

#[cfg(not(unix))]
fn on_sigterm() -> bool {
    false
}

/// Whether `signal` is ignored (as a background job's SIGINT is).
#[cfg(unix)]
fn ignored(signal: i32) -> bool {
    // SAFETY: reads the current action of `signal` without changing it.
    unsafe {
        let mut old: libc::sigaction = std::mem::zeroed();
        libc::sigaction(signal, std::ptr::null(), &mut old) == 0
            && old.sa_sigaction == libc::SIG_IGN
    }
}

#[cfg(not(unix))]
fn ignored(_: i32) -> bool {
    false
}
