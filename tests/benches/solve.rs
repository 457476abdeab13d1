//! (solve benches, in progress)
fn main() {}
