//! (import tests, in progress)
