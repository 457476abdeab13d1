//! # marionette-host
//!
//! The host half of Marionette: everything that builds and drives, never the
//! per-frame logic itself (that lives in `marionette-core`, which this crate
//! calls).

pub mod blob;
pub mod board;
pub mod build;
pub mod bundle;
pub mod capacity;
pub mod cmd;
pub mod flash;
pub mod icount;
pub mod import;
pub mod interrupt;
pub mod link;
pub mod live;
pub mod locate;
pub mod perform;
pub mod period;
pub mod progress;
pub mod qemu;
pub mod refusal;
pub mod render;
pub mod rigfile;
pub mod save;
pub mod sender;
pub mod show;
pub mod skeleton;
pub mod take;
#[cfg(feature = "view")]
pub mod view;
