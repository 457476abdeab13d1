//! A real-time sender: tracker frames to a board over a link that may be
//! slower than the frames come, or stall.
//!
//! **Newest wins.** The sender holds at most one tracker frame waiting to
//! go out. A frame offered while another is still waiting replaces it, and
//! the replaced one is counted as dropped: nothing queues behind a slow
//! link. A writer thread takes the newest frame only when the link is free
//! (see below), gives it the next sequence number, encodes it, writes it,
//! and records it: the frames actually sent, in order, are a session `sim`
//! replays exactly ([`Sender::finish`] returns them).
//!
//! **When the link is free.** The writer never writes faster than the
//! link's rate: after a frame of `B` bytes it waits `10·B / baud` seconds
//! (8N1) before taking the next. It then waits for the port's own
//! [`Write::flush`] (on a serial port, the driver's `tcdrain`: until the
//! bytes are on the wire). A write that times out is retried where it
//! stopped, never abandoned: a slow or stalled link drops frames, it never
//! aborts the performance. Only a failed port (not a slow one) stops the
//! writer, with its error.
//!
//! Commands (`Hello`, `Arm`, `Disarm`) are never dropped: they wait in
//! order and go before the next tracker frame.

use crate::link::Link;
use crate::perform::{Framing, Sent, frame_bytes, tracker_message};
use marionette_core::rig::MAX_PARAMS;
use marionette_core::wire::{Command, CommandKind, List, Message, Params, TrackerFrame};
use std::collections::VecDeque;
use std::io::{ErrorKind, Write};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What the sender did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Counts {
    /// Tracker frames offered.
    pub offered: u64,
    /// Tracker frames written to the link.
    pub sent: u64,
    /// Tracker frames replaced by a newer one before they could go.
    pub dropped: u64,
    /// Bytes written (frames, parameters and commands).
    pub bytes: u64,
    /// `Params` messages written (each the newest values when the link
    /// was free; older ones are replaced, not queued).
    pub params_sent: u64,
}

/// A message that is never dropped.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Control {
    /// `Hello` (after a `0x00`): the sequence numbers start again at 0.
    Hello,
    /// A command, with the next sequence number.
    Command(CommandKind),
}

/// Something waiting for the writer.
#[derive(Default)]
struct Queue {
    controls: VecDeque<Control>,
    frame: Option<TrackerFrame>,
    params: Option<List<f32, MAX_PARAMS>>,
    counts: Counts,
    /// Frames written, with the sequence numbers they went with.
    sent: Vec<TrackerFrame>,
    /// Every message written (commands, `Params`, frames), as written, at
    /// the time it went (µs since the sender started): a take's session.
    written: Vec<Sent>,
    /// The writer has sent everything and stops.
    closing: bool,
    /// The writer stopped on a failed port.
    failed: Option<String>,
    /// The writer is busy with a message.
    busy: bool,
}

type Shared = Arc<(Mutex<Queue>, Condvar)>;

/// The sender: offer frames, queue commands, [`Sender::finish`] at the end.
pub struct Sender {
    shared: Shared,
    writer: Option<JoinHandle<()>>,
}

/// Locks the queue, whatever another thread did while holding it.
fn lock(shared: &Shared) -> std::sync::MutexGuard<'_, Queue> {
    shared.0.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Sender {
    /// Starts the writer thread on `port`, a link of `link`'s rate, with
    /// tracker frames framed as `framing` says.
    pub fn spawn<W: Write + Send + 'static>(port: W, link: Link, framing: Framing) -> Self {
        let shared: Shared = Arc::new((Mutex::new(Queue::default()), Condvar::new()));
        let inner = Arc::clone(&shared);
        let start = Instant::now();
        let writer = std::thread::spawn(move || write_loop(port, link, framing, &inner, start));
        Self {
            shared,
            writer: Some(writer),
        }
    }

    fn control(&self, c: Control) {
        lock(&self.shared).controls.push_back(c);
        self.shared.1.notify_all();
    }

    /// Queues a `Hello` (sequence numbers start again at 0 after it).
    pub fn hello(&self) {
        self.control(Control::Hello);
    }

    /// Queues a command (never dropped; it takes the next sequence number).
    pub fn command(&self, kind: CommandKind) {
        self.control(Control::Command(kind));
    }

    /// Offers a tracker frame (its `seq` is the writer's); it replaces, and
    /// drops, one still waiting.
    pub fn offer(&self, frame: TrackerFrame) {
        let mut q = lock(&self.shared);
        q.counts.offered += 1;
        if q.frame.replace(frame).is_some() {
            q.counts.dropped += 1;
        }
        self.shared.1.notify_all();
    }

    /// Offers parameter values (a `Params` message, sent before the next
    /// tracker frame); they replace values still waiting.
    pub fn offer_params(&self, values: &[f32]) {
        lock(&self.shared).params = List::from_slice(values).ok();
        self.shared.1.notify_all();
    }

    /// Takes the tracker frames sent so far (with their sequence numbers),
    /// for a recording written as it goes.
    pub fn take_sent(&self) -> Vec<TrackerFrame> {
        std::mem::take(&mut lock(&self.shared).sent)
    }

    /// Takes every message written so far (see [`Sender::finish`]'s
    /// frames: these are all of them, commands and `Params` too), each the
    /// bytes as written at its time, µs since the sender started.
    pub fn take_written(&self) -> Vec<Sent> {
        std::mem::take(&mut lock(&self.shared).written)
    }

    /// What the sender did so far.
    #[must_use]
    pub fn counts(&self) -> Counts {
        lock(&self.shared).counts.clone()
    }

    /// The writer's error, if the port failed.
    #[must_use]
    pub fn failed(&self) -> Option<String> {
        lock(&self.shared).failed.clone()
    }

    /// Waits until everything queued has been written (or `limit` passed,
    /// or the port failed); true if it has.
    pub fn drain(&self, limit: Duration) -> bool {
        let deadline = Instant::now() + limit;
        let mut q = lock(&self.shared);
        loop {
            if q.failed.is_some() {
                return false;
            }
            if !q.busy && q.controls.is_empty() && q.frame.is_none() && q.params.is_none() {
                return true;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            q = self
                .shared
                .1
                .wait_timeout(q, left.min(Duration::from_millis(20)))
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Stops the writer once it has sent what is queued (waiting at most
    /// `limit`: a stalled writer is left behind) and returns the counts and
    /// the tracker frames sent, in order, with their sequence numbers.
    pub fn finish(mut self, limit: Duration) -> (Counts, Vec<TrackerFrame>) {
        self.drain(limit);
        let mut q = lock(&self.shared);
        q.closing = true;
        self.shared.1.notify_all();
        let out = (q.counts.clone(), std::mem::take(&mut q.sent));
        drop(q);
        if let Some(w) = self.writer.take()
            && w.is_finished()
        {
            let _ = w.join();
        }
        out
    }
}

/// What the writer takes next: a control first, else the newest frame.
enum Next {
    Control(Control),
    Params(List<f32, MAX_PARAMS>),
    Frame(Box<TrackerFrame>),
}

/// The writer thread: waits for the link to be free and something to send,
/// sends it, records it.
fn write_loop<W: Write>(
    mut port: W,
    link: Link,
    framing: Framing,
    shared: &Shared,
    start: Instant,
) {
    let mut seq = 0u32;
    let mut free_at = Instant::now();
    loop {
        // The link's own time for the last message first (newest wins
        // meanwhile), then whatever is newest.
        std::thread::sleep(free_at.saturating_duration_since(Instant::now()));
        let Some(next) = take(shared) else {
            return;
        };
        let is_params = matches!(next, Next::Params(_));
        let (bytes, frame) = match next {
            Next::Control(Control::Hello) => {
                seq = 0;
                let hello = Message::Hello(marionette_core::wire::Hello {
                    protocol_version: marionette_core::wire::PROTOCOL_VERSION,
                });
                (crate::perform::encode(&hello), None)
            }
            Next::Control(Control::Command(kind)) => {
                let msg = Message::Command(Command { seq, kind });
                seq = seq.wrapping_add(1);
                (frame_bytes(&msg), None)
            }
            Next::Params(values) => {
                let msg = Message::Params(Params { seq, values });
                seq = seq.wrapping_add(1);
                (frame_bytes(&msg), None)
            }
            Next::Frame(mut f) => {
                f.seq = seq;
                seq = seq.wrapping_add(1);
                (frame_bytes(&tracker_message(&f, framing)), Some(*f))
            }
        };
        let bytes = bytes.unwrap_or_default();
        let time_us = u32::try_from(start.elapsed().as_micros()).unwrap_or(u32::MAX);
        let result = write_fully(&mut port, &bytes);
        let mut q = lock(shared);
        q.busy = false;
        if let Err(e) = result {
            q.failed = Some(e.to_string());
            shared.1.notify_all();
            return;
        }
        q.counts.bytes += bytes.len() as u64;
        q.counts.params_sent += u64::from(is_params);
        if let Some(f) = frame {
            q.counts.sent += 1;
            q.sent.push(f);
        }
        free_at = free_at.max(Instant::now()) + link.transfer_time(bytes.len());
        q.written.push(Sent { time_us, bytes });
        shared.1.notify_all();
        drop(q);
    }
}

/// Waits for something to send; `None` once closing with nothing left.
fn take(shared: &Shared) -> Option<Next> {
    let mut q = lock(shared);
    loop {
        if let Some(c) = q.controls.pop_front() {
            q.busy = true;
            return Some(Next::Control(c));
        }
        if let Some(p) = q.params.take() {
            q.busy = true;
            return Some(Next::Params(p));
        }
        if let Some(f) = q.frame.take() {
            q.busy = true;
            return Some(Next::Frame(Box::new(f)));
        }
        if q.closing {
            return None;
        }
        q = shared
            .1
            .wait_timeout(q, Duration::from_millis(50))
            .unwrap_or_else(PoisonError::into_inner)
            .0;
    }
}

/// Writes every byte, retrying where a write timed out or was interrupted,
/// then waits for the port to have sent them ([`Write::flush`]).
fn write_fully<W: Write>(port: &mut W, mut bytes: &[u8]) -> std::io::Result<()> {
    while !bytes.is_empty() {
        match port.write(bytes) {
            Ok(0) => {
                return Err(std::io::Error::new(
                    ErrorKind::WriteZero,
                    "the port took nothing",
                ));
            }
            Ok(n) => bytes = bytes.get(n..).unwrap_or(&[]),
            Err(e) if retry(&e) => {}
            Err(e) => return Err(e),
        }
    }
    loop {
        match port.flush() {
            Ok(()) => return Ok(()),
            Err(e) if retry(&e) => {}
            Err(e) => return Err(e),
        }
    }
}

/// A slow link, not a broken one.
fn retry(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use marionette_core::wire::List;

    /// A port that times out on every write until `until`, then takes
    /// everything.
    struct Stalled {
        until: Instant,
        written: Arc<Mutex<Vec<u8>>>,
    }

    impl Write for Stalled {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if Instant::now() < self.until {
                std::thread::sleep(Duration::from_millis(5));
                return Err(ErrorKind::TimedOut.into());
            }
            self.written
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .extend_from_slice(buf);
            Ok(buf.len())
        }

        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn frame(time_us: u32) -> TrackerFrame {
        TrackerFrame {
            seq: 0,
            time_us,
            sensors: List::new(),
        }
    }

    #[test]
    fn a_stalled_port_drops_all_but_the_newest_frame_and_keeps_every_command() {
        let written = Arc::new(Mutex::new(Vec::new()));
        let port = Stalled {
            until: Instant::now() + Duration::from_millis(300),
            written: Arc::clone(&written),
        };
        let sender = Sender::spawn(port, Link::Uart { baud: 921_600 }, Framing::F32);
        sender.hello();
        sender.command(CommandKind::Arm);
        // Ten frames while the port is stalled on the Hello: only the
        // last can still go.
        for t in 1..=10 {
            sender.offer(frame(t * 1000));
        }
        assert!(sender.drain(Duration::from_secs(5)));
        sender.command(CommandKind::Disarm);
        let (counts, sent) = sender.finish(Duration::from_secs(5));
        assert_eq!((counts.offered, counts.sent, counts.dropped), (10, 1, 9));
        assert_eq!(sent.len(), 1);
        assert_eq!((sent[0].seq, sent[0].time_us), (1, 10_000));
        let bytes = written.lock().unwrap().clone();
        assert_eq!(counts.bytes, bytes.len() as u64);
        let got = crate::perform::decode_replies(&bytes);
        let kinds: Vec<String> = got
            .iter()
            .map(|m| match m {
                Message::Hello(_) => "hello".to_owned(),
                Message::Command(c) => format!("{:?} {}", c.kind, c.seq),
                Message::TrackerFrame(f) => format!("frame {} {}", f.seq, f.time_us),
                other => format!("{other:?}"),
            })
            .collect();
        assert_eq!(kinds, ["hello", "Arm 0", "frame 1 10000", "Disarm 2"]);
    }

    #[test]
    fn params_go_before_the_next_frame_newest_values_only() {
        let written = Arc::new(Mutex::new(Vec::new()));
        let port = Stalled {
            until: Instant::now() + Duration::from_millis(200),
            written: Arc::clone(&written),
        };
        let sender = Sender::spawn(port, Link::Uart { baud: 921_600 }, Framing::F32);
        sender.hello();
        sender.offer_params(&[1.0]);
        sender.offer_params(&[2.0, 3.0]);
        sender.offer(frame(5));
        let (counts, _) = sender.finish(Duration::from_secs(5));
        assert_eq!((counts.params_sent, counts.sent), (1, 1));
        let got = crate::perform::decode_replies(&written.lock().unwrap());
        let params = got.iter().find_map(|m| match m {
            Message::Params(p) => Some((p.seq, p.values.as_slice().to_vec())),
            _ => None,
        });
        assert_eq!(params, Some((0, vec![2.0, 3.0])));
        assert!(matches!(got.last(), Some(Message::TrackerFrame(f)) if f.seq == 1));
    }

    #[test]
    fn the_writer_never_writes_faster_than_the_link() {
        let written = Arc::new(Mutex::new(Vec::new()));
        let port = Stalled {
            until: Instant::now(),
            written: Arc::clone(&written),
        };
        // 10,000 baud: 1,000 bytes a second; an empty f32 frame is a few
        // bytes, so 200 offered back to back must mostly be dropped.
        let link = Link::Uart { baud: 10_000 };
        let sender = Sender::spawn(port, link, Framing::F32);
        let start = Instant::now();
        for t in 0..200 {
            sender.offer(frame(t));
            std::thread::sleep(Duration::from_micros(500));
        }
        sender.drain(Duration::from_secs(5));
        let seconds = start.elapsed().as_secs_f64();
        let (counts, _) = sender.finish(Duration::from_secs(5));
        assert_eq!(counts.sent + counts.dropped, 200);
        assert!(counts.dropped > 0);
        // Every message but the last had its full transfer time.
        let last = written.lock().unwrap().len() as f64 / f64::from(counts.sent.max(1) as u32);
        assert!(
            (counts.bytes as f64 - last) / link.bytes_per_second() <= seconds,
            "{counts:?} in {seconds} s"
        );
    }
}
