//! `marionette stream --port DEV`: a performance on a real board, in real
//! time.
//!
//! Streams a tracker recording to a board over a serial port (the session of
//! `marionette emulate` and `sim`: `Hello`, `Arm`, the frames, `Disarm`)
//! through the real-time [`Sender`]: each frame is offered at its recorded
//! time, and one that cannot go out before the next is due is dropped and
//! counted, never queued behind (newest wins). A slow or stalled link drops
//! frames; it never aborts the performance.
//!
//! It first says `Hello` until the board answers (QEMU's pseudo-terminals
//! notice a new reader only once a second), and stops with the board's
//! reason and what to do if the board cannot arm. At the end it writes:
//!
//! - `sent.csv`: the frames actually sent, as a tracker recording (every
//!   value exact): `marionette sim` on it reproduces the board's servo
//!   output bit for bit (given the board's fail-safe trips, which its
//!   telemetry reports);
//! - `telemetry.csv`: the servo targets the board reported;
//! - with `--take T.take`, the session as a take (docs/take.md): every
//!   message written, the replies, and the targets the telemetry reported.
//!
//! Ctrl-C (SIGINT; SIGTERM and SIGHUP too) stops offering frames and ends
//! the session as at the recording's end (`Disarm`, the files, the take,
//! the summary with `stopped`); a second quits at once with exit code 130
//! ([`crate::interrupt`]).
//!
//! It prints frames sent and dropped, the link's use against its capacity,
//! and what the board said about itself: its state, fail-safe trips, and
//! frame timing (mean, worst, overruns of the frame period) in its counter
//! units (see README, "Reading the board's timing").

use super::CmdError;
use crate::import::csv::TrackerSample;
use crate::link::Link;
use crate::perform::{self, Framing};
use crate::refusal::{ShowReport, Stop};
use crate::sender::{Counts, Sender};
use crate::{import, rigfile};
use marionette_core::wire::{
    CommandKind, FrameTiming, Message, ShowState, State, Status, StatusReason, TrackerFrame,
};
use serde::Serialize;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Arguments of `marionette stream`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The board's tracker serial port, e.g. /dev/ttyUSB0.
    #[arg(long)]
    pub port: String,
    /// Baud rate of the tracker link (the Black Pill's USART1 runs at
    /// 921 600); the sender never writes faster than it.
    #[arg(long, default_value_t = 921_600)]
    pub baud: u32,
    /// The tracker recording (CSV; docs/recording.md).
    #[arg(long)]
    pub recording: PathBuf,
    /// The rig file (docs/rig.md; for its frame period, the rig itself is in
    /// the board's flash), or a rig name: `rigs/<name>.toml` here, else a
    /// rig built in (humanoid16, cmu31).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// Send every frame as soon as the link takes it (nothing dropped, not
    /// in real time) instead of at its recorded time.
    #[arg(long)]
    pub fast: bool,
    /// How tracker frames travel: the compact frame (quantized) or `f32`.
    #[arg(long, value_enum, default_value_t = Framing::Compact)]
    pub frame: Framing,
    /// Where to write `telemetry.csv` and `sent.csv`.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// Also save the session as a take (docs/take.md): the messages sent,
    /// the board's replies, and the servo targets its telemetry reported
    /// (a board's servo link is not seen from here).
    #[arg(long)]
    pub take: Option<PathBuf>,
    /// The table blob the board's flash holds, kept in the take with the
    /// rig (so that `replay --emulated`, `take edit` and `take export
    /// --bvh` can run the core on it); without it the take holds the rig
    /// only. Repeat it for a rig with `[[layer]]` tables.
    #[arg(long)]
    pub tables: Vec<PathBuf>,
    /// The live view (`--view`, `--listen`), from the board's telemetry.
    #[command(flatten)]
    pub view: super::view::ViewArgs,
}

/// What a stream did, and what the board answered.
#[derive(Debug, Default, Serialize)]
pub struct Summary {
    /// Tracker frames in the recording.
    pub frames: usize,
    /// What the sender did: frames offered, sent, dropped; bytes written.
    pub sender: Counts,
    /// Seconds from the first frame to the last one sent.
    pub seconds: f64,
    /// Bytes a second written, on average.
    pub link_bytes_per_s: f64,
    /// The link's capacity, bytes a second (8N1).
    pub link_capacity_bytes_per_s: f64,
    /// Status messages received.
    pub statuses: usize,
    /// Acks received.
    pub acks: usize,
    /// Acks that refused their command.
    pub refused: usize,
    /// Telemetry messages received.
    pub telemetry: usize,
    /// The board's last error counters' total.
    pub errors: u32,
    /// The board's last reported state.
    pub state: Option<State>,
    /// Fail-safe trips the board reported.
    pub trips: u32,
    /// The board's last reported frame timing (its counter units).
    pub timing: Option<FrameTiming>,
    /// Whether the board acknowledged the closing `Disarm` (its replies
    /// to every frame before it then arrived).
    pub disarm_acked: bool,
    /// The telemetry CSV written.
    pub telemetry_csv: String,
    /// The recording of the frames sent.
    pub sent_csv: String,
    /// The board's flashed show, from its last `Status` (`null` if it sent
    /// none).
    pub show: Option<ShowReport>,
    /// Whether Ctrl-C (or SIGTERM, SIGHUP) ended the session: `stream`
    /// before the recording's end, `live` before `--seconds`.
    pub stopped: bool,
}

/// Tallies the board's replies into `s` and writes the telemetry's servo
/// targets to `csv`.
pub fn summarize(replies: &[Message], s: &mut Summary, csv: &Path) -> Result<(), CmdError> {
    let mut text = String::from("seq,targets_us\n");
    for m in replies {
        match m {
            Message::Status(st) => {
                s.statuses += 1;
                s.errors = st.errors.total();
                s.state = Some(st.state);
            }
            Message::Ack(a) => {
                s.acks += 1;
                s.refused += usize::from(!a.ok);
            }
            Message::Telemetry(t) => {
                s.telemetry += 1;
                s.errors = t.errors.total();
                s.state = Some(t.state);
                s.trips = t.trips;
                s.timing = Some(t.timing);
                let us: Vec<String> = t
                    .servo_targets
                    .iter()
                    .map(|q| (f64::from(*q) / 4.0).to_string())
                    .collect();
                text.push_str(&format!("{},{}\n", t.seq, us.join(" ")));
            }
            _ => {}
        }
    }
    s.show = ShowReport::of(replies);
    s.telemetry_csv = csv.display().to_string();
    crate::save::save(csv, text.as_bytes(), &[])?;
    Ok(())
}

/// Bytes from the board, collected by a background thread.
pub struct Replies {
    bytes: Arc<Mutex<Vec<u8>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Replies {
    /// Starts reading `port` (which has a read timeout).
    pub fn spawn(mut port: impl Read + Send + 'static) -> Self {
        let bytes = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (sink, halt) = (Arc::clone(&bytes), Arc::clone(&stop));
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 1024];
            while !halt.load(Ordering::Relaxed) {
                match port.read(&mut buf) {
                    Ok(n) if n > 0 => {
                        if let (Ok(mut v), Some(chunk)) = (sink.lock(), buf.get(..n)) {
                            v.extend_from_slice(chunk);
                        }
                    }
                    Ok(_) => std::thread::sleep(Duration::from_millis(1)),
                    Err(_) => std::thread::sleep(Duration::from_millis(1)),
                }
            }
        });
        Self {
            bytes,
            stop,
            thread: Some(thread),
        }
    }

    /// The messages in the last `bytes` bytes received (the first may be
    /// cut: it is skipped).
    #[must_use]
    pub fn recent(&self, bytes: usize) -> Vec<Message> {
        let tail = self
            .bytes
            .lock()
            .map(|v| v[v.len().saturating_sub(bytes)..].to_vec())
            .unwrap_or_default();
        perform::decode_replies(&tail)
    }

    /// The messages received so far.
    #[must_use]
    pub fn messages(&self) -> Vec<Message> {
        let bytes = self.bytes.lock().map(|v| v.clone()).unwrap_or_default();
        perform::decode_replies(&bytes)
    }

    /// Waits up to `limit` for a reply `pick` accepts.
    pub fn wait_for<T>(&self, limit: Duration, pick: impl Fn(&Message) -> Option<T>) -> Option<T> {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(found) = self.messages().iter().find_map(&pick) {
                return Some(found);
            }
            if Instant::now() > deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Stops reading and returns every message received.
    pub fn finish(mut self) -> Vec<Message> {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.messages()
    }
}

/// Says `Hello` until the board answers with a `Status` (once a second, up
/// to `limit`); errors if it never does or cannot arm, or if `stop` is set
/// first (a Ctrl-C while waiting acts within a second and the board is
/// never armed).
pub fn handshake(
    sender: &Sender,
    replies: &Replies,
    port: &str,
    limit: Duration,
    stop: &AtomicBool,
) -> Result<(), CmdError> {
    let say = &mut || {
        sender.hello();
        Ok(())
    };
    let status = answer_to_hello(say, replies, (port, limit), stop)?;
    if status.reason != StatusReason::Ok || !status.table_ok {
        let reason = if status.reason == StatusReason::Ok {
            StatusReason::NoTable
        } else {
            status.reason
        };
        return Err(Box::new(Stop::refused(
            format!("the board on {port}"),
            reason,
            &[],
            None,
        )));
    }
    Ok(())
}

/// The board's answer to `Hello`: says it (`say`) once a second until the
/// board sends a `Status`, for up to `limit`; a fault if it never does, an
/// error if `stop` is set first (the board is then never armed).
pub fn answer_to_hello(
    say: &mut dyn FnMut() -> Result<(), CmdError>,
    replies: &Replies,
    (port, limit): (&str, Duration),
    stop: &AtomicBool,
) -> Result<Status, CmdError> {
    let deadline = Instant::now() + limit;
    let status = loop {
        if stop.load(Ordering::Relaxed) {
            return Err(stopped_before_arming(port));
        }
        say()?;
        let got = replies.wait_for(Duration::from_secs(1), |m| match m {
            Message::Status(st) if st.request_seq.is_none() => Some(*st),
            _ => None,
        });
        if let Some(st) = got {
            break st;
        }
        if Instant::now() > deadline {
            return Err(Box::new(Stop::fault(
                format!("the board on {port}"),
                format!(
                    "no answer from the board in {limit:?}: check the port, the baud rate, \
                     and that the board runs Marionette's firmware"
                ),
            )));
        }
    };
    if stop.load(Ordering::Relaxed) {
        return Err(stopped_before_arming(port));
    }
    Ok(status)
}

/// Ctrl-C before the board armed: the command ends without arming it
/// (nothing but `Hello` was sent).
fn stopped_before_arming(port: &str) -> CmdError {
    format!("{port}: stopped by Ctrl-C before the board armed (it was sent only Hello)").into()
}

/// Arms the board; a refusal is a [`Stop`] with the board's `Status`
/// reason (asked for again after the refused `Ack`).
pub fn arm(sender: &Sender, replies: &Replies, port: &str) -> Result<(), CmdError> {
    sender.command(CommandKind::Arm);
    let ack = replies.wait_for(Duration::from_secs(2), |m| match m {
        Message::Ack(a) if a.seq == 0 => Some(a.ok),
        _ => None,
    });
    match ack {
        Some(true) => Ok(()),
        Some(false) => {
            sender.hello();
            let reason = replies.wait_for(Duration::from_secs(1), |m| match m {
                Message::Status(st) if st.reason != StatusReason::Ok => Some(st.reason),
                _ => None,
            });
            Err(Box::new(match reason {
                Some(reason) => Stop::refused(format!("the board on {port}"), reason, &[], None),
                None => Stop::fault(
                    format!("the board on {port}"),
                    "it refused Arm but its Status names no reason",
                ),
            }))
        }
        None => Err(Box::new(Stop::fault(
            format!("the board on {port}"),
            "the board did not acknowledge Arm within 2 s",
        ))),
    }
}

/// Waits (up to `limit`) for the board to acknowledge the `Disarm`: the
/// board answers in order, so its replies to every frame before it (the
/// telemetry, with the fail-safe trips) have then arrived, however far
/// behind a loaded board ran. True if it did.
pub fn await_disarm(replies: &Replies, limit: Duration) -> bool {
    // The session's commands are `Arm` (seq 0) and `Disarm` (seq > 0).
    let acked = replies.wait_for(limit, |m| match m {
        Message::Ack(a) if a.seq > 0 => Some(()),
        _ => None,
    });
    // The last bytes after the Ack (nothing the session needs).
    std::thread::sleep(Duration::from_millis(50));
    acked.is_some()
}

/// Offers each frame at its recorded time (or, `fast`, as soon as the
/// last one went) until `stop` is set; returns the frames offered and the
/// seconds it took.
fn schedule(
    sender: &Sender,
    frames: &[TrackerFrame],
    (fast, stop): (bool, &AtomicBool),
    after: &dyn Fn(usize),
) -> (usize, f64) {
    let start = Instant::now();
    let first = frames.first().map_or(0, |f| f.time_us);
    let mut offered = 0;
    for f in frames {
        let due = (!fast)
            .then(|| start + Duration::from_micros(u64::from(f.time_us.wrapping_sub(first))));
        if !wait_for(sender, due, stop) {
            break;
        }
        sender.offer(*f);
        offered += 1;
        after(offered);
    }
    (offered, start.elapsed().as_secs_f64())
}

/// Waits, in steps of at most 50 ms watching `stop`, until `due` or (none)
/// until the sender has written what it was given (at most an hour, or
/// until the port fails); false if `stop` was set.
fn wait_for(sender: &Sender, due: Option<Instant>, stop: &AtomicBool) -> bool {
    const STEP: Duration = Duration::from_millis(50);
    let give_up = Instant::now() + Duration::from_secs(3600);
    loop {
        if stop.load(Ordering::Relaxed) {
            return false;
        }
        match due {
            Some(due) => {
                let left = due.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    return true;
                }
                std::thread::sleep(left.min(STEP));
            }
            None => {
                if sender.drain(STEP) || sender.failed().is_some() || Instant::now() >= give_up {
                    return true;
                }
            }
        }
    }
}

/// Saves the take of a session with a board on a port (`source` names the
/// command): the region the host knows (the rig, and `tables` if given),
/// every message `written`, and the board's `replies`
/// ([`crate::take::Take::of_port`]).
pub fn save_port_take(
    (source, path): (&str, &Path),
    rig: &rigfile::RigFile,
    tables: &[PathBuf],
    written: &[perform::Sent],
    replies: &[Message],
) -> Result<(), CmdError> {
    let region = rigfile::region_of_files(rig, tables)?;
    crate::take::Take::of_port(source, &region, written, replies)?.save(path)?;
    Ok(())
}

/// Frames as a tracker recording.
#[must_use]
pub fn samples(frames: &[TrackerFrame]) -> Vec<TrackerSample> {
    frames
        .iter()
        .flat_map(|f| {
            f.sensors.as_slice().iter().map(|s| {
                let [w, x, y, z] = s.rotation.map(f64::from);
                TrackerSample {
                    time_us: u64::from(f.time_us),
                    sensor: s.id,
                    position: glam::Vec3::from(s.position).as_dvec3(),
                    orientation: glam::DQuat::from_xyzw(x, y, z, w),
                }
            })
        })
        .collect()
}

/// Writes the frames sent as a recording (every value exact).
pub fn write_sent(path: &Path, frames: &[TrackerFrame]) -> Result<(), CmdError> {
    let mut text = Vec::new();
    super::record::write_csv_exact(&mut text, &samples(frames))
        .map_err(|e| format!("{}: {e}", path.display()))?;
    crate::save::save(path, &text, &[])?;
    Ok(())
}

/// Streams the recording to the board and reports what happened; Ctrl-C
/// ends it early the same way (a second quits at once:
/// [`crate::interrupt`]).
pub fn run(args: &Args) -> Result<(), CmdError> {
    let stop = crate::interrupt::stop_on_ctrl_c("stream")?;
    let (summary, _) =
        stream(args, stop).inspect_err(|e| crate::refusal::print_json_stop(&**e, args.json))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary);
    }
    Ok(())
}

/// Streams the recording to the board until its end or until `stop` is
/// set (then the frames not yet offered are not sent; the session ends as
/// at the end); returns the summary and every message the board sent.
pub fn stream(args: &Args, stop: &AtomicBool) -> Result<(Summary, Vec<Message>), CmdError> {
    let rig = rigfile::load(&rigfile::resolve(&args.rig))?;
    let frames = perform::frames(&import::csv::read_tracker_csv(&args.recording)?)?;
    let port = serialport::new(&args.port, args.baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| format!("{}: {e}", args.port))?;
    let reader = port
        .try_clone()
        .map_err(|e| format!("{}: {e}", args.port))?;
    let replies = Replies::spawn(reader);
    let link = Link::Uart { baud: args.baud };
    let sender = Sender::spawn(port, link, args.frame);
    handshake(&sender, &replies, &args.port, Duration::from_secs(5), stop)?;
    arm(&sender, &replies, &args.port)?;
    let mut rig_blob = vec![0u8; marionette_core::rig::MAX_BLOB_LEN];
    let n = rig
        .desc()
        .to_blob(&mut rig_blob)
        .map_err(|e| format!("{}: {e:?}", args.rig.display()))?;
    rig_blob.truncate(n);
    let title = format!(
        "{}: {}",
        rig.name(),
        args.recording
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    );
    let (offered, seconds) =
        super::view::watched_board(&args.view, &rig_blob, &title, &frames, |hook| {
            Ok(schedule(&sender, &frames, (args.fast, stop), &|offered| {
                hook(offered, sender.counts().dropped, None, &|| {
                    replies.recent(4096)
                });
            }))
        })?;
    sender.drain(Duration::from_secs(2));
    sender.command(CommandKind::Disarm);
    let failed = sender.failed();
    sender.drain(Duration::from_secs(2));
    let written = sender.take_written();
    let (counts, sent) = sender.finish(Duration::from_secs(2));
    let disarm_acked = await_disarm(&replies, Duration::from_secs(20));
    let messages = replies.finish();
    if let Some(e) = failed {
        return Err(format!("{}: the port failed: {e}", args.port).into());
    }
    if let Some(path) = &args.take {
        save_port_take(("stream", path), &rig, &args.tables, &written, &messages)?;
    }
    let sent_csv = args.out.join("sent.csv");
    write_sent(&sent_csv, &sent)?;
    let mut summary = Summary {
        frames: frames.len(),
        link_bytes_per_s: counts.bytes as f64 / seconds.max(1e-9),
        link_capacity_bytes_per_s: link.bytes_per_second(),
        sender: counts,
        seconds,
        sent_csv: sent_csv.display().to_string(),
        disarm_acked,
        stopped: offered < frames.len(),
        ..Summary::default()
    };
    summarize(&messages, &mut summary, &args.out.join("telemetry.csv"))?;
    Ok((summary, messages))
}

fn print_summary(s: &Summary) {
    if s.stopped {
        println!(
            "stream: stopped by Ctrl-C after {} of {} frames",
            s.sender.offered, s.frames
        );
    }
    println!(
        "stream: {} of {} frames sent, {} dropped (newest wins) in {:.2} s; link {:.0} B/s of \
         {:.0} ({:.1} %)",
        s.sender.sent,
        s.frames,
        s.sender.dropped,
        s.seconds,
        s.link_bytes_per_s,
        s.link_capacity_bytes_per_s,
        100.0 * s.link_bytes_per_s / s.link_capacity_bytes_per_s.max(1.0)
    );
    println!(
        "board: {} status, {} acks ({} refused), {} telemetry; {} errors counted; state {}, \
         {} fail-safe trips",
        s.statuses,
        s.acks,
        s.refused,
        s.telemetry,
        s.errors,
        state_name(s.state),
        s.trips
    );
    if let Some(t) = s.timing {
        println!("board frame time: {}", timing_line(&t));
    }
    if !s.disarm_acked {
        println!("board: no Ack of Disarm within 20 s: its last replies may be missing");
    }
    print_show(s.show.as_ref());
    println!(
        "frames sent: {}; telemetry: {}",
        s.sent_csv, s.telemetry_csv
    );
}

/// The board's flashed show, for a summary line: a refused one on stderr,
/// in words with what to do.
pub fn print_show(show: Option<&ShowReport>) {
    match show {
        Some(r) if r.refused => {
            if let Some(line) = r.refusal_line() {
                eprintln!("board: {line}");
            }
        }
        Some(r) if r.state != ShowState::None => println!("board: flashed show {:?}", r.state),
        _ => {}
    }
}

/// The board's last reported state, for a summary line.
#[must_use]
pub fn state_name(state: Option<State>) -> String {
    state.map_or_else(|| "unknown".to_owned(), |s| format!("{s:?}"))
}

/// The board's frame timing in one line (its counter units).
#[must_use]
pub fn timing_line(t: &FrameTiming) -> String {
    let pct = |x: u32| 100.0 * f64::from(x) / f64::from(t.budget.max(1));
    if t.budget == 0 {
        format!(
            "mean {}, worst {} counts over {} frames (no cycle counter: no budget)",
            t.mean, t.worst, t.frames
        )
    } else {
        format!(
            "mean {} ({:.0} %), worst {} ({:.0} %) of a {}-count frame period; {} of {} frames \
             overran it",
            t.mean,
            pct(t.mean),
            t.worst,
            pct(t.worst),
            t.budget,
            t.overruns,
            t.frames
        )
    }
}
