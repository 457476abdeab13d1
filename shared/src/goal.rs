//! `goal` (in progress).
