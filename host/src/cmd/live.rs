//! `marionette live`: a performance from a live source.
//!
//! Listens for a VMC source (OSC over UDP: trackers and humanoid bones
//! become sensors) and plain OSC parameter addresses, mapped by the rig
//! file's `[live]` table (see [`crate::live`]), and forwards what it hears
//! to a board through the real-time sender of `marionette stream`
//! ([`crate::sender`]: newest wins on a slow link, nothing queues). The
//! board is the emulated one by default (the `perform` firmware on QEMU,
//! its tracker UART on a pseudo-terminal, the servo bus to
//! `out/live/servo_live.bin`) or a real one with `--port DEV`.
//!
//! **Who may drive the puppet.** It listens on `127.0.0.1:39539` by
//! default (this machine only). `--listen ADDR:PORT` opens it to a network;
//! `--allow IP,...` names the senders it accepts, and packets from anyone
//! else are counted and dropped, never read. It prints where it listens,
//! each new sender, each refused one, and when the source goes silent (the
//! board's fail-safe then eases the servos to rest) or comes back.
//!
//! **The view.** `--view` shows the performance in a web page as `stream
//! --view` does (the figure posed from the servo targets of the board's
//! telemetry, the goals of the newest frame offered). `--listen` being the
//! source's, the view's address is `--view-listen` (`127.0.0.1:8765` by
//! default: this machine only).
//!
//! **Ending it.** It runs until `--seconds` pass or Ctrl-C (SIGINT; SIGTERM
//! and SIGHUP too): the first says so on stderr and ends the session the
//! same way as `--seconds` (the board disarmed, the summary printed with
//! `stopped`, the end check run, the take saved); a second quits at once
//! with exit code 130 ([`crate::interrupt`], which also keeps the emulated
//! board out of the terminal's Ctrl-C and ends it on that quit).
//!
//! **The recording.** Every tracker frame actually sent is appended to
//! `out/live/live.csv` as it goes (flushed every 100 ms, so a session that
//! quits at once is kept up to then): `marionette sim --recording
//! out/live/live.csv` replays it. On the emulated board `live` checks that
//! itself at the end: the servo output against the core run on the
//! recording (following the fail-safe trips the board reported). `Params` from OSC faders are sent
//! but not part of the recording (a recording holds tracker samples only).

use super::CmdError;
use super::stream::{self, Replies};
use crate::import::csv::HEADER;
use crate::link::Link;
use crate::live::{Source, SourceCounts, VMC_PORT};
use crate::perform::{self, Framing};
use crate::qemu::{self, PtyBoard};
use crate::rigfile;
use crate::sender::Sender;
use marionette_core::wire::{CommandKind, Message, TrackerFrame};
use serde::Serialize;
use std::collections::BTreeSet;
use std::io::Write;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The emulated UART's pace: it takes about 20 kB/s (DESIGN §6), so the
/// sender treats it as a 200,000-baud link.
pub const EMULATED_BAUD: u32 = 200_000;

/// Arguments of `marionette live`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig file (docs/rig.md), with its `[live]` table, or a rig name:
    /// `rigs/<name>.toml` here, else a rig built in (humanoid16, cmu31).
    #[arg(long, default_value = "rigs/humanoid16.toml")]
    pub rig: PathBuf,
    /// The table blob for the emulated board (`marionette demo` writes
    /// `out/reach_humanoid16.bin`); a real board has its own in flash
    /// (given with `--port`, it is only kept in the take). Repeat it for a
    /// rig with `[[layer]]` tables: table 0, 1, … in order.
    #[arg(long)]
    pub tables: Vec<PathBuf>,
    /// A real board's tracker serial port (default: the emulated board).
    #[arg(long)]
    pub port: Option<String>,
    /// Baud rate of the tracker link (default 921,600 for `--port`; the
    /// emulated board is paced as 200,000).
    #[arg(long)]
    pub baud: Option<u32>,
    /// Where to listen for the source (UDP).
    #[arg(long, default_value_t = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), VMC_PORT))]
    pub listen: SocketAddr,
    /// The only senders accepted (IP addresses, comma-separated); default:
    /// anyone who can reach `--listen`.
    #[arg(long, value_delimiter = ',')]
    pub allow: Vec<IpAddr>,
    /// Say the source went silent after this long without a packet, ms.
    #[arg(long, default_value_t = 500)]
    pub silence_ms: u64,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// How tracker frames travel: the compact frame (quantized) or `f32`.
    #[arg(long, value_enum, default_value_t = Framing::Compact)]
    pub frame: Framing,
    /// Where to write `live.csv`, `telemetry.csv` (and, emulated,
    /// `region.bin`, `servo_live.bin`).
    #[arg(long, default_value = "out/live")]
    pub out: PathBuf,
    /// Also save the session as a take (docs/take.md). On the emulated
    /// board it holds the servo outputs; with `--port`, the servo targets
    /// the board's telemetry reported (its servo link is not seen), and the
    /// rig with `--tables` if given.
    #[arg(long)]
    pub take: Option<PathBuf>,
    /// Print the summary as JSON (and nothing else).
    #[arg(long)]
    pub json: bool,
    /// The live view (`--view`, `--view-listen`), from the board's
    /// telemetry.
    #[command(flatten)]
    pub view: super::view::LiveViewArgs,
}

/// The emulated board's output against the core on the recording.
#[derive(Debug, Default, Serialize)]
pub struct Checked {
    /// The raw servo-bus bytes (UART1).
    pub servo_bytes: String,
    /// The table-region image the board ran with.
    pub region: String,
    /// Output frames compared (up to the last frame-driven one).
    pub compared: usize,
    /// Those that differ from the core run on the recording.
    pub mismatches: usize,
    /// Fail-safe trips the board reported and the replay followed.
    pub failsafe_trips: usize,
}

/// What a live session did.
#[derive(Debug, Default, Serialize)]
pub struct Summary {
    /// Where it listened.
    pub listen: String,
    /// The senders accepted (empty: anyone).
    pub allow: Vec<String>,
    /// Senders heard, in order of first packet.
    pub senders: Vec<String>,
    /// Packets refused (sender not allowed).
    pub refused: u64,
    /// The addresses refused.
    pub refused_from: Vec<String>,
    /// What the source sent.
    pub source: SourceCounts,
    /// Times the source went silent.
    pub silences: u64,
    /// The link and the board (`frames` = tracker frames offered;
    /// `sent_csv` = the recording).
    pub board: stream::Summary,
    /// On the emulated board: its servo output against `sim`.
    pub emulated: Option<Checked>,
}

/// The bound UDP socket.
pub struct Listener {
    socket: UdpSocket,
}

impl Listener {
    /// Binds `addr` (port 0: any free port).
    pub fn bind(addr: SocketAddr) -> Result<Self, CmdError> {
        let socket = UdpSocket::bind(addr).map_err(|e| format!("listening on {addr}: {e}"))?;
        socket.set_read_timeout(Some(Duration::from_millis(20)))?;
        Ok(Self { socket })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> Result<SocketAddr, CmdError> {
        Ok(self.socket.local_addr()?)
    }
}

/// The board `live` forwards to.
enum Board {
    /// A real board on a serial port.
    Real,
    /// The emulated board, with its region and servo file.
    Emulated {
        board: PtyBoard,
        region: PathBuf,
        servo: PathBuf,
    },
}

/// Boots the emulated board (or names the real one's port): the port and
/// its pace.
fn board(args: &Args, rig: &rigfile::RigFile) -> Result<(Board, String, u32), CmdError> {
    if let Some(port) = &args.port {
        return Ok((Board::Real, port.clone(), args.baud.unwrap_or(921_600)));
    }
    if args.tables.is_empty() {
        return Err(
            "the emulated board needs a table blob: --tables out/reach_humanoid16.bin \
                    (written by `marionette demo`), or a real board: --port DEV"
                .into(),
        );
    }
    std::fs::create_dir_all(&args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    let region = args.out.join("region.bin");
    let image = rigfile::region_of_files(rig, &args.tables)?;
    crate::save::save(&region, &image, &[])?;
    let servo = args.out.join("servo_live.bin");
    let elf = qemu::firmware_elf("perform")?;
    let board = PtyBoard::start(&elf, &region, &servo)?;
    let port = board.pty().display().to_string();
    let baud = args.baud.unwrap_or(EMULATED_BAUD);
    Ok((
        Board::Emulated {
            board,
            region,
            servo,
        },
        port,
        baud,
    ))
}

/// The recording, written as it goes.
struct Recording {
    path: PathBuf,
    file: std::io::BufWriter<std::fs::File>,
    frames: usize,
}

impl Recording {
    fn create(path: &Path) -> Result<Self, CmdError> {
        let f = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut file = std::io::BufWriter::new(f);
        writeln!(file, "{}", HEADER.join(","))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            frames: 0,
        })
    }

    fn append(&mut self, frames: &[TrackerFrame]) -> Result<(), CmdError> {
        super::record::write_rows_exact(&mut self.file, &stream::samples(frames))
            .map_err(|e| format!("{}: {e}", self.path.display()))?;
        self.frames += frames.len();
        Ok(())
    }
}

/// Who is sending, who is refused, and whether the source is silent.
struct Senders {
    allow: Vec<IpAddr>,
    seen: Vec<SocketAddr>,
    refused: u64,
    refused_from: BTreeSet<IpAddr>,
    last: Option<Instant>,
    silent: bool,
    silences: u64,
    quiet: bool,
}

impl Senders {
    /// Whether a packet from `from` is read (prints new senders).
    fn accept(&mut self, from: SocketAddr) -> bool {
        if !self.allow.is_empty() && !self.allow.contains(&from.ip()) {
            self.refused += 1;
            if self.refused_from.insert(from.ip()) && !self.quiet {
                println!("live: refused {from}: not in --allow (counted and dropped)");
            }
            return false;
        }
        if !self.seen.contains(&from) {
            self.seen.push(from);
            if !self.quiet {
                println!("live: {from} is sending");
            }
        }
        if self.silent && !self.quiet {
            println!("live: the source is back ({from})");
        }
        self.silent = false;
        self.last = Some(Instant::now());
        true
    }

    /// Notices a source gone silent for `after`.
    fn check_silence(&mut self, after: Duration) {
        if !self.silent && self.last.is_some_and(|t| t.elapsed() >= after) {
            self.silent = true;
            self.silences += 1;
            if !self.quiet {
                println!(
                    "live: the source is silent ({:.1} s): the board eases the servos to rest \
                     (its fail-safe) until it comes back",
                    after.as_secs_f64()
                );
            }
        }
    }
}

/// Runs `marionette live` until Ctrl-C or `--seconds` (a second Ctrl-C
/// quits at once: [`crate::interrupt`]).
pub fn run(args: &Args) -> Result<(), CmdError> {
    let listener = Listener::bind(args.listen)?;
    let stop = crate::interrupt::stop_on_ctrl_c("live")?;
    let (summary, _) = live(args, &listener, stop)
        .inspect_err(|e| crate::refusal::print_json_stop(&**e, args.json))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary);
    }
    match &summary.emulated {
        Some(c) if c.mismatches > 0 => {
            Err("the emulated board's servo output differs from sim on the recording".into())
        }
        _ => Ok(()),
    }
}

/// A live session on `listener` until `stop` is set or `--seconds` pass;
/// returns the summary and every message the board sent.
pub fn live(
    args: &Args,
    listener: &Listener,
    stop: &AtomicBool,
) -> Result<(Summary, Vec<Message>), CmdError> {
    let rig = rigfile::load(&rigfile::resolve(&args.rig))?;
    if rig.live.sensors.is_empty() && rig.live.params.is_empty() {
        return Err(format!(
            "{}: no [live] table: map the source's names to sensors ([[live.sensor]]) or OSC \
             addresses to parameters ([[live.param]]); see rigs/humanoid16.toml",
            rig.file
        )
        .into());
    }
    let quiet = args.json;
    let listen = listener.local_addr()?;
    let (mut board, port, baud) = board(args, &rig)?;
    let serial = serialport::new(&port, baud)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| format!("{port}: {e}"))?;
    let replies = Replies::spawn(serial.try_clone().map_err(|e| format!("{port}: {e}"))?);
    let link = Link::Uart { baud };
    let sender = Sender::spawn(serial, link, args.frame);
    stream::handshake(&sender, &replies, &port, Duration::from_secs(10), stop)?;
    stream::arm(&sender, &replies, &port)?;
    std::fs::create_dir_all(&args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    let mut recording = Recording::create(&args.out.join("live.csv"))?;
    if !quiet {
        let who = if args.allow.is_empty() {
            "from anyone who can reach it".to_owned()
        } else {
            let ips: Vec<String> = args.allow.iter().map(IpAddr::to_string).collect();
            format!("from {} only", ips.join(", "))
        };
        println!("live: listening on udp://{listen} (VMC / OSC) {who}");
        let to = match &board {
            Board::Real => format!("the board on {port}"),
            Board::Emulated { .. } => format!("the emulated board (tracker link {port})"),
        };
        println!(
            "live: forwarding to {to} at {baud} baud; recording to {}",
            recording.path.display()
        );
    }
    let mut senders = Senders {
        allow: args.allow.clone(),
        seen: Vec::new(),
        refused: 0,
        refused_from: BTreeSet::new(),
        last: None,
        silent: false,
        silences: 0,
        quiet,
    };
    let mut source = Source::new(rig.live.clone());
    let title = format!("{}: live from udp://{listen}", rig.name());
    let view = super::view::ViewArgs::from(&args.view);
    let rig_blob = rigfile::to_blob(&rig)?;
    let (offered, seconds) = super::view::watched_board(&view, &rig_blob, &title, &[], |hook| {
        listen_loop(
            args,
            (listener, stop),
            (&mut senders, &mut source),
            &sender,
            &mut recording,
            &|offered, newest| {
                hook(offered, sender.counts().dropped, newest, &|| {
                    replies.recent(4096)
                });
            },
        )
    })?;
    sender.drain(Duration::from_secs(2));
    sender.command(CommandKind::Disarm);
    let failed = sender.failed();
    sender.drain(Duration::from_secs(2));
    let written = sender.take_written();
    let (counts, rest) = sender.finish(Duration::from_secs(2));
    recording.append(&rest)?;
    recording.file.flush()?;
    let disarm_acked = stream::await_disarm(&replies, Duration::from_secs(20));
    let messages = replies.finish();
    if let Some(e) = failed {
        return Err(format!("{port}: the port failed: {e}").into());
    }
    let mut board_summary = stream::Summary {
        frames: offered,
        link_bytes_per_s: counts.bytes as f64 / seconds.max(1e-9),
        link_capacity_bytes_per_s: link.bytes_per_second(),
        sender: counts,
        seconds,
        sent_csv: recording.path.display().to_string(),
        disarm_acked,
        stopped: stop.load(Ordering::Relaxed),
        ..stream::Summary::default()
    };
    stream::summarize(
        &messages,
        &mut board_summary,
        &args.out.join("telemetry.csv"),
    )?;
    let emulated = match &mut board {
        Board::Real => {
            if let Some(path) = &args.take {
                stream::save_port_take(("live", path), &rig, &args.tables, &written, &messages)?;
            }
            None
        }
        Board::Emulated {
            board,
            region,
            servo,
        } => Some(check(
            board,
            (region, servo),
            &recording.path,
            args.frame,
            (&messages, args.take.as_deref()),
        )?),
    };
    let summary = Summary {
        listen: listen.to_string(),
        allow: args.allow.iter().map(IpAddr::to_string).collect(),
        senders: senders.seen.iter().map(SocketAddr::to_string).collect(),
        refused: senders.refused,
        refused_from: senders.refused_from.iter().map(IpAddr::to_string).collect(),
        source: source.counts.clone(),
        silences: senders.silences,
        board: board_summary,
        emulated,
    };
    Ok((summary, messages))
}

/// Reads packets until stopped, offering frames and parameters and telling
/// `progress` (the view) the frames offered so far and the newest, after
/// every packet or read time-out; returns the tracker frames offered and
/// the seconds it ran.
fn listen_loop(
    args: &Args,
    (listener, stop): (&Listener, &AtomicBool),
    (senders, source): (&mut Senders, &mut Source),
    sender: &Sender,
    recording: &mut Recording,
    progress: &dyn Fn(usize, Option<&TrackerFrame>),
) -> Result<(usize, f64), CmdError> {
    let start = Instant::now();
    let end = args
        .seconds
        .map(|s| start + Duration::from_secs_f64(s.max(0.0)));
    let silence = Duration::from_millis(args.silence_ms);
    let mut buf = vec![0u8; 65_536];
    let mut offered = 0;
    let mut newest = None;
    let mut flushed = Instant::now();
    while !stop.load(Ordering::Relaxed) && end.is_none_or(|e| Instant::now() < e) {
        match listener.socket.recv_from(&mut buf) {
            Ok((n, from)) => {
                if senders.accept(from) {
                    let heard = source.packet(buf.get(..n).unwrap_or(&[]));
                    if heard.params {
                        sender.offer_params(source.params());
                    }
                    let sensors = source.sensors();
                    if heard.sensors && !sensors.as_slice().is_empty() {
                        let time_us =
                            u32::try_from(start.elapsed().as_micros()).unwrap_or(u32::MAX);
                        let frame = TrackerFrame {
                            seq: 0,
                            time_us,
                            sensors,
                        };
                        sender.offer(frame);
                        newest = Some(frame);
                        offered += 1;
                    }
                }
            }
            // Interrupted: a signal (Ctrl-C sets `stop`) arrived during the read.
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) => {}
            Err(e) => return Err(format!("reading udp: {e}").into()),
        }
        senders.check_silence(silence);
        progress(offered, newest.as_ref());
        if flushed.elapsed() >= Duration::from_millis(100) {
            recording.append(&sender.take_sent())?;
            recording.file.flush()?;
            flushed = Instant::now();
            if let Some(e) = sender.failed() {
                return Err(format!("the tracker link failed: {e}").into());
            }
        }
    }
    Ok((offered, start.elapsed().as_secs_f64()))
}

/// How long the emulated board may take to end its session after the
/// Disarm (it eases every servo to rest first).
const END_WAIT: Duration = Duration::from_secs(30);

/// Waits for the emulated board to stop and compares its servo output with
/// the core run on the recording; an error if it does not stop within
/// [`END_WAIT`].
fn check(
    board: &mut PtyBoard,
    (region, servo): (&Path, &Path),
    recording: &Path,
    framing: Framing,
    (replies, take): (&[Message], Option<&Path>),
) -> Result<Checked, CmdError> {
    // The board ends its session by itself once disarmed and at rest; one
    // that has not within the wait has not sent all its servo output, and
    // comparing part of it would report differences that are not there.
    if board.wait(END_WAIT)?.is_none() {
        return Err(format!(
            "the emulated board did not end its session within {} s of the Disarm: its servo \
             output ({}) was not compared with the native core",
            END_WAIT.as_secs(),
            servo.display()
        )
        .into());
    }
    let region_bytes = std::fs::read(region).map_err(|e| format!("{}: {e}", region.display()))?;
    let frames = perform::frames(&crate::import::csv::read_tracker_csv(recording)?)?;
    let session = perform::session_with(&frames, framing)?;
    let native = perform::simulate(&region_bytes, &session)?;
    let channels = native.frame_targets.first().map_or(1, Vec::len);
    let format = perform::ServoFormat::of_region(&region_bytes, channels)
        .unwrap_or(perform::ServoFormat::Maestro { channels });
    let bytes = std::fs::read(servo).map_err(|e| format!("{}: {e}", servo.display()))?;
    let outputs = format.decode(&bytes);
    let followed = perform::follow(&region_bytes, &session, &outputs, replies)?;
    if let Some(path) = take {
        let mut frame_targets = outputs.clone();
        let rest_targets = frame_targets.split_off(frames.len().min(frame_targets.len()));
        let run = perform::Run {
            frame_targets,
            rest_targets,
            replies: replies.to_vec(),
            ..perform::Run::default()
        };
        crate::take::Take::of_run("live", &region_bytes, &session, &run)?.save(path)?;
    }
    Ok(Checked {
        servo_bytes: servo.display().to_string(),
        region: region.display().to_string(),
        compared: followed.compared,
        mismatches: followed.mismatches,
        failsafe_trips: followed.trips.len(),
    })
}

fn print_summary(s: &Summary) {
    let c = &s.source;
    if s.board.stopped {
        println!("live: stopped by Ctrl-C after {:.1} s", s.board.seconds);
    }
    println!(
        "live: {} packets from {} sender(s) ({} malformed, {} refused); {} messages used, {} not \
         mapped; silent {} time(s)",
        c.packets,
        s.senders.len(),
        c.malformed,
        s.refused,
        c.used,
        c.unused,
        s.silences
    );
    let b = &s.board;
    println!(
        "link: {} of {} frames sent, {} dropped (newest wins), {} Params; {:.0} B/s of {:.0} ({:.1} %)",
        b.sender.sent,
        b.frames,
        b.sender.dropped,
        b.sender.params_sent,
        b.link_bytes_per_s,
        b.link_capacity_bytes_per_s,
        100.0 * b.link_bytes_per_s / b.link_capacity_bytes_per_s.max(1.0)
    );
    println!(
        "board: {} telemetry, {} errors counted, state {}, {} fail-safe trips",
        b.telemetry,
        b.errors,
        stream::state_name(b.state),
        b.trips
    );
    if let Some(t) = b.timing {
        println!("board frame time: {}", stream::timing_line(&t));
    }
    if !b.disarm_acked {
        println!("board: no Ack of Disarm within 20 s: its last replies may be missing");
    }
    stream::print_show(b.show.as_ref());
    if let Some(e) = &s.emulated {
        println!(
            "emulated board: {} servo outputs compared with sim on {}: {} differ ({} fail-safe \
             trips followed)",
            e.compared, b.sent_csv, e.mismatches, e.failsafe_trips
        );
    }
    println!(
        "recording: {} (marionette sim --recording {})",
        b.sent_csv, b.sent_csv
    );
}
