//! Cooperative cancellation of long calls (Ctrl-C in Python): the caller hands in a check,
//! the long call polls it at a bounded rate and stops with [`Error::Cancelled`].
//!
//! The check may be costly (the Python binding re-acquires the GIL to look for a pending
//! signal), so [`Cancel::poll`] calls it at most once per [`Cancel::interval`]; a poll in
//! between costs one clock read. Once the check has said "stop", every later poll says so
//! too (the check itself may consume the request, as Python's signal check does).

use crate::error::{Error, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Default time between two calls of the caller's check: short next to the one second a user
/// waits for Ctrl-C, long next to the microseconds a check costs.
pub const DEFAULT_CANCEL_INTERVAL: Duration = Duration::from_millis(50);

/// A cancellation check shared by the stages of one long call (see the module docs).
pub struct Cancel<'a> {
    check: Option<&'a (dyn Fn() -> bool + Sync)>,
    interval: Duration,
    last: Mutex<Instant>,
    cancelled: AtomicBool,
}

impl<'a> Cancel<'a> {
    /// Never cancels (what the plain entry points use).
    pub fn never() -> Self {
        Self::build(None, DEFAULT_CANCEL_INTERVAL)
    }

    /// Cancels once `check` returns true; `check` runs at most every
    /// [`DEFAULT_CANCEL_INTERVAL`].
    pub fn new(check: &'a (dyn Fn() -> bool + Sync)) -> Self {
        Self::build(Some(check), DEFAULT_CANCEL_INTERVAL)
    }

    /// As [`Cancel::new`] with the time between two checks (zero: at every poll).
    pub fn with_interval(check: &'a (dyn Fn() -> bool + Sync), interval: Duration) -> Self {
        Self::build(Some(check), interval)
    }

    fn build(check: Option<&'a (dyn Fn() -> bool + Sync)>, interval: Duration) -> Self {
        Self {
            check,
            interval,
            last: Mutex::new(Instant::now()),
            cancelled: AtomicBool::new(false),
        }
    }

    pub fn interval(&self) -> Duration {
        self.interval
    }

    /// True once cancellation was requested; calls the check when `interval` has passed.
    pub fn poll(&self) -> bool {
        if self.cancelled.load(Ordering::Relaxed) {
            return true;
        }
        let Some(check) = self.check else {
            return false;
        };
        {
            let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
            let now = Instant::now();
            if now.duration_since(*last) < self.interval {
                return false;
            }
            *last = now;
        }
        if check() {
            self.cancelled.store(true, Ordering::Relaxed);
        }
        self.cancelled.load(Ordering::Relaxed)
    }

    /// True if an earlier poll saw the cancellation (no new check).
    pub fn was_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }

    /// `Err(Error::Cancelled)` naming `during` when cancellation was requested.
    pub fn checkpoint(&self, during: &str) -> Result<()> {
        if self.poll() {
            Err(Error::Cancelled(during.to_string()))
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn never_cancels_and_a_check_is_rate_limited_and_sticky() {
        assert!(!Cancel::never().poll());
        let calls = AtomicUsize::new(0);
        let check = || calls.fetch_add(1, Ordering::Relaxed) >= 1;
        let cancel = Cancel::with_interval(&check, Duration::from_secs(3600));
        // Within the interval the check is not called at all.
        for _ in 0..1000 {
            assert!(!cancel.poll());
        }
        assert_eq!(calls.load(Ordering::Relaxed), 0);
        let cancel = Cancel::with_interval(&check, Duration::ZERO);
        assert!(!cancel.poll());
        assert!(cancel.poll());
        // Sticky: no further calls once cancelled.
        assert!(cancel.poll() && cancel.was_cancelled());
        assert_eq!(calls.load(Ordering::Relaxed), 2);
        let err = cancel.checkpoint("backward").unwrap_err();
        assert!(matches!(err, Error::Cancelled(_)), "{err}");
    }
}
