//! `grid` (in progress).
