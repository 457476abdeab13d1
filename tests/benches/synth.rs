//! (synth benches, in progress)
fn main() {}
