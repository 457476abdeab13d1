//! # marionette-core
//!
//! The one `no_std` core of Marionette, used unchanged by the host tools and the
//! firmware. It holds no heap, no `unsafe` and no panic path: every capacity is a
//! const generic or a documented constant, every fallible step returns a typed
//! error, and every array access is checked.
//!
//! ## Pipeline
//!
//! ```text
//! message -> sensor map -> params + goals -> synth (grid / clip) -> solve -> servo map
//! ```
//!
//! ## Determinism
//!
//! Host and firmware must produce bit-identical numbers. The core therefore never
//! calls `f32` inherent methods such as `x.sin()` (on the host these resolve to
//! `std`, on the firmware to something else). All transcendental functions go
//! through [`math`].
#![no_std]
#![forbid(unsafe_code)]
#![cfg_attr(
    test,
    allow(
        clippy::indexing_slicing,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic
    )
)]

pub mod body;
pub mod clip;
pub mod crc;
pub mod frame;
pub mod goal;
pub mod grid;
pub mod math;
pub mod output;
pub mod perform;
pub mod pose;
pub mod region;
pub mod rig;
pub mod servo;
pub mod solve;
pub mod table;
pub mod wire;
