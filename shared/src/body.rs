//! `body` (in progress).
