//! `solve` (in progress).
