//! `marionette view`, and the `--view` options of `demo`, `emulate`,
//! `stream` and `live`: the performance shown live in a web page while the
//! board performs it ([`crate::view`]; the page is described in
//! `docs/view.md`).
//!
//! `marionette view` is the demo watched: the same inputs and checks as
//! `marionette demo` (its options too), with the view on.

use super::CmdError;
use crate::qemu::Taps;
use marionette_core::wire::{Message, TrackerFrame};
use std::net::SocketAddr;

/// Why `--view` is refused by a build without the view.
#[cfg(not(feature = "view"))]
const NO_VIEW: &str = "this marionette was built without the `view` feature: build it with the \
                       default features (`cargo run --release -p marionette-host -- …` or \
                       `cargo install --path host`)";

/// Where the view listens by default: this machine only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8765";

/// The live view's options.
#[derive(clap::Args, Clone, Debug)]
pub struct ViewArgs {
    /// Show the performance live in a web page (the figure in four views,
    /// the goals and residuals, each servo within its limits, the link and
    /// the board's state; read-only). The address is printed at the start.
    #[arg(long)]
    pub view: bool,
    /// Where the view listens: this machine only unless told otherwise
    /// (port 0: any free port).
    #[arg(long, default_value = DEFAULT_LISTEN, value_name = "ADDR")]
    pub listen: SocketAddr,
    /// Seconds the page keeps being served after the session ends.
    #[arg(long, default_value_t = 3.0, value_name = "SECONDS")]
    pub view_linger: f64,
}

/// Seconds the view lingers, bounded.
#[cfg(feature = "view")]
fn linger(args: &ViewArgs) -> std::time::Duration {
    std::time::Duration::from_secs_f64(args.view_linger.clamp(0.0, 3600.0))
}

/// What a real board's session tells its view after each frame offered
/// (and, for a live source, while it waits for one): frames offered so
/// far, frames dropped, the newest frame offered when the frames are not
/// known in advance (`live`), and a way to read its recent replies (called
/// only when a snapshot is due).
pub type BoardHook<'h> = &'h dyn Fn(usize, u64, Option<&TrackerFrame>, &dyn Fn() -> Vec<Message>);

/// Runs `session` (a performance on a real board, `stream` or `live`, of
/// the rig `rig_blob`) under the live view when `--view` asks for it.
#[cfg_attr(not(feature = "view"), allow(unused_variables))]
pub fn watched_board<R>(
    args: &ViewArgs,
    rig_blob: &[u8],
    title: &str,
    frames: &[TrackerFrame],
    session: impl FnOnce(BoardHook<'_>) -> Result<R, CmdError>,
) -> Result<R, CmdError> {
    if args.view {
        #[cfg(feature = "view")]
        return with_board_view(args, rig_blob, title, frames, session);
        #[cfg(not(feature = "view"))]
        return Err(NO_VIEW.into());
    }
    session(&|_, _, _, _| ())
}

/// Runs `session` (an emulated performance of `region`, given a watcher
/// of the board's links) under the live view when `--view` asks for it.
#[cfg_attr(not(feature = "view"), allow(unused_variables))]
pub fn watched<R>(
    args: &ViewArgs,
    region: &[u8],
    title: &str,
    frames: &[TrackerFrame],
    session: impl FnOnce(&dyn Fn(&Taps)) -> Result<R, CmdError>,
) -> Result<R, CmdError> {
    if args.view {
        #[cfg(feature = "view")]
        return with_view(args, region, title, frames, session);
        #[cfg(not(feature = "view"))]
        return Err(NO_VIEW.into());
    }
    session(&|_| ())
}

/// Starts the view asked for and says where it is.
#[cfg(feature = "view")]
fn start(args: &ViewArgs) -> Result<crate::view::View, CmdError> {
    let view = crate::view::View::start(args.listen)?;
    eprintln!("marionette: live view at {}", view.url());
    Ok(view)
}

/// The servo channels a rig drives (its highest channel + 1).
#[cfg(feature = "view")]
fn channels(rig: &marionette_core::rig::Rig<'_>) -> usize {
    rig.servos()
        .iter()
        .map(|s| usize::from(s.channel) + 1)
        .max()
        .unwrap_or(1)
}

#[cfg(feature = "view")]
fn with_board_view<R>(
    args: &ViewArgs,
    rig_blob: &[u8],
    title: &str,
    frames: &[TrackerFrame],
    session: impl FnOnce(BoardHook<'_>) -> Result<R, CmdError>,
) -> Result<R, CmdError> {
    use crate::perform::ServoFormat;
    use crate::view::watch::Watch;
    let (rig, _) =
        marionette_core::rig::Rig::parse(rig_blob).map_err(|e| format!("the rig: {e:?}"))?;
    let view = start(args)?;
    // A real board's targets come from its telemetry: the format is unused.
    let format = ServoFormat::Maestro {
        channels: channels(&rig),
    };
    let watch = Watch::new(&view, &rig, title, frames, format);
    let result = session(&|sent, drops, newest, recent| {
        watch.replies(recent, sent, drops, newest);
    });
    view.end(linger(args));
    result
}

#[cfg(feature = "view")]
fn with_view<R>(
    args: &ViewArgs,
    region: &[u8],
    title: &str,
    frames: &[TrackerFrame],
    session: impl FnOnce(&dyn Fn(&Taps)) -> Result<R, CmdError>,
) -> Result<R, CmdError> {
    use crate::perform::ServoFormat;
    use crate::view::watch::Watch;
    use marionette_core::frame::Region;
    let parsed = Region::parse(region);
    let Some(rig) = parsed.rig.as_ref() else {
        return session(&|_| ());
    };
    let channels = channels(rig);
    let format =
        ServoFormat::of_region(region, channels).unwrap_or(ServoFormat::Maestro { channels });
    let view = start(args)?;
    let watch = Watch::new(&view, rig, title, frames, format);
    let last = std::cell::RefCell::new(None);
    let result = session(&|taps: &Taps| {
        watch.board(taps);
        *last.borrow_mut() = Some(taps.clone());
    });
    if let Some(taps) = last.take() {
        view.publish(&watch.snapshot(&taps));
    }
    view.end(linger(args));
    result
}

/// The live view's options on `marionette live`, whose `--listen` is its
/// tracker source's (UDP): the view's address is `--view-listen`.
#[derive(clap::Args, Clone, Debug)]
pub struct LiveViewArgs {
    /// Show the performance live in a web page (as `stream --view`: the
    /// figure from the servo targets in the board's telemetry; read-only).
    /// The address is printed at the start.
    #[arg(long)]
    pub view: bool,
    /// Where the view listens: this machine only unless told otherwise
    /// (port 0: any free port).
    #[arg(long, default_value = DEFAULT_LISTEN, value_name = "ADDR")]
    pub view_listen: SocketAddr,
    /// Seconds the page keeps being served after the session ends.
    #[arg(long, default_value_t = 3.0, value_name = "SECONDS")]
    pub view_linger: f64,
}

impl From<&LiveViewArgs> for ViewArgs {
    fn from(a: &LiveViewArgs) -> Self {
        Self {
            view: a.view,
            listen: a.view_listen,
            view_linger: a.view_linger,
        }
    }
}

impl Default for LiveViewArgs {
    /// No view.
    fn default() -> Self {
        let v = ViewArgs::default();
        Self {
            view: v.view,
            view_listen: v.listen,
            view_linger: v.view_linger,
        }
    }
}

impl Default for ViewArgs {
    /// No view.
    fn default() -> Self {
        Self {
            view: false,
            listen: SocketAddr::from(([127, 0, 0, 1], 8765)),
            view_linger: 3.0,
        }
    }
}
