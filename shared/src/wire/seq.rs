//! Sequence-number tracking: lost, duplicate and out-of-order frames.

use super::WireError;

/// How far behind the last accepted sequence number a frame may be and still
/// count as stale (rejected). A frame further behind is taken as the sender
/// restarting its counter: it is accepted and tracking restarts from it.
pub const STALE_WINDOW: u32 = 256;

/// Tracks one sender's `u32` sequence numbers, with wrap-around.
///
/// With `d = seq − last` (mod 2³²):
/// - `d = 0`: duplicate → [`WireError::Stale`];
/// - `1 ≤ d < 2³¹`: ahead → accepted, `d − 1` frames were lost;
/// - otherwise `seq` is behind by `b = last − seq`: if `b ≤ STALE_WINDOW`
///   → [`WireError::Stale`], else the sender restarted → accepted, 0 lost.
///
/// The first number after [`SeqTracker::new`] or [`SeqTracker::reset`] is
/// always accepted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SeqTracker {
    last: Option<u32>,
}

impl SeqTracker {
    /// A tracker that has seen nothing.
    #[must_use]
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// Forgets the last number (a new session).
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// The last accepted number.
    #[must_use]
    pub const fn last(&self) -> Option<u32> {
        self.last
    }

    /// Checks `seq` and, if accepted, returns how many frames were lost
    /// before it.
    ///
    /// # Errors
    /// [`WireError::Stale`] for a duplicate or a slightly older number.
    pub fn observe(&mut self, seq: u32) -> Result<u32, WireError> {
        let Some(last) = self.last else {
            self.last = Some(seq);
            return Ok(0);
        };
        let ahead = seq.wrapping_sub(last);
        if ahead == 0 {
            return Err(WireError::Stale);
        }
        if ahead < 1 << 31 {
            self.last = Some(seq);
            return Ok(ahead - 1);
        }
        if last.wrapping_sub(seq) <= STALE_WINDOW {
            return Err(WireError::Stale);
        }
        self.last = Some(seq);
        Ok(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_order_gap_duplicate_stale_restart() {
        let mut t = SeqTracker::new();
        assert_eq!(t.observe(10), Ok(0));
        assert_eq!(t.observe(11), Ok(0));
        assert_eq!(t.observe(15), Ok(3));
        assert_eq!(t.observe(15), Err(WireError::Stale));
        assert_eq!(t.observe(12), Err(WireError::Stale));
        assert_eq!(t.last(), Some(15));
        t.reset();
        assert_eq!(t.observe(3), Ok(0));
    }

    #[test]
    fn wraps() {
        let mut t = SeqTracker::new();
        assert_eq!(t.observe(u32::MAX - 1), Ok(0));
        assert_eq!(t.observe(u32::MAX), Ok(0));
        assert_eq!(t.observe(0), Ok(0));
        assert_eq!(t.observe(3), Ok(2));
        // Behind across the wrap: stale.
        assert_eq!(t.observe(u32::MAX), Err(WireError::Stale));
    }

    #[test]
    fn restart_far_behind() {
        let mut t = SeqTracker::new();
        assert_eq!(t.observe(5000), Ok(0));
        assert_eq!(t.observe(5000 - STALE_WINDOW), Err(WireError::Stale));
        assert_eq!(t.observe(5000 - STALE_WINDOW - 1), Ok(0));
        assert_eq!(t.observe(5000 - STALE_WINDOW), Ok(0));
    }
}
