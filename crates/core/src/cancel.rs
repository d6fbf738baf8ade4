//! Cooperative cancellation of a fit: a flag the caller sets, checked at every Clarabel
//! iteration and between the stages of a fit.
//!
//! A fit (or a containment) can take seconds to minutes of interior-point iterations. A caller
//! that wants to stop one early (the service's `CancelFitJob`, or a server shutting down) runs
//! the fit inside [`cancellable`] with an [`AtomicBool`]; when the flag turns true:
//!
//! ```text
//! Clarabel   the termination callback of the running solve returns true at the end of the
//!            current interior-point iteration (status CallbackTerminated)
//! stages     the next stage boundary (hull → build → solve → verify → volume) stops
//! result     Err(Error::Cancelled); no retry runs, no body is produced
//! ```
//!
//! The flag travels in a thread-local scope rather than through every signature: the fit
//! entry points (`sublevel_fit::fit_points`, `sublevel_fit::auto::fit_auto`,
//! `sublevel_fit::containment::contain_bodies`) keep their arguments, and a fit run outside a scope
//! is never cancelled. The scope belongs to the calling thread; `sublevel_fit::sdp` reads it
//! before it hands the problem to its solver thread. Only std atomics are used (no async
//! runtime), so the core stays free of the service's dependencies.

use crate::{Error, Result};
use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

thread_local! {
    /// The cancellation flag of the fit running on this thread, if it runs in a scope.
    static CURRENT: RefCell<Option<Arc<AtomicBool>>> = const { RefCell::new(None) };
}

/// Runs `f` with `flag` as this thread's cancellation flag: every fit SDP solved inside stops at
/// its next Clarabel iteration once `flag` is true, and the fit returns [`Error::Cancelled`].
/// Scopes nest (the inner flag wins until it returns); the previous scope is restored when `f`
/// returns or unwinds.
pub fn cancellable<T>(flag: Arc<AtomicBool>, f: impl FnOnce() -> T) -> T {
    /// Restores the previous scope on drop (also when `f` panics).
    struct Restore(Option<Arc<AtomicBool>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let previous = self.0.take();
            CURRENT.with(|c| *c.borrow_mut() = previous);
        }
    }
    let previous = CURRENT.with(|c| c.borrow_mut().replace(flag));
    let _restore = Restore(previous);
    f()
}

/// Runs `f` in the scope of `flag` when there is one (a flag taken with [`current`] on the thread
/// that spawned this one), else outside any scope: how a fit's own worker threads share the
/// caller's cancellation, since the scope is per thread.
pub fn within<T>(flag: Option<Arc<AtomicBool>>, f: impl FnOnce() -> T) -> T {
    match flag {
        Some(flag) => cancellable(flag, f),
        None => f(),
    }
}

/// The cancellation flag of this thread's scope (None outside [`cancellable`]).
pub fn current() -> Option<Arc<AtomicBool>> {
    CURRENT.with(|c| c.borrow().clone())
}

/// Whether this thread's scope has been cancelled (false outside a scope).
pub fn is_cancelled() -> bool {
    CURRENT.with(|c| c.borrow().as_ref().is_some_and(|f| f.load(Ordering::Relaxed)))
}

/// Returns [`Error::Cancelled`] when this thread's scope has been cancelled, else `Ok(())`:
/// the check made between the stages of a fit.
///
/// # Errors
/// [`Error::Cancelled`] as described.
pub fn check() -> Result<()> {
    if is_cancelled() {
        return Err(Error::Cancelled("the fit was cancelled".into()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scopes_nest_and_restore() {
        assert!(current().is_none());
        assert!(check().is_ok());
        let outer = Arc::new(AtomicBool::new(true));
        let inner = Arc::new(AtomicBool::new(false));
        cancellable(outer.clone(), || {
            assert!(matches!(check(), Err(Error::Cancelled(_))));
            cancellable(inner.clone(), || {
                assert!(!is_cancelled());
                inner.store(true, Ordering::Relaxed);
                assert!(is_cancelled());
            });
            assert!(Arc::ptr_eq(&current().expect("outer scope"), &outer));
        });
        assert!(current().is_none());
        assert!(!is_cancelled());
    }
}
