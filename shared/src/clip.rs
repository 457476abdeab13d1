//! `clip` (in progress).
