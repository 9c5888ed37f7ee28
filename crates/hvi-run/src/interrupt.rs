//! Ctrl-C (SIGINT) and SIGTERM: the first asks the running work to stop cleanly (runs in
//! progress stop at their next step and remove their temporary directories, no new run starts,
//! the tables of what finished are written, and the process exits with 128 + the signal's
//! number: 130 or 143); a second one of the same kind ends the process at once with that code.
//! Finished runs are in the store, so the same command resumes where it stopped.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

pub use crate::error::{Interrupted, SIGINT, SIGTERM};

/// The signal received (0: none).
static RECEIVED: OnceLock<Arc<AtomicUsize>> = OnceLock::new();

/// Installs the handlers (once; later calls do nothing). Without them (a library user who
/// did not call this), a signal ends the process as usual and [`requested`] stays `None`.
pub fn install() -> std::io::Result<()> {
    if RECEIVED.get().is_some() {
        return Ok(());
    }
    let flag = Arc::new(AtomicUsize::new(0));
    for sig in [SIGINT, SIGTERM] {
        let seen = Arc::new(std::sync::atomic::AtomicBool::new(false));
        // A second signal of the kind exits at once (registered first, so it sees the flag
        // as the first signal left it).
        signal_hook::flag::register_conditional_shutdown(sig, 128 + sig, Arc::clone(&seen))?;
        signal_hook::flag::register(sig, seen)?;
        signal_hook::flag::register_usize(sig, Arc::clone(&flag), sig as usize)?;
    }
    let _ = RECEIVED.set(flag);
    Ok(())
}

/// The signal that asked the work to stop, if any.
pub fn requested() -> Option<i32> {
    let n = RECEIVED.get()?.load(Ordering::Relaxed);
    (n != 0).then_some(n as i32)
}

/// `Err(Interrupted)` once a signal asked the work to stop.
pub fn check() -> crate::error::Result<()> {
    match requested() {
        Some(sig) => Err(Interrupted(sig).into()),
        None => Ok(()),
    }
}

/// The interruption in an error's chain, if it is one (a [`crate::error::RunError`]'s, or an
/// `anyhow::Error`'s: pass `&*e`).
pub fn of(e: &(dyn std::error::Error + 'static)) -> Option<Interrupted> {
    std::iter::successors(Some(e), |&e| e.source()).find_map(|c| {
        c.downcast_ref::<Interrupted>()
            .copied()
            .or_else(|| match crate::error::as_run_error(c) {
                Some(crate::error::RunError::Interrupted(i)) => Some(*i),
                _ => None,
            })
    })
}
