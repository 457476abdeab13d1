//! Fuzz target bodies, shared by the cargo-fuzz project in `tests/fuzz/`
//! (libFuzzer, nightly only) and the stable replay test
//! `tests/fuzz_replay.rs`, which runs every committed corpus file through the
//! same functions in `cargo test`.
//!
//! Every target takes arbitrary bytes and must never panic, hang or abort.
//! Where a property is meaningful it is asserted (a failed assertion is a
//! crash to the fuzzer): accepted tracker frames hold finite, in-range values;
//! messages re-encode identically; decoded table samples are unit rotations;
//! a rig file the host accepts gives a blob the core accepts; host parser
//! errors name the file; servo targets stay within their calibrated pulse
//! range and move at most one speed-limit step per output; the fail-safe
//! reaches rest.
//!
//! Inputs that carry a CRC can be "fixed up" by the harness, so that mutations
//! reach the decoders behind the CRC (selected by a leading mode byte, see
//! each target). Each target returns an [`Outcome`](crate::fuzz_targets::Outcome) so the replay can check
//! that the corpora reach the accepting paths, not just the rejections.

use glam::{Quat, Vec3};
use marionette_core::body::Angles;
use marionette_core::crc::crc32;
use marionette_core::frame::{NoCycles, Performer, Region, Update};
use marionette_core::goal::{GoalSet, Target as GoalTarget};
use marionette_core::grid::GridError;
use marionette_core::perform::JOG_TIMEOUT_US;
use marionette_core::pose::Pose;
use marionette_core::rig::Rig;
use marionette_core::servo::quarter_us;
use marionette_core::solve::{self, Solver, SolverState};
use marionette_core::table::{self, Interp, Kind, Table, Wrap};
use marionette_core::wire::{
    self, Ack, Command, CommandKind, Direction, ErrorCounters, FRAME_CAPACITY, FrameReader, Hello,
    Incoming, List, MAX_FRAME, MAX_SENSORS, Message, PROTOCOL_VERSION, Params, Receiver, Sensor,
    Status, StatusReason, Telemetry, TrackerFrame,
};
use marionette_core::wire::{FrameTiming, State, Trip};
use marionette_host::blob::{self, AxisSpec, TableSpec};
use marionette_host::import::{EndSites, Motion, amc, bvh};
use marionette_host::rigfile;
use std::sync::OnceLock;

/// Whether an input reached the accepting path of its target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Decoded, parsed or driven through the whole path.
    Accepted,
    /// Refused with a typed error (as it should be for most inputs).
    Rejected,
}

impl Outcome {
    fn of(ok: bool) -> Self {
        if ok { Self::Accepted } else { Self::Rejected }
    }
}

/// One fuzz target: its cargo-fuzz name (also its corpus folder) and body.
#[derive(Clone, Copy)]
pub struct Target {
    /// The target's name: `tests/fuzz/fuzz_targets/<name>.rs`,
    /// `tests/fuzz/corpus/<name>/`.
    pub name: &'static str,
    /// The body.
    pub run: fn(&[u8]) -> Outcome,
}

/// Every target.
pub const TARGETS: [Target; 8] = [
    Target {
        name: "wire",
        run: wire,
    },
    Target {
        name: "table_blob",
        run: table_blob,
    },
    Target {
        name: "rig_blob",
        run: rig_blob,
    },
    Target {
        name: "rig_toml",
        run: rig_toml,
    },
    Target {
        name: "bvh",
        run: bvh_text,
    },
    Target {
        name: "amc",
        run: amc_text,
    },
    Target {
        name: "sensor_map",
        run: sensor_map,
    },
    Target {
        name: "performer",
        run: performer,
    },
];

// ------------------------------------------------------------------ shared

/// The shipped humanoid16 rig file.
pub const HUMANOID16_TOML: &str = include_str!("../rigs/humanoid16.toml");
/// The shipped cmu31 rig file.
pub const CMU31_TOML: &str = include_str!("../rigs/cmu31.toml");
/// The HDM05 skeleton, base of the AMC target's AMC-only inputs.
const HDM05_ASF: &[u8] = include_bytes!("../data/hdm05_bk/HDM_bk.asf");

fn humanoid16() -> &'static rigfile::RigFile {
    static RIG: OnceLock<rigfile::RigFile> = OnceLock::new();
    RIG.get_or_init(|| {
        rigfile::parse(HUMANOID16_TOML, "humanoid16.toml").expect("the shipped rig parses")
    })
}

/// The humanoid16 rig blob.
pub fn humanoid16_blob() -> &'static [u8] {
    static BLOB: OnceLock<Vec<u8>> = OnceLock::new();
    BLOB.get_or_init(|| rigfile::to_blob(humanoid16()).expect("the shipped rig has a blob"))
}

fn humanoid16_rig() -> &'static Rig<'static> {
    static RIG: OnceLock<Rig<'static>> = OnceLock::new();
    RIG.get_or_init(|| {
        Rig::parse(humanoid16_blob())
            .expect("the shipped rig blob is valid")
            .0
    })
}

/// A small grid table for humanoid16: 2×2×2 samples over the three hand
/// parameters, each sample the rest pose with every segment turned by a
/// sample-dependent angle about Y (so interpolation has work to do).
pub fn humanoid16_table() -> Vec<u8> {
    let rig = humanoid16();
    let core = humanoid16_rig();
    let rest = core.rest_pose();
    let n = rig.segment_names().len();
    let samples = (0..8u8)
        .map(|k| {
            let turn = Quat::from_rotation_y(0.05 * f32::from(k) - 0.2);
            (0..n)
                .map(|i| (rest.positions[i], turn * rest.rotations[i]))
                .collect()
        })
        .collect();
    let axis = |name: &str| AxisSpec {
        name: name.into(),
        min: -0.5,
        step: 1.0,
        count: 2,
        wrap: Wrap::Bounded,
        interp: Interp::Linear,
    };
    let spec = TableSpec {
        rig_hash: rig.rig_hash(),
        kind: Kind::Grid,
        axes: vec![axis("hand_x"), axis("hand_y"), axis("hand_z")],
        segment_names: rig.segment_names().to_vec(),
        samples,
        valid: vec![true],
        durations: vec![],
        travel: vec![],
    };
    blob::write(&spec).expect("the test table is valid")
}

/// A small clip table (two clips of three phases-axis samples, one cyclic
/// Catmull-Rom parameter axis), for the table target's seeds.
pub fn clip_table() -> Vec<u8> {
    let pose = |k: u8| {
        let a = 0.3 * f32::from(k);
        vec![
            (Vec3::new(0.0, 1.0, 0.1 * a), Quat::from_rotation_x(a)),
            (Vec3::new(0.2, 1.4, 0.0), Quat::from_rotation_z(-a)),
        ]
    };
    let spec = TableSpec {
        rig_hash: 7,
        kind: Kind::Clips { phases: 1 },
        axes: vec![
            AxisSpec {
                name: "speed".into(),
                min: 0.0,
                step: 0.5,
                count: 4,
                wrap: Wrap::Cyclic { period: 2.0 },
                interp: Interp::CatmullRom,
            },
            AxisSpec {
                name: "phase".into(),
                min: 0.0,
                step: 0.5,
                count: 3,
                wrap: Wrap::Bounded,
                interp: Interp::Linear,
            },
        ],
        segment_names: vec!["hips".into(), "hand".into()],
        samples: (0..12).map(pose).collect(),
        valid: vec![true, false, true, true],
        durations: vec![1.0, 1.1, 1.2, 1.3],
        travel: vec![],
    };
    blob::write(&spec).expect("the clip table is valid")
}

/// The performer target's table region: humanoid16 rig + its small table.
pub fn humanoid16_region() -> &'static [u8] {
    static REGION: OnceLock<Vec<u8>> = OnceLock::new();
    REGION.get_or_init(|| {
        marionette_host::perform::region(humanoid16_blob(), Some(&humanoid16_table()))
    })
}

/// Reads little-endian fields off the front of the fuzz input.
struct Cursor<'a>(&'a [u8]);

impl<'a> Cursor<'a> {
    fn u8(&mut self) -> Option<u8> {
        let (&b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(b)
    }

    fn array<const K: usize>(&mut self) -> Option<[u8; K]> {
        let (b, rest) = self.0.split_first_chunk::<K>()?;
        self.0 = rest;
        Some(*b)
    }

    fn u16(&mut self) -> Option<u16> {
        self.array().map(u16::from_le_bytes)
    }

    fn u32(&mut self) -> Option<u32> {
        self.array().map(u32::from_le_bytes)
    }

    fn f32(&mut self) -> Option<f32> {
        self.array().map(f32::from_le_bytes)
    }

    /// Up to `n` bytes (fewer at the end of the input).
    fn take(&mut self, n: usize) -> &'a [u8] {
        let (b, rest) = self.0.split_at(n.min(self.0.len()));
        self.0 = rest;
        b
    }

    fn sensor(&mut self) -> Option<Sensor> {
        Some(Sensor {
            id: self.u8()?,
            position: [self.f32()?, self.f32()?, self.f32()?],
            rotation: [self.f32()?, self.f32()?, self.f32()?, self.f32()?],
        })
    }
}

/// `| |q| − 1 |` is small and every component finite.
fn unit(q: Quat, tol: f32) -> bool {
    q.is_finite() && (q.dot(q) - 1.0).abs() <= tol
}

// -------------------------------------------------------------------- wire

/// The wire decoder: the whole input through a board [`Receiver`]
/// (`push_slice`: COBS, CRC, postcard, direction, version, sequence,
/// validation), through [`wire::decode_frame`] as one decoded frame, and as a
/// bare payload with its CRC appended by the harness (so postcard sees every
/// mutation). Accepted messages must hold their validated invariants and
/// re-encode to a frame that decodes to the same bytes.
pub fn wire(data: &[u8]) -> Outcome {
    let mut ok = false;
    let mut rx = Receiver::<FRAME_CAPACITY>::new();
    let mut input = data;
    let mut accepted = 0u32;
    while let Some(incoming) = rx.push_slice(&mut input) {
        check_incoming(&incoming, rx.frame());
        if !matches!(
            incoming,
            Incoming::Hello {
                accepted: false,
                ..
            }
        ) {
            accepted += 1;
        }
        ok = true;
    }
    assert!(input.is_empty(), "push_slice stopped before the end");
    assert_eq!(
        rx.frames_ok(),
        accepted,
        "frames_ok counts accepted messages"
    );
    if let Ok(msg) = wire::decode_frame(data) {
        round_trip(&msg);
        ok = true;
    }
    let mut framed = data.to_vec();
    framed.extend_from_slice(&crc32(data).to_le_bytes());
    match (wire::decode_frame(&framed), wire::decode_payload(data)) {
        (Ok(a), Ok(b)) => {
            assert_eq!(encoded(&a), encoded(&b), "decode_frame vs decode_payload");
            round_trip(&a);
            ok = true;
        }
        (Err(_), Err(_)) => {}
        (a, b) => panic!("decode_frame {a:?} but decode_payload {b:?}"),
    }
    Outcome::of(ok)
}

/// The validated invariants of an accepted host message.
fn check_incoming(incoming: &Incoming, frame: &marionette_core::wire::ValidTrackerFrame) {
    match incoming {
        Incoming::Hello {
            host_version,
            accepted,
        } => assert_eq!(
            *accepted,
            (wire::MIN_PROTOCOL_VERSION..=PROTOCOL_VERSION).contains(host_version)
        ),
        Incoming::Tracker => {
            let mut seen = 0u32;
            for s in frame.sensors() {
                assert!(usize::from(s.id()) < MAX_SENSORS, "sensor id {}", s.id());
                assert!(seen & (1 << s.id()) == 0, "repeated sensor id {}", s.id());
                seen |= 1 << s.id();
                let p = s.position();
                assert!(p.is_finite() && p.dot(p) <= 100.0 * 100.0, "position {p}");
                assert!(unit(s.rotation(), 1e-5), "rotation {}", s.rotation());
            }
        }
        Incoming::Params(p) => {
            assert!(p.values().len() <= wire::MAX_PARAMS);
            for v in p.values() {
                assert!(v.is_finite() && v.abs() <= wire::PARAM_LIMIT, "param {v}");
            }
        }
        Incoming::Command(c) => match c.kind() {
            CommandKind::SetGoalWeight { goal, weight } => {
                assert!(usize::from(goal) < wire::MAX_GOALS);
                assert!(
                    (0.0..=wire::WEIGHT_LIMIT).contains(&weight),
                    "weight {weight}"
                );
            }
            CommandKind::Boresight { sensor } => assert!(usize::from(sensor) < MAX_SENSORS),
            _ => {}
        },
    }
}

/// The frame bytes of a message (every decodable message fits a frame).
fn encoded(msg: &Message) -> Vec<u8> {
    let mut out = [0u8; MAX_FRAME];
    match wire::encode(msg, &mut out) {
        Ok(frame) => frame.to_vec(),
        Err(e) => panic!("a decoded message does not re-encode: {e:?} {msg:?}"),
    }
}

/// Encode → frame reader → decode → encode gives the same bytes.
fn round_trip(msg: &Message) {
    let first = encoded(msg);
    assert!(first.len() <= MAX_FRAME);
    let (last, body) = first.split_last().expect("a frame is never empty");
    assert_eq!(*last, 0, "a frame ends with its delimiter");
    assert!(!body.contains(&0), "COBS leaves no zero inside the frame");
    let mut reader = FrameReader::<FRAME_CAPACITY>::new();
    let mut errors = ErrorCounters::new();
    let mut input = first.as_slice();
    let frame = reader
        .push_slice(&mut input, &mut errors)
        .expect("an encoded frame is read back");
    let again = wire::decode_frame(frame).expect("an encoded frame decodes");
    assert_eq!(encoded(&again), first, "re-encoding changed the frame");
}

// ------------------------------------------------------------------- table

/// Writes the CRC of a table blob at `total_len − 4`, `total_len` read from
/// the header's first field (a varint after the 10-byte prefix).
fn fix_table_crc(blob: &mut [u8]) {
    let mut total: u64 = 0;
    for (i, &b) in blob.iter().skip(table::PREFIX_LEN).take(5).enumerate() {
        total |= u64::from(b & 0x7F) << (7 * i);
        if b & 0x80 == 0 {
            break;
        }
    }
    let Ok(total) = usize::try_from(total) else {
        return;
    };
    if total < table::PREFIX_LEN + table::CRC_LEN || total > blob.len() {
        return;
    }
    let crc = crc32(&blob[..total - 4]);
    blob[total - 4..total].copy_from_slice(&crc.to_le_bytes());
}

/// The table-blob validator and reader. Byte 0 is the mode: bit 0 set = the
/// harness fixes the CRC first. A blob that parses is read completely: every
/// segment name, every sample of every segment (unit rotations; finite
/// positions when the scale allows), every cell flag and duration, and
/// grid synthesis at a few parameter sets (a finite, normalized pose, or a
/// typed error).
pub fn table_blob(data: &[u8]) -> Outcome {
    let Some((&mode, rest)) = data.split_first() else {
        return Outcome::Rejected;
    };
    let mut blob = rest.to_vec();
    if mode & 1 == 1 {
        fix_table_crc(&mut blob);
    }
    let Ok(t) = Table::parse(&blob) else {
        return Outcome::Rejected;
    };
    read_table(&t);
    Outcome::Accepted
}

fn read_table(t: &Table<'_>) {
    let segments = t.segment_count();
    assert!((1..=table::MAX_SEGMENTS).contains(&segments));
    for s in 0..segments {
        let _ = t.segment_name(s);
    }
    assert!(t.segment_name(segments).is_none());
    let finite_positions = (t.position_scale() * 32768.0).is_finite();
    for i in 0..t.grid_samples() {
        for s in 0..segments {
            let (p, q) = t.sample(i, s).expect("every sample of the shape is stored");
            assert!(unit(q, 1e-5), "sample {i} segment {s}: rotation {q}");
            assert!(
                !finite_positions || p.is_finite(),
                "sample {i}: position {p}"
            );
        }
    }
    assert!(t.sample(t.grid_samples(), 0).is_none());
    assert!(t.sample(0, segments).is_none());
    for c in 0..t.param_cells() {
        assert!(t.cell_valid(c).is_some());
    }
    assert!(t.cell_valid(t.param_cells()).is_none());
    if let Kind::Clips { phases } = t.kind() {
        for i in 0..t.param_samples() {
            for p in 0..usize::from(phases) {
                assert!(t.duration(i, p).is_some(), "clip {i} phase {p}");
            }
        }
    }
    if let Ok(grid) = t.grid() {
        assert_eq!(grid.sample_count(), t.grid_samples());
        synth_queries(t, &grid, finite_positions);
    }
    let _ = t.param_grid();
}

/// Grid synthesis on a parsed table at the axis minima, midpoints, far
/// outside, and NaN.
fn synth_queries(t: &Table<'_>, grid: &marionette_core::grid::Grid<'_>, finite: bool) {
    let axes = grid.axes();
    let probes: [fn(&marionette_core::grid::Axis) -> f32; 4] = [
        |a| a.min,
        |a| a.min + a.step * (a.count as f32) * 0.37,
        |a| a.min - 1e30,
        |_| f32::NAN,
    ];
    let mut pose = Box::new(Pose::<{ table::MAX_SEGMENTS }>::default());
    for probe in probes {
        let params: Vec<f32> = axes.iter().map(probe).collect();
        match grid.query(&params) {
            Ok(q) => {
                assert!(params.iter().all(|p| p.is_finite()), "NaN params accepted");
                q.pose(t, &mut *pose)
                    .expect("a table holds every sample its grid needs");
                for (p, r) in pose.positions().iter().zip(pose.rotations()) {
                    assert!(unit(*r, 1e-3), "synthesized rotation {r}");
                    assert!(!finite || p.is_finite(), "synthesized position {p}");
                }
            }
            Err(GridError::NonFinite { .. }) => {
                assert!(params.iter().any(|p| !p.is_finite()));
            }
            Err(GridError::NoValidCell) => {
                assert!((0..grid.cell_count()).all(|c| !grid.cell_valid(c)));
            }
            Err(e) => panic!("query refused finite params: {e:?}"),
        }
    }
}

// --------------------------------------------------------------------- rig

/// Writes a rig blob's CRC (`u32` LE header length at 6..10, the
/// description, then the CRC of everything before it).
fn fix_rig_crc(blob: &mut [u8]) {
    let Some(len) = blob.get(6..10) else {
        return;
    };
    let len = u32::from_le_bytes(len.try_into().expect("4 bytes")) as usize;
    let Some(end) = len.checked_add(10) else {
        return;
    };
    if end + 4 > blob.len() {
        return;
    }
    let crc = crc32(&blob[..end]);
    blob[end..end + 4].copy_from_slice(&crc.to_le_bytes());
}

/// The rig blob (`Rig::parse`). Byte 0 is the mode: bit 0 set = the harness
/// fixes the CRC first. A rig that parses must validate, map sensors to
/// finite parameters and the right number of goals, keep every calibrated
/// pulse in range, and run a performer (no table: it must refuse to arm and
/// stay at rest).
pub fn rig_blob(data: &[u8]) -> Outcome {
    let Some((&mode, rest)) = data.split_first() else {
        return Outcome::Rejected;
    };
    let mut blob = rest.to_vec();
    if mode & 1 == 1 {
        fix_rig_crc(&mut blob);
    }
    let Ok((rig, _)) = Rig::parse(&blob) else {
        return Outcome::Rejected;
    };
    assert_eq!(rig.body().validate(), Ok(()), "a parsed rig validates");
    let _ = rig.rest_angles::<{ marionette_core::pose::MAX_SEGMENTS }>();
    check_mapping(&rig, &canned_sensors());
    check_mapping(&rig, &[]);
    for servo in rig.servos() {
        let cal = servo.calibration();
        for a in [
            f32::NAN,
            f32::INFINITY,
            -1e30,
            0.0,
            cal.angle_min,
            cal.angle_max,
        ] {
            let p = cal.pulse_us(a);
            assert!(
                p >= cal.pulse_low() && p <= cal.pulse_high(),
                "pulse {p} for {a}"
            );
        }
    }
    let region = Region {
        rig: Some(rig.clone()),
        table: None,
        reason: StatusReason::NoTable,
        ..Region::EMPTY
    };
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    assert!(p.pipeline().is_some(), "a valid rig gives a pipeline");
    let mut run = Run::new(&p, &rig);
    run.feed(&mut p, &encode(&Message::Command(arm(1))));
    assert!(!p.armed(), "a board without a table never arms");
    run.finish(&mut p);
    Outcome::Accepted
}

/// Three sensors where humanoid16's performer would hold them.
fn canned_sensors() -> Vec<Sensor> {
    let at = |id, position| Sensor {
        id,
        position,
        rotation: [1.0, 0.0, 0.0, 0.0],
    };
    vec![
        at(0, [-0.3, 1.2, 0.3]),
        at(1, [0.3, 0.9, 0.1]),
        at(2, [0.0, 1.0, 0.0]),
    ]
}

/// `map_sensors` gives finite parameters and the rig's goals, every active
/// goal with a finite target.
fn check_mapping(rig: &Rig<'_>, sensors: &[Sensor]) -> GoalSet<16> {
    let mut params = [0.0f32; marionette_core::rig::MAX_PARAMS];
    let mut goals = GoalSet::<16>::new();
    rig.map_sensors(sensors, &mut params, &mut goals);
    assert!(params.iter().all(|v| v.is_finite()), "params {params:?}");
    assert_eq!(goals.len(), rig.goal_count().min(16));
    for g in goals.as_slice() {
        let finite = match g.target {
            GoalTarget::Position(t) => t.is_finite(),
            GoalTarget::Plane { normal, offset, .. } => normal.is_finite() && offset.is_finite(),
            GoalTarget::Orientation(q) => q.is_finite(),
        };
        assert!(!g.is_active() || finite, "active goal with target {g:?}");
    }
    goals
}

/// The rig TOML loader (`rigfile::parse`, then the blob writer). Errors
/// must name the file; a file the host accepts must give a blob the core
/// parses, with the same rig hash.
pub fn rig_toml(data: &[u8]) -> Outcome {
    let Ok(text) = std::str::from_utf8(data) else {
        return Outcome::Rejected;
    };
    let rig = match rigfile::parse(text, "fuzz.toml") {
        Ok(rig) => rig,
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.starts_with("fuzz.toml:"),
                "error without its file: {msg}"
            );
            return Outcome::Rejected;
        }
    };
    let blob = match rigfile::to_blob(&rig) {
        Ok(b) => b,
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.starts_with("fuzz.toml"),
                "error without its file: {msg}"
            );
            return Outcome::Rejected;
        }
    };
    match Rig::parse(&blob) {
        Ok((core, _)) => assert_eq!(core.rig_hash(), rig.rig_hash()),
        Err(e) => panic!("the host accepted a rig the core refuses: {e:?}"),
    }
    Outcome::Accepted
}

// ------------------------------------------------------------------- mocap

/// A parsed motion holds finite root positions and unit rotations, and
/// converts to the core's skeleton and first local pose.
fn check_motion(m: &Motion) {
    for f in &m.frames {
        assert!(f.root_position.is_finite(), "root {}", f.root_position);
        assert_eq!(f.rotations.len(), m.joints.len());
        for q in &f.rotations {
            assert!(
                q.is_finite() && (q.length_squared() - 1.0).abs() < 1e-9,
                "rotation {q}"
            );
        }
    }
    if let Ok(skeleton) = m.core_skeleton(EndSites::Keep)
        && !m.frames.is_empty()
    {
        let _ = m.local_pose::<{ marionette_core::pose::MAX_SEGMENTS }>(&skeleton, 0);
    }
}

/// An import error names its file, first thing in its message.
fn check_import_error(e: &marionette_host::import::ImportError, file: &str) {
    assert_eq!(e.file(), file);
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("{file}:")), "{msg}");
}

/// The BVH parser, whole-file and streaming: both must agree; errors name
/// the file; motions are finite.
pub fn bvh_text(data: &[u8]) -> Outcome {
    const FILE: &str = "fuzz.bvh";
    let whole = bvh::parse(data, FILE, 0.056444);
    let mut streamed = Vec::new();
    let stream = bvh::FrameReader::new(data, FILE, 0.056444).and_then(|mut r| {
        while r.next_frame(&mut streamed)? {}
        Ok(r.header().clone())
    });
    match (&whole, &stream) {
        (Ok(b), Ok(h)) => {
            assert_eq!(&b.header, h);
            assert_eq!(b.values, streamed);
        }
        (Err(a), Err(b)) => {
            check_import_error(a, FILE);
            assert_eq!(a.to_string(), b.to_string());
        }
        _ => panic!("bvh::parse and FrameReader disagree"),
    }
    let Ok(b) = whole else {
        return Outcome::Rejected;
    };
    match b.to_motion() {
        Ok(m) => {
            check_motion(&m);
            Outcome::Accepted
        }
        Err(e) => {
            check_import_error(&e, FILE);
            Outcome::Rejected
        }
    }
}

fn hdm05_asf() -> &'static amc::Asf {
    static ASF: OnceLock<amc::Asf> = OnceLock::new();
    ASF.get_or_init(|| amc::parse_asf(HDM05_ASF, "HDM_bk.asf", None).expect("HDM05 ASF parses"))
}

/// The ASF/AMC parsers. An input with a NUL byte is `ASF \0 AMC`; without,
/// it is parsed both as an ASF and as an AMC for the HDM05 skeleton.
/// Errors name the file; motions are finite.
pub fn amc_text(data: &[u8]) -> Outcome {
    let (asf, amc_bytes) = match data.iter().position(|&b| b == 0) {
        Some(at) => {
            let asf = amc::parse_asf(&data[..at], "fuzz.asf", None);
            if let Err(e) = &asf {
                check_import_error(e, "fuzz.asf");
            }
            (asf.ok(), &data[at + 1..])
        }
        None => {
            if let Err(e) = amc::parse_asf(data, "fuzz.asf", Some(0.056444)) {
                check_import_error(&e, "fuzz.asf");
            }
            (None, data)
        }
    };
    let asf = asf.as_ref().unwrap_or_else(|| hdm05_asf());
    let parsed = match amc::parse_amc(amc_bytes, "fuzz.amc", asf) {
        Ok(a) => a,
        Err(e) => {
            check_import_error(&e, "fuzz.amc");
            return Outcome::Rejected;
        }
    };
    match asf.to_motion(&parsed, 1.0 / 120.0) {
        Ok(m) => {
            check_motion(&m);
            Outcome::Accepted
        }
        Err(_) => Outcome::Rejected,
    }
}

// ------------------------------------------------------------- sensor map

/// The sensor-to-parameter mapping with arbitrary floats: the input is up
/// to 16 sensors of 29 bytes (`id`, position `[f32; 3]`, rotation
/// `[f32; 4]`, little-endian), NaN and infinities included, mapped by the
/// humanoid16 rig; parameters must be finite and active goals finite. The
/// goals are then solved from the rest pose: no joint leaves its limits and
/// no angle or position becomes NaN.
pub fn sensor_map(data: &[u8]) -> Outcome {
    let mut cur = Cursor(data);
    let mut sensors = Vec::new();
    while sensors.len() < MAX_SENSORS {
        match cur.sensor() {
            Some(s) => sensors.push(s),
            None => break,
        }
    }
    let rig = humanoid16_rig();
    let goals = check_mapping(rig, &sensors);
    let body = rig.body();
    let mut angles = rig.rest_angles().expect("humanoid16 has a rest pose");
    let mut pose = Box::new(Pose::<{ marionette_core::pose::MAX_SEGMENTS }>::default());
    let solved = solve::solve(&Solver::DEFAULT, &body, &goals, &mut angles, &mut *pose);
    check_solution(&body, &angles, &pose);
    Outcome::of(solved.is_ok() && goals.as_slice().iter().any(|g| g.is_active()))
}

/// Angles within limits and finite; world pose finite.
pub fn check_solution<const N: usize>(
    body: &marionette_core::body::Body<'_>,
    angles: &Angles<N>,
    pose: &Pose<N>,
) {
    assert_eq!(angles.limit_excess(body), 0.0, "a joint left its limits");
    for v in angles.values.iter().take(angles.count) {
        assert!(v.iter().all(|a| a.is_finite()), "angles {v:?}");
    }
    assert!(angles.root_position.is_finite());
    for (p, q) in pose.positions().iter().zip(pose.rotations()) {
        assert!(p.is_finite() && q.is_finite(), "pose {p} {q}");
    }
}

// --------------------------------------------------------------- performer

/// Frames a message as the host sends it (delimiter first, like
/// `marionette_host::perform::encode`).
fn encode(msg: &Message) -> Vec<u8> {
    let mut out = vec![0];
    out.extend_from_slice(&encoded(msg));
    out
}

/// Frames a raw postcard payload (CRC and COBS added by the harness).
fn frame_payload(payload: &[u8]) -> Vec<u8> {
    let mut body = payload.to_vec();
    body.extend_from_slice(&crc32(payload).to_le_bytes());
    let mut out = vec![0u8; wire::cobs::max_encoded_len(body.len()) + 2];
    let n = wire::cobs::encode(&body, &mut out[1..]).expect("sized for the worst case");
    out.truncate(n + 1);
    out.push(0);
    out
}

fn arm(seq: u32) -> Command {
    Command {
        seq,
        kind: CommandKind::Arm,
    }
}

/// Tracks a performer's outputs against its rig's servo limits.
pub struct Run {
    /// Per channel: (lowest, highest, largest step, rest) in quarter-µs.
    limits: Vec<Option<(u16, u16, u16, u16)>>,
    /// The targets after the last call.
    last: Vec<u16>,
    /// The board clock, µs.
    pub now: u32,
    timeout_us: u32,
    period_us: u32,
    /// Calls that produced new outputs.
    pub outputs: u32,
}

impl Run {
    /// Starts tracking a fresh performer of `rig`.
    pub fn new(p: &Performer<'_, '_>, rig: &Rig<'_>) -> Self {
        let mut limits = vec![None; p.targets().len()];
        let period = rig.frame_period_s();
        for servo in rig.servos() {
            let cal = servo.calibration();
            let (lo, hi) = (quarter_us(cal.pulse_low()), quarter_us(cal.pulse_high()));
            let step = servo.step_limits(period).max_step.max(1);
            let rest = quarter_us(servo.rest_us).max(lo).min(hi);
            if let Some(slot) = limits.get_mut(usize::from(servo.channel)) {
                *slot = Some((lo, hi, step, rest));
            }
        }
        let run = Self {
            limits,
            last: p.targets().to_vec(),
            now: 1_000_000,
            timeout_us: rig.failsafe_timeout_ms().saturating_mul(1000),
            period_us: rig.frame_period_us().max(1),
            outputs: 0,
        };
        run.check_range(p);
        run
    }

    fn check_range(&self, p: &Performer<'_, '_>) {
        for (ch, (&t, l)) in p.targets().iter().zip(&self.limits).enumerate() {
            if let Some((lo, hi, _, _)) = *l {
                assert!(lo <= t && t <= hi, "channel {ch}: {t} outside [{lo}, {hi}]");
            }
        }
    }

    /// Checks one update: pulses in range, steps within the speed limit,
    /// unchanged targets when no output is reported, sendable replies.
    pub fn check(&mut self, p: &Performer<'_, '_>, update: &Update) {
        self.check_range(p);
        let now = p.targets();
        assert_eq!(now.len(), self.last.len());
        for (ch, ((&t, &before), l)) in now.iter().zip(&self.last).zip(&self.limits).enumerate() {
            if let Some((_, _, step, _)) = *l {
                assert!(
                    t.abs_diff(before) <= step,
                    "channel {ch}: {before} -> {t} exceeds {step} per frame"
                );
            }
        }
        if update.outputs.is_some() {
            self.outputs += 1;
        } else {
            assert_eq!(now, self.last.as_slice(), "targets moved without an output");
        }
        if let Some(reply) = &update.reply {
            let _ = encoded(reply);
        }
        self.last = now.to_vec();
    }

    /// Feeds bytes at the current clock until they are consumed.
    pub fn feed(&mut self, p: &mut Performer<'_, '_>, bytes: &[u8]) {
        let mut input = bytes;
        while !input.is_empty() {
            let before = input.len();
            let update = p.receive(&mut input, self.now, &mut NoCycles);
            self.check(p, &update);
            assert!(
                input.len() < before || update.outputs.is_some() || update.reply.is_some(),
                "receive made no progress"
            );
        }
    }

    /// One board tick after `dt` µs.
    pub fn tick(&mut self, p: &mut Performer<'_, '_>, dt: u32) {
        self.now = self.now.wrapping_add(dt);
        let update = p.tick(self.now);
        self.check(p, &update);
    }

    /// The fail-safe: the link goes quiet for the fail-safe time-out (or
    /// the jog's, [`JOG_TIMEOUT_US`], if longer: a jog ends then); ticking
    /// at the frame period must then bring every servo to its rest pulse,
    /// still, within the time its speed and acceleration limits need.
    pub fn finish(&mut self, p: &mut Performer<'_, '_>) {
        let bound = self
            .limits
            .iter()
            .flatten()
            .map(|&(lo, hi, step, _)| u32::from(hi - lo) / u32::from(step) + 3 * u32::from(step))
            .max()
            .unwrap_or(0)
            + 10;
        self.now = self.now.wrapping_add(self.timeout_us.max(JOG_TIMEOUT_US));
        let mut ticks = 0;
        while !p.resting() {
            assert!(ticks <= bound, "not at rest after {ticks} ticks");
            self.tick(p, self.period_us);
            ticks += 1;
        }
        for (ch, (&t, l)) in p.targets().iter().zip(&self.limits).enumerate() {
            if let Some((_, _, _, rest)) = *l {
                assert_eq!(t, rest, "channel {ch} resting off its rest pulse");
            }
        }
        assert!(
            p.tick(self.now.wrapping_add(self.period_us))
                .outputs
                .is_none()
        );
    }
}

/// The whole live loop, [`Performer::receive`] and [`Performer::tick`], on
/// the humanoid16 rig with a small table. The input is a script of
/// operations, each an opcode byte (mod 8) and its operands (little-endian;
/// an operation cut short by the end of the input is dropped):
///
/// | op | operands | what the harness sends |
/// |---|---|---|
/// | 0 | `n: u8`, `n` bytes | the raw bytes |
/// | 1 | `n: u8`, `n` bytes | the bytes as a postcard payload, framed with CRC and COBS |
/// | 2 | `dt: u16` | nothing: the clock advances `dt` µs and the board ticks |
/// | 3 | `dt: u16`, `k: u8`, `k mod 17` sensors of 29 bytes | a `TrackerFrame` (next seq, tracker time `+dt`) |
/// | 4 | `kind: u8`, operands of the kind | a `Command` (next seq) |
/// | 5 | `k: u8`, `k mod 7` `f32` | a `Params` (next seq) |
/// | 6 | `version: u16` | a `Hello` |
/// | 7 | `d: u32` | nothing: the host's seq jumps by `d` |
///
/// After the script the link goes quiet and the fail-safe must bring every
/// servo to rest. Every output is checked by [`Run`].
pub fn performer(data: &[u8]) -> Outcome {
    let region = Region::parse(humanoid16_region());
    let mut solver = SolverState::new();
    let mut p = Performer::new(&region, &mut solver);
    let rig = region.rig.as_ref().expect("the test region has a rig");
    assert_eq!(p.reason(), StatusReason::Ok);
    let mut run = Run::new(&p, rig);
    let mut cur = Cursor(data);
    let mut seq = 0u32;
    let mut tracker_us = 0u32;
    let mut armed_frames = 0u32;
    while let Some(op) = cur.u8() {
        let Some(bytes) = script_op(op, &mut cur, &mut seq, &mut tracker_us, &mut run) else {
            break;
        };
        if let [lo, hi] = bytes[..]
            && op % 8 == 2
        {
            run.tick(&mut p, u32::from(u16::from_le_bytes([lo, hi])));
            continue;
        }
        let frames_before = run.outputs;
        let was_armed = p.armed();
        run.feed(&mut p, &bytes);
        if was_armed && p.armed() && run.outputs > frames_before {
            armed_frames += 1;
        }
    }
    run.finish(&mut p);
    Outcome::of(armed_frames > 0)
}

/// Decodes one script operation into the bytes to send (for op 2, the two
/// bytes of `dt`). `None` when the input ends inside it.
fn script_op(
    op: u8,
    cur: &mut Cursor<'_>,
    seq: &mut u32,
    tracker_us: &mut u32,
    run: &mut Run,
) -> Option<Vec<u8>> {
    let mut next_seq = || {
        *seq = seq.wrapping_add(1);
        *seq
    };
    match op % 8 {
        0 => {
            let n = cur.u8()?;
            Some(cur.take(usize::from(n)).to_vec())
        }
        1 => {
            let n = cur.u8()?;
            Some(frame_payload(cur.take(usize::from(n))))
        }
        2 => cur.u16().map(|dt| dt.to_le_bytes().to_vec()),
        3 => {
            let dt = cur.u16()?;
            let k = cur.u8()? % 17;
            let mut sensors = List::<Sensor, MAX_SENSORS>::new();
            for _ in 0..k {
                sensors.push(cur.sensor()?).expect("at most 16");
            }
            *tracker_us = tracker_us.wrapping_add(u32::from(dt));
            run.now = run.now.wrapping_add(u32::from(dt));
            Some(encode(&Message::TrackerFrame(TrackerFrame {
                seq: next_seq(),
                time_us: *tracker_us,
                sensors,
            })))
        }
        4 => {
            let kind = match cur.u8()? % 7 {
                0 => CommandKind::Arm,
                1 => CommandKind::Disarm,
                2 => CommandKind::SelectTable(cur.u8()?),
                3 => CommandKind::SelectClip(cur.u8()?),
                4 => CommandKind::SetGoalWeight {
                    goal: cur.u8()?,
                    weight: cur.f32()?,
                },
                5 => CommandKind::Boresight { sensor: cur.u8()? },
                _ => CommandKind::RequestStatus,
            };
            Some(encode(&Message::Command(Command {
                seq: next_seq(),
                kind,
            })))
        }
        5 => {
            let k = cur.u8()? % 7;
            let mut values = List::new();
            for _ in 0..k {
                values.push(cur.f32()?).expect("at most 6");
            }
            Some(encode(&Message::Params(Params {
                seq: next_seq(),
                values,
            })))
        }
        6 => Some(encode(&Message::Hello(Hello {
            protocol_version: cur.u16()?,
        }))),
        _ => {
            *seq = seq.wrapping_add(cur.u32()?);
            Some(Vec::new())
        }
    }
}

// ------------------------------------------------------------------- seeds

/// Seed inputs for every target (valid inputs built from the shipped rigs,
/// the test tables and slices of `data/`), as `(target, name, bytes)`.
/// `tests/fuzz_replay.rs` writes them with `--ignored write_seed_corpus`.
pub fn seeds(repo: &std::path::Path) -> Vec<(&'static str, String, Vec<u8>)> {
    let mut out = Vec::new();
    wire_seeds(&mut out);
    let rest_table = humanoid16_table();
    for (name, blob) in [("grid", rest_table), ("clips", clip_table())] {
        for mode in [0u8, 1] {
            let mut b = vec![mode];
            b.extend_from_slice(&blob);
            out.push(("table_blob", format!("{name}-{mode}"), b));
        }
    }
    let cmu31 = rigfile::parse(CMU31_TOML, "cmu31.toml").expect("cmu31 parses");
    for (name, blob) in [
        ("humanoid16", humanoid16_blob().to_vec()),
        ("cmu31", rigfile::to_blob(&cmu31).expect("cmu31 blob")),
    ] {
        for mode in [0u8, 1] {
            let mut b = vec![mode];
            b.extend_from_slice(&blob);
            out.push(("rig_blob", format!("{name}-{mode}"), b));
        }
    }
    out.push(("rig_toml", "humanoid16".into(), HUMANOID16_TOML.into()));
    out.push(("rig_toml", "cmu31".into(), CMU31_TOML.into()));
    mocap_seeds(repo, &mut out);
    for (i, sensors) in [canned_sensors(), canned_sensors()[..1].to_vec()]
        .iter()
        .enumerate()
    {
        let mut b = Vec::new();
        for s in sensors {
            b.push(s.id);
            s.position.iter().for_each(|v| b.extend(v.to_le_bytes()));
            s.rotation.iter().for_each(|v| b.extend(v.to_le_bytes()));
        }
        out.push(("sensor_map", format!("hands-{i}"), b));
    }
    out.push(("performer", "session".into(), performer_script(40)));
    out.push(("performer", "short".into(), performer_script(3)));
    out
}

fn wire_seeds(out: &mut Vec<(&'static str, String, Vec<u8>)>) {
    let sensors = List::from_slice(&canned_sensors()).expect("3 sensors");
    let msgs = [
        Message::Hello(Hello {
            protocol_version: PROTOCOL_VERSION,
        }),
        Message::Command(arm(1)),
        Message::TrackerFrame(TrackerFrame {
            seq: 2,
            time_us: 1000,
            sensors,
        }),
        Message::Params(Params {
            seq: 3,
            values: List::from_slice(&[0.1, -0.2]).expect("2 values"),
        }),
        Message::Command(Command {
            seq: 4,
            kind: CommandKind::SetGoalWeight {
                goal: 1,
                weight: 2.5,
            },
        }),
        Message::Status(Status {
            protocol_version: 1,
            armed: true,
            table_ok: true,
            reason: StatusReason::Ok,
            errors: ErrorCounters::new(),
            frames_ok: 9,
            request_seq: Some(4),
            state: State::Armed,
            trips: 1,
            show: marionette_core::wire::ShowState::Ready,
            show_refusals: 0,
        }),
        Message::Telemetry(Telemetry {
            seq: 5,
            servo_targets: List::from_slice(&[6000, 6100]).expect("2 targets"),
            goal_residuals: List::from_slice(&[0.01]).expect("1 residual"),
            stage_counts: [1, 2, 3, 4, 5, 15],
            errors: ErrorCounters::new(),
            state: State::FailSafe,
            trips: 2,
            last_trip: Trip { seq: 5, ticks: 30 },
            timing: FrameTiming {
                frames: 10,
                mean: 1500,
                worst: 2000,
                overruns: 1,
                budget: 1800,
            },
        }),
        Message::Ack(Ack { seq: 4, ok: true }),
    ];
    let mut session = Vec::new();
    for (i, m) in msgs.iter().enumerate() {
        // The board refuses board-to-host frames: only their payloads seed.
        if m.direction() == Direction::HostToBoard {
            let frame = encode(m);
            session.extend_from_slice(&frame);
            out.push(("wire", format!("frame-{i}"), frame));
        }
        let mut payload = [0u8; wire::MAX_PAYLOAD];
        let p = wire::encode_payload(m, &mut payload).expect("fits");
        out.push(("wire", format!("payload-{i}"), p.to_vec()));
    }
    out.push(("wire", "session".into(), session));
}

/// A script for [`performer`]: Hello, Arm, `frames` tracker frames of a
/// right hand circling in front of the pelvis tracker, Disarm.
fn performer_script(frames: u16) -> Vec<u8> {
    let mut s = vec![6, 1, 0, 4, 0];
    for i in 0..frames {
        let a = f32::from(i) * 0.05;
        s.extend([3, 0xE8, 0x03, 3]);
        let sensors = [
            (0u8, [-0.3 + 0.1 * a.cos(), 1.25 + 0.1 * a.sin(), 0.3]),
            (1, [0.3, 0.8, 0.1]),
            (2, [0.0, 1.0, 0.0]),
        ];
        for (id, p) in sensors {
            s.push(id);
            p.iter().for_each(|v| s.extend(v.to_le_bytes()));
            [1.0f32, 0.0, 0.0, 0.0]
                .iter()
                .for_each(|v| s.extend(v.to_le_bytes()));
        }
        if i % 10 == 9 {
            s.extend([2, 0xF4, 0x01]);
        }
    }
    s.extend([4, 1]);
    s
}

/// The first `frames` frames of a BVH file, its `Frames:` line rewritten.
fn bvh_head(text: &str, frames: usize) -> Option<Vec<u8>> {
    let (header, motion) = text.split_once("MOTION")?;
    let mut lines = motion.lines().filter(|l| !l.trim().is_empty());
    let _count = lines.next()?;
    let time = lines.next()?;
    let mut out = format!("{header}MOTION\nFrames: {frames}\n{time}\n");
    for l in lines.take(frames) {
        out.push_str(l);
        out.push('\n');
    }
    Some(out.into_bytes())
}

/// The header and first `frames` frames of an AMC file.
fn amc_head(bytes: &[u8], frames: usize) -> Vec<u8> {
    let mut out = Vec::new();
    let mut seen = 0;
    for line in bytes.split_inclusive(|&b| b == b'\n') {
        let first = line.first().copied().unwrap_or(b' ');
        if first.is_ascii_digit() {
            seen += 1;
            if seen > frames {
                break;
            }
        }
        out.extend_from_slice(line);
    }
    out
}

fn mocap_seeds(repo: &std::path::Path, out: &mut Vec<(&'static str, String, Vec<u8>)>) {
    let data = repo.join("data");
    let bvhs = [
        ("cmu_02_01", "cmu_02_01_walk/02_01.bvh"),
        ("cmu_16_21", "cmu_16_walk_run/16_21.bvh"),
        ("cmu_74_15", "cmu_74_slope_walks/74_15.bvh"),
    ];
    for (name, path) in bvhs {
        if let Some(b) = std::fs::read_to_string(data.join(path))
            .ok()
            .and_then(|t| bvh_head(&t, 2))
        {
            out.push(("bvh", name.into(), b));
        }
    }
    if let Ok(dir) = std::fs::read_dir(data.join("cmu_subject07_walk_speeds_ccrig")) {
        let mut files: Vec<_> = dir.flatten().map(|e| e.path()).collect();
        files.sort();
        if let Some(b) = files
            .iter()
            .find(|p| p.extension().is_some_and(|e| e == "bvh"))
            .and_then(|p| std::fs::read_to_string(p).ok())
            .and_then(|t| bvh_head(&t, 1))
        {
            out.push(("bvh", "cmu_07_ccrig".into(), b));
        }
    }
    let amc = std::fs::read(data.join("hdm05_bk/HDM_bk_grabHighR_005_120.amc")).unwrap_or_default();
    let head = amc_head(&amc, 2);
    out.push(("amc", "hdm05-amc".into(), head.clone()));
    let mut both = HDM05_ASF.to_vec();
    both.push(0);
    both.extend_from_slice(&head);
    out.push(("amc", "hdm05-asf-amc".into(), both));
}
