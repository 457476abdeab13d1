//! Shared support for Marionette's end-to-end tests: slow, obviously correct
//! `f64` reference implementations live here, never in the code under test.
