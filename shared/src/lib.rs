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
//! ## Start here
//!
//! Each entry point carries a runnable example (run as doctests):
//!
//! - a grid query over a table's axes: [`grid::Grid::query`];
//! - synthesizing a pose from samples in memory: [`grid::Grid::synthesize`]
//!   (a flashed table: [`table::Table::parse`], then [`table::Table::grid`]);
//! - solving weighted goals on a body: [`solve::solve`];
//! - encoding a wire frame and receiving it on the board:
//!   [`wire::encode`] and [`wire::Receiver`];
//! - the board's loop on a few messages: [`perform::Performer`].
//!
//! ```
//! use marionette_core::grid::{Axis, Grid};
//!
//! let grid = Grid::new(&[Axis::linear(-1.0, 0.5, 5)], None).unwrap();
//! let q = grid.query(&[0.25]).unwrap();
//! assert_eq!(q.window().indices(), &[2, 3]);
//! assert_eq!(q.window().weights(), &[0.5, 0.5]);
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
pub mod deadline;
pub mod frame;
pub mod goal;
pub mod grid;
pub mod layer;
pub mod math;
pub mod output;
pub mod perform;
pub mod pose;
pub mod region;
pub mod rig;
pub mod servo;
pub mod show;
pub mod solve;
pub mod table;
pub mod wire;
