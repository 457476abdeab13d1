//! # marionette-host
//!
//! The host half of Marionette: everything that builds and drives, never the
//! per-frame logic itself (that lives in `marionette-core`, which this crate
//! calls).

pub mod blob;
pub mod build;
pub mod cmd;
pub mod flash;
pub mod icount;
pub mod import;
pub mod link;
pub mod locate;
pub mod perform;
pub mod qemu;
pub mod render;
pub mod rigfile;
