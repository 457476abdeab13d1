//! `pose` (in progress).
