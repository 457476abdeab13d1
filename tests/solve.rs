//! (solve tests, in progress)
