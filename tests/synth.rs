//! (synth tests, in progress)
