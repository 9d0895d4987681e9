//! Ctrl-C for work that can end cleanly (`splat fit` saves its checkpoint). While a run
//! listens, the first Ctrl-C sets its flag and a second ends the process; when nothing
//! listens, Ctrl-C ends the process at once, as without a handler. Only SIGINT is taken:
//! SIGTERM and SIGHUP keep their effect (`nohup` still works), and a process started with
//! SIGINT ignored (a background job) keeps ignoring it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// Exit status of a process ended by SIGINT, as shells report it.
const INTERRUPTED: i32 = 130;

static LISTENING: AtomicBool = AtomicBool::new(false);

/// A run listening for Ctrl-C until dropped.
pub struct Listening(Arc<AtomicBool>);

impl Listening {
    /// Set once Ctrl-C was pressed during the run.
    pub fn flag(&self) -> Arc<AtomicBool> {
        self.0.clone()
    }
}

impl Drop for Listening {
    fn drop(&mut self) {
        LISTENING.store(false, Ordering::SeqCst);
    }
}

/// Listens for Ctrl-C (the handler is installed on first use, its flag cleared); `None` where
/// SIGINT is ignored or the program has a handler of its own.
pub fn listen() -> Option<Listening> {
    static FLAG: OnceLock<Option<Arc<AtomicBool>>> = OnceLock::new();
    let flag = FLAG.get_or_init(|| {
        if sigint_ignored() {
            return None;
        }
        let flag = Arc::new(AtomicBool::new(false));
        let seen = flag.clone();
        let installed = ctrlc::set_handler(move || {
            if !LISTENING.load(Ordering::SeqCst) || seen.swap(true, Ordering::SeqCst) {
                std::process::exit(INTERRUPTED);
            }
        });
        installed.is_ok().then_some(flag)
    });
    let flag = flag.clone()?;
    flag.store(false, Ordering::SeqCst);
    LISTENING.store(true, Ordering::SeqCst);
    Some(Listening(flag))
}

#[cfg(unix)]
fn sigint_ignored() -> bool {
    // SAFETY: reads the current action of SIGINT without changing it.
    unsafe {
        let mut old: libc::sigaction = std::mem::zeroed();
        libc::sigaction(libc::SIGINT, std::ptr::null(), &mut old) == 0
            && old.sa_sigaction == libc::SIG_IGN
    }
}

#[cfg(not(unix))]
fn sigint_ignored() -> bool {
    false
}
