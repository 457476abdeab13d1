//! The core's own `f32` math (filled in by the synthesis work).
