//! Feeding a [`View`] from a session on the emulated board: the servo
//! targets from the servo bus as they come (Maestro; a bus-servo rig's
//! from the board's telemetry, which carries quarter-µs targets), the goals
//! of the tracker frame those targets answer, and the residuals, errors,
//! state and trips of the board's last `Telemetry` or `Status`.

use super::View;
use super::scene::{LinkView, Reported, Scene, Snapshot, state_name};
use crate::cmd::demo::error_total;
use crate::perform::{self, ServoFormat};
use crate::qemu::Taps;
use marionette_core::rig::Rig;
use marionette_core::wire::{Message, TrackerFrame};
use std::cell::RefCell;
use std::time::Instant;

/// A session watched by a view.
pub struct Watch<'a> {
    view: &'a View,
    scene: Scene<'a>,
    frames: Vec<TrackerFrame>,
    /// The newest frame offered, when the frames are not known in advance.
    newest: RefCell<Option<TrackerFrame>>,
    format: ServoFormat,
    start: Instant,
}

impl<'a> Watch<'a> {
    /// Watches the performance of `frames` (the tracker frames sent, in
    /// order) by `rig`, whose outputs go out as `format`.
    #[must_use]
    pub fn new(
        view: &'a View,
        rig: &'a Rig<'a>,
        title: impl Into<String>,
        frames: &[TrackerFrame],
        format: ServoFormat,
    ) -> Self {
        Self {
            view,
            scene: Scene::new(rig, title),
            frames: frames.to_vec(),
            newest: RefCell::new(None),
            format,
            start: Instant::now(),
        }
    }

    /// Offers the view what the board has sent so far.
    pub fn board(&self, taps: &Taps) {
        self.view.offer(|| self.snapshot(taps));
    }

    /// The snapshot of what the emulated board has sent so far.
    #[must_use]
    pub fn snapshot(&self, taps: &Taps) -> Snapshot {
        let per_frame = self.format.bytes_for(1).max(1);
        let done = taps.servo_len() / per_frame;
        let replies = perform::decode_replies(&taps.replies());
        let bus = match &self.format {
            ServoFormat::Maestro { .. } if done > 0 => self
                .format
                .decode(&taps.servo_bytes((done - 1) * per_frame..done * per_frame))
                .pop(),
            _ => None,
        };
        self.compose(&replies, bus, done, 0)
    }

    /// Offers the view a real board's state: its recent replies (the
    /// servo targets from its last `Telemetry`), `sent` tracker frames
    /// offered so far, `drops` dropped by the sender, and the `newest`
    /// frame offered if the frames were not given to [`Watch::new`] (a
    /// live source).
    pub fn replies(
        &self,
        recent: &dyn Fn() -> Vec<Message>,
        sent: usize,
        drops: u64,
        newest: Option<&TrackerFrame>,
    ) {
        if let Some(f) = newest {
            *self.newest.borrow_mut() = Some(*f);
        }
        self.view
            .offer(|| self.compose(&recent(), None, sent, drops));
    }

    /// The snapshot of the board's replies, with the servo targets of
    /// `bus` if given (else its last telemetry's), after `done` frames.
    fn compose(
        &self,
        replies: &[Message],
        bus: Option<Vec<u16>>,
        done: usize,
        drops: u64,
    ) -> Snapshot {
        let mut link = LinkView {
            frames: done as u64,
            rate_hz: done as f64 / self.start.elapsed().as_secs_f64().max(1e-3),
            drops,
            connected: true,
            state: "waiting".into(),
            ..LinkView::default()
        };
        let mut residuals = Vec::new();
        let mut telemetry_targets = Vec::new();
        for m in replies {
            match m {
                Message::Telemetry(t) => {
                    link.errors = u64::from(error_total(&t.errors));
                    link.state = state_name(t.state);
                    link.trips = t.trips;
                    residuals = t.goal_residuals.as_slice().to_vec();
                    telemetry_targets = t.servo_targets.as_slice().to_vec();
                }
                Message::Status(s) => {
                    link.errors = u64::from(error_total(&s.errors));
                    link.state = state_name(s.state);
                    link.trips = s.trips;
                }
                _ => {}
            }
        }
        let targets = bus.unwrap_or(telemetry_targets);
        let newest = *self.newest.borrow();
        self.scene.snapshot(&Reported {
            targets: &targets,
            frame: newest
                .as_ref()
                .or_else(|| done.checked_sub(1).and_then(|i| self.frames.get(i))),
            residuals: &residuals,
            t_s: self.start.elapsed().as_secs_f64(),
            link,
        })
    }
}
