//! Layers (#18): the blend against a slow `f64` reference, the layer list
//! format, the region's refusal of a failing layer table, and clip tables
//! played in time through the core's live loop (phase advance, continuity
//! under a parameter ramp, root travel, cross-fades), natively on the
//! humanoid16 puppet's real reach and walk tables.

use glam::{Quat, Vec3};
use marionette_core::clip::Clips;
use marionette_core::frame::{Performer, Region};
use marionette_core::layer::{self, Layer, LayerError, Layers, Root, Source};
use marionette_core::pose::LocalPose;
use marionette_core::region::{self as reg, Entry};
use marionette_core::rig::Rig;
use marionette_core::solve::SolverState;
use marionette_core::table::{Kind, MAX_AXES, Table};
use marionette_core::wire::{Command, CommandKind, List, Message, Params, StatusReason};
use marionette_host::cmd::demo;
use marionette_host::flash::{self, BLACKPILL};
use marionette_host::import::csv::read_tracker_csv;
use marionette_host::perform::{self, Sent};
use marionette_host::rigfile::{self, RigFile};
use std::path::PathBuf;
use std::sync::OnceLock;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

// ---------------------------------------------------------------------------
// The blend against an independent f64 reference.

/// A small deterministic generator (xorshift64*), so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn quat(&mut self) -> [f64; 4] {
        let mut q = [0.0; 4];
        for c in &mut q {
            *c = self.next() * 2.0 - 1.0;
        }
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        q.map(|c| c / n)
    }
}

/// Slerp in `f64`, written from its definition: shortest arc (flip `b` if
/// `a·b < 0`), `(sin((1−t)θ)·a + sin(tθ)·b) / sin θ`, `θ = acos(a·b)`.
fn slerp64(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
    let mut dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|c| -c)
    } else {
        b
    };
    let theta = dot.min(1.0).acos();
    if theta < 1e-12 {
        return a;
    }
    let (wa, wb) = (
        ((1.0 - t) * theta).sin() / theta.sin(),
        (t * theta).sin() / theta.sin(),
    );
    [0, 1, 2, 3].map(|i| wa * a[i] + wb * b[i])
}

fn to_f32(q: [f64; 4]) -> Quat {
    Quat::from_xyzw(q[1] as f32, q[2] as f32, q[3] as f32, q[0] as f32)
}

fn to_f64(q: Quat) -> [f64; 4] {
    [q.w, q.x, q.y, q.z].map(f64::from)
}

/// Angle between two rotations (sign-independent), radians, from the
/// chord between the normalized quaternions (well conditioned near 0,
/// where `acos` of the dot product is not).
fn angle_between(a: [f64; 4], b: [f64; 4]) -> f64 {
    let unit = |q: [f64; 4]| {
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        q.map(|c| c / n)
    };
    let (a, b) = (unit(a), unit(b));
    let d: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let s = if d < 0.0 { -1.0 } else { 1.0 };
    let chord = (0..4)
        .map(|i| (a[i] - s * b[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    4.0 * (chord / 2.0).min(1.0).asin()
}

#[test]
fn the_blend_follows_its_stated_rule_against_an_f64_reference() {
    const S: usize = 13;
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut worst: f64 = 0.0;
    for trial in 0..200 {
        let base_q: Vec<[f64; 4]> = (0..S).map(|_| rng.quat()).collect();
        let base_root = [0, 1, 2].map(|_| rng.next() - 0.5);
        let layers = 1 + trial % 3;
        let mut pose = LocalPose::<S>::new(S).unwrap();
        for (r, q) in pose.rotations.iter_mut().zip(&base_q) {
            *r = to_f32(*q);
        }
        pose.root_position = Vec3::new(
            base_root[0] as f32,
            base_root[1] as f32,
            base_root[2] as f32,
        );
        let mut want_q: Vec<[f64; 4]> = pose.rotations.iter().map(|q| to_f64(*q)).collect();
        let mut want_root = pose.root_position.to_array().map(f64::from);
        for k in 0..layers {
            let mut layer = LocalPose::<S>::new(S).unwrap();
            for r in &mut layer.rotations {
                *r = to_f32(rng.quat());
            }
            layer.root_position = Vec3::new(rng.next() as f32, rng.next() as f32, 0.3);
            // Masks with hard 0s and 1s and soft values; weights with both ends.
            let mask: Vec<u8> = (0..S)
                .map(|s| match (s + k + trial) % 4 {
                    0 => 0,
                    1 => 255,
                    _ => (rng.next() * 255.0) as u8,
                })
                .collect();
            let weight = match trial % 5 {
                0 => 1.0,
                1 => 0.0,
                _ => rng.next() as f32,
            };
            let before = pose;
            layer::blend(&mut pose, &layer, &mask, weight);
            for s in 0..S {
                let w = f64::from(weight) * f64::from(mask[s]) / 255.0;
                want_q[s] = slerp64(want_q[s], to_f64(layer.rotations[s]), w);
                // The ends are exact: untouched, or replaced.
                if w == 0.0 {
                    assert_eq!(pose.rotations[s], before.rotations[s]);
                } else if w == 1.0 {
                    assert_eq!(pose.rotations[s], layer.rotations[s]);
                }
            }
            let w0 = f64::from(weight) * f64::from(mask[0]) / 255.0;
            let lr = layer.root_position.to_array().map(f64::from);
            want_root = [0, 1, 2].map(|i| want_root[i] + (lr[i] - want_root[i]) * w0);
        }
        for (got, want) in pose.rotations.iter().zip(&want_q) {
            let e = angle_between(to_f64(*got), *want);
            worst = worst.max(e);
        }
        let got_root = pose.root_position.to_array().map(f64::from);
        for i in 0..3 {
            assert!(
                (got_root[i] - want_root[i]).abs() < 1e-6,
                "trial {trial}: root {got_root:?} vs {want_root:?}"
            );
        }
    }
    // Three chained f32 slerps of 6.7e-6 rad each, plus f32 rounding of the
    // inputs.
    assert!(worst < 5e-5, "worst rotation error {worst} rad");
}

// ---------------------------------------------------------------------------
// The layer list format.

fn sample_layers(mask: &[u8]) -> [Layer<'_>; 2] {
    let mut a = [Source::Const(0.0); MAX_AXES];
    a[0] = Source::Ramp {
        from: 0.8,
        to: 1.9,
        seconds: 2.0,
    };
    let mut b = [Source::Const(0.0); MAX_AXES];
    b[..3].copy_from_slice(&[Source::Param(0), Source::Param(1), Source::Const(0.25)]);
    [
        Layer {
            table: 1,
            root: Root::Apply,
            fade_s: 0.5,
            weight: Source::Param(4),
            rate: Source::Param(2),
            axes: a,
            axis_count: 1,
            mask,
        },
        Layer {
            table: 0,
            root: Root::Drop,
            fade_s: 0.0,
            weight: Source::Const(1.0),
            rate: Source::Const(1.0),
            axes: b,
            axis_count: 3,
            mask,
        },
    ]
}

#[test]
fn a_layer_list_round_trips_and_every_byte_is_checked() {
    let mask = [0u8, 255, 128, 7, 0];
    let layers = sample_layers(&mask);
    let mut out = vec![0u8; layer::len(2, 5)];
    assert_eq!(Layers::write(&layers, 5, &mut out), Ok(out.len()));
    // 8-byte prefix, two layers of 136 + 8 (5 mask bytes padded), CRC.
    assert_eq!(out.len(), 8 + 2 * (136 + 8) + 4);
    assert_eq!(&out[..8], b"MLAY\x02\x00\x02\x05");
    // Layer 0's rate source after its weight: kind 1 (parameter), index 2.
    assert_eq!(
        &out[8 + 24..8 + 40],
        &[1, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    );
    let parsed = Layers::parse(&out).unwrap();
    assert_eq!(parsed.as_slice(), &layers[..]);
    assert_eq!(parsed.segments(), 5);
    for i in 0..out.len() {
        let mut b = out.clone();
        b[i] ^= 0x01;
        assert!(Layers::parse(&b).is_err(), "byte {i} not checked");
    }
    for cut in 0..out.len() {
        assert!(Layers::parse(&out[..cut]).is_err(), "cut at {cut}");
    }
    // A field out of its domain, with a valid CRC, names its layer.
    let fix_crc = |b: &mut Vec<u8>| {
        let n = b.len() - 4;
        let crc = marionette_core::crc::crc32(&b[..n]);
        b[n..].copy_from_slice(&crc.to_le_bytes());
    };
    let second = 8 + 144;
    for (at, value) in [(second + 1, 2u8), (second + 3, 1), (second + 24, 9)] {
        let mut b = out.clone();
        b[at] = value;
        fix_crc(&mut b);
        assert_eq!(
            Layers::parse(&b),
            Err(LayerError::Field { index: 1 }),
            "{at}"
        );
    }
    let mut b = out.clone();
    b[4] = 3;
    fix_crc(&mut b);
    assert_eq!(Layers::parse(&b), Err(LayerError::Version(3)));
    assert_eq!(LayerError::Version(3).reason(), StatusReason::BadVersion);
}

#[test]
fn a_version_1_layer_list_still_reads_with_rate_1() {
    let mask = [0u8, 255, 128, 7, 0];
    let mut layers = sample_layers(&mask);
    let mut v2 = vec![0u8; layer::len(2, 5)];
    Layers::write(&layers, 5, &mut v2).unwrap();
    // Version 1 by hand: version 1, and each layer without the 16 bytes of
    // its rate source (offset 24 of the layer), then a new CRC.
    let mut v1 = b"MLAY\x01\x00\x02\x05".to_vec();
    for layer in v2[8..v2.len() - 4].chunks(144) {
        v1.extend_from_slice(&layer[..24]);
        v1.extend_from_slice(&layer[40..]);
    }
    let crc = marionette_core::crc::crc32(&v1);
    v1.extend_from_slice(&crc.to_le_bytes());
    assert_eq!(v1.len(), 8 + 2 * (120 + 8) + 4);
    for l in &mut layers {
        l.rate = Source::Const(1.0);
    }
    assert_eq!(Layers::parse(&v1).unwrap().as_slice(), &layers[..]);
}

// ---------------------------------------------------------------------------
// The humanoid16 puppet's real tables.

struct Puppet {
    rig: RigFile,
    rig_blob: Vec<u8>,
    reach: Vec<u8>,
    walk: Vec<u8>,
}

fn puppet() -> &'static Puppet {
    static P: OnceLock<Puppet> = OnceLock::new();
    P.get_or_init(|| {
        let rig = rigfile::load(&repo().join("rigs/humanoid16.toml")).unwrap();
        let rig_blob = rigfile::to_blob(&rig).unwrap();
        let reach = demo::build_table(&repo().join("data/builds/reach_humanoid16.toml"))
            .unwrap()
            .blob;
        let walk = demo::build_table(&repo().join("data/builds/walk_humanoid16.toml"))
            .unwrap()
            .blob;
        Puppet {
            rig,
            rig_blob,
            reach,
            walk,
        }
    })
}

fn region_of(entries: &[Entry<'_>]) -> Vec<u8> {
    let mut out = vec![0u8; reg::len(entries).unwrap()];
    let n = reg::write(entries, &mut out).unwrap();
    out.truncate(n);
    out
}

fn list(layers: &[Layer<'_>], segments: usize) -> Vec<u8> {
    let mut out = vec![0u8; layer::len(layers.len(), segments)];
    Layers::write(layers, segments, &mut out).unwrap();
    out
}

fn one<'m>(axes: &[Source], table: u8, root: Root, weight: Source, mask: &'m [u8]) -> Layer<'m> {
    let mut a = [Source::Const(0.0); MAX_AXES];
    a[..axes.len()].copy_from_slice(axes);
    Layer {
        table,
        root,
        fade_s: 0.0,
        weight,
        rate: Source::Const(1.0),
        axes: a,
        axis_count: axes.len() as u8,
        mask,
    }
}

#[test]
fn the_demo_region_arms_and_a_failing_layer_table_is_refused_with_a_reason() {
    let p = puppet();
    let good = demo::layered_region(&p.rig, &p.reach, &p.walk, 2.0).unwrap();
    let r = Region::parse(&good);
    assert_eq!(r.reason, StatusReason::Ok);
    let layers = r.layers.as_ref().unwrap();
    assert_eq!(layers.as_slice().len(), 2);
    assert_eq!(r.layer_tables[0].unwrap().kind(), Kind::Clips { phases: 1 });
    assert_eq!(r.layer_tables[1].unwrap().kind(), Kind::Grid);
    let mut solver = SolverState::new();
    assert_eq!(Performer::new(&r, &mut solver).reason(), StatusReason::Ok);
    // `marionette flash` checks it as the board reads it.
    let armed = flash::check_region(&BLACKPILL, &good).unwrap();
    assert_eq!((armed.layers, armed.grid.clone()), (2, vec![2, 64]));
    assert!(armed.to_string().contains("2 layers"), "{armed}");

    let segments = p.rig.segment_names().len();
    let mask = vec![255u8; segments];
    let walk = one(
        &[Source::Const(1.0)],
        1,
        Root::Drop,
        Source::Const(1.0),
        &mask,
    );
    let reach = one(
        &[Source::Param(0), Source::Param(1), Source::Param(2)],
        0,
        Root::Drop,
        Source::Const(1.0),
        &mask,
    );
    let refused = |entries: &[Entry<'_>]| {
        let bytes = region_of(entries);
        let r = Region::parse(&bytes);
        let mut solver = SolverState::new();
        let board = Performer::new(&r, &mut solver).reason();
        assert_eq!(board, r.reason, "the board reports the region's reason");
        (r.reason, r.refused_layer, r.layers.is_some())
    };
    let l = list(&[reach, walk], segments);
    let rig = Entry::rig(&p.rig_blob);
    // Both tables fine.
    assert_eq!(
        refused(&[
            rig,
            Entry::table(&p.reach),
            Entry::table(&p.walk),
            Entry::layers(&l)
        ]),
        (StatusReason::Ok, None, true)
    );
    // The walk table damaged: its CRC.
    let mut bad = p.walk.clone();
    bad[40] ^= 0x20;
    let damaged = [
        rig,
        Entry::table(&p.reach),
        Entry::table(&bad),
        Entry::layers(&l),
    ];
    assert_eq!(refused(&damaged), (StatusReason::BadCrc, Some(1), false));
    match flash::check_region(&BLACKPILL, &region_of(&damaged)) {
        Err(flash::FlashError::WouldNotArm { reason, why }) => {
            assert_eq!(reason, StatusReason::BadCrc);
            assert!(why.contains("layer 1"), "{why}");
        }
        other => panic!("not refused: {other:?}"),
    }
    // Layer 1's table missing.
    assert_eq!(
        refused(&[rig, Entry::table(&p.reach), Entry::layers(&l)]),
        (StatusReason::NoTable, Some(1), false)
    );
    // A layer whose sources do not match its table's axes (the reach grid
    // given the walk layer's one source).
    let wrong = list(
        &[
            reach,
            one(
                &[Source::Const(1.0)],
                0,
                Root::Drop,
                Source::Const(1.0),
                &mask,
            ),
        ],
        segments,
    );
    assert_eq!(
        refused(&[rig, Entry::table(&p.reach), Entry::layers(&wrong)]),
        (StatusReason::Unsupported, Some(1), false)
    );
    // A list for another segment count.
    let short = list(
        &[one(
            &[Source::Const(1.0)],
            1,
            Root::Drop,
            Source::Const(1.0),
            &mask[1..],
        )],
        segments - 1,
    );
    assert_eq!(
        refused(&[
            rig,
            Entry::table(&p.reach),
            Entry::table(&p.walk),
            Entry::layers(&short)
        ]),
        (StatusReason::RigMismatch, None, false)
    );
    // The list itself damaged.
    let mut broken = l.clone();
    broken[9] ^= 1;
    assert_eq!(
        refused(&[
            rig,
            Entry::table(&p.reach),
            Entry::table(&p.walk),
            Entry::layers(&broken)
        ]),
        (StatusReason::BadCrc, None, false)
    );
}

// ---------------------------------------------------------------------------
// Clips in time, through the live loop.

/// The bundled recording's first `frames` tracker frames (1 kHz; the walk
/// ignores them) in a session: `Hello`, `Arm`, every goal's weight set to 0
/// (so that the solver leaves the synthesized angles alone), the frames
/// (numbered 100, 102, …, leaving room), with `dials[k]` sent as a `Params`
/// message just before frame `k`, then `Disarm`.
fn session_without_goals(goals: usize, frames: usize, dials: &[(usize, [f32; 6])]) -> Vec<Sent> {
    let samples = read_tracker_csv(&repo().join("data/recordings/reach_hdm05_007.csv")).unwrap();
    let mut tracker = perform::frames(&samples).unwrap();
    tracker.truncate(frames);
    for (k, f) in tracker.iter_mut().enumerate() {
        f.seq = 100 + 2 * k as u32;
    }
    let mut s = perform::session(&tracker).unwrap();
    let sent = |time_us: u32, msg: &Message| Sent {
        time_us,
        bytes: perform::frame_bytes(msg).unwrap(),
    };
    // Dials first (from the back, so the indices stay those of the frames).
    for (k, values) in dials.iter().rev() {
        let f = &tracker[*k];
        let msg = Message::Params(Params {
            seq: f.seq - 1,
            values: List::from_slice(values).unwrap(),
        });
        s.insert(2 + k, sent(f.time_us, &msg));
    }
    let t = s[1].time_us;
    for g in (0..goals).rev() {
        let cmd = Message::Command(Command {
            seq: 1 + g as u32,
            kind: CommandKind::SetGoalWeight {
                goal: g as u8,
                weight: 0.0,
            },
        });
        s.insert(2, sent(t, &cmd));
    }
    s
}

/// Per performed frame: every servo's joint angle (before calibration and
/// slew), the root position, and layer 0's weight and phase.
struct Trace {
    angles: Vec<Vec<f32>>,
    roots: Vec<Vec3>,
    layer0: Vec<(f32, f32)>,
}

fn trace(region: &[u8], frames: usize) -> Trace {
    trace_with(region, frames, &[])
}

fn trace_with(region: &[u8], frames: usize, dials: &[(usize, [f32; 6])]) -> Trace {
    let r = Region::parse(region);
    assert_eq!(r.reason, StatusReason::Ok);
    let rig: &Rig<'_> = r.rig.as_ref().unwrap();
    let session = session_without_goals(rig.goal_count(), frames, dials);
    let mut t = Trace {
        angles: Vec::new(),
        roots: Vec::new(),
        layer0: Vec::new(),
    };
    perform::simulate_with(region, &session, &mut |p, u| {
        if let (Some(marionette_core::frame::Cause::Frame(_)), Some(pl)) = (u.outputs, p.pipeline())
        {
            let a = pl.angles();
            t.angles.push(
                rig.servos()
                    .iter()
                    .map(|s| Rig::servo_angle(s, a).unwrap())
                    .collect(),
            );
            t.roots.push(a.root_position);
            t.layer0.push(pl.layer(0).unwrap());
        }
    })
    .unwrap();
    assert_eq!(t.angles.len(), frames, "every frame performed");
    t
}

fn walk_region(speed: Source, root: Root, weight: Source) -> Vec<u8> {
    walk_region_at(1.0, speed, root, weight)
}

/// [`walk_region`] played at `rate`.
fn walk_region_at(rate: f32, speed: Source, root: Root, weight: Source) -> Vec<u8> {
    let p = puppet();
    let segments = p.rig.segment_names().len();
    let mut mask = vec![255u8; segments];
    mask[0] = if root == Root::Apply { 255 } else { 0 };
    let mut walk = one(&[speed], 0, root, weight, &mask);
    walk.rate = Source::Const(rate);
    let l = list(&[walk], segments);
    region_of(&[
        Entry::rig(&p.rig_blob),
        Entry::table(&p.walk),
        Entry::layers(&l),
    ])
}

fn walk_speeds() -> (f32, f32) {
    let t = Table::parse(&puppet().walk).unwrap();
    let a = t.param_axes()[0];
    (a.min, a.min + a.step * f32::from(a.count - 1))
}

#[test]
fn the_phase_advances_by_the_frame_period_over_the_interpolated_duration() {
    let p = puppet();
    let table = Table::parse(&p.walk).unwrap();
    let Kind::Clips { phases } = table.kind() else {
        panic!("the walk is a clip table")
    };
    let clips = Clips::new(
        table.grid().unwrap(),
        table.param_grid().unwrap(),
        phases.into(),
    )
    .unwrap();
    let (slow, fast) = walk_speeds();
    let mid = 0.5 * (slow + fast);
    // The stored durations (the table's own array), and the midpoint's by
    // linear interpolation, worked here.
    let (d_slow, d_fast) = (table.duration(0, 0).unwrap(), table.duration(1, 0).unwrap());
    let d_mid = clips.motion(&table, &[mid]).unwrap().duration();
    assert!((f64::from(d_mid) - 0.5 * f64::from(d_slow + d_fast)).abs() < 1e-6);
    let frames = 1500;
    let t = trace(
        &walk_region(Source::Const(mid), Root::Drop, Source::Const(1.0)),
        frames,
    );
    let period = 1e-3_f64; // humanoid16: 1 kHz, the recording's rate too
    for (k, &(w, phase)) in t.layer0.iter().enumerate() {
        assert_eq!(w, 1.0);
        let want = ((k + 1) as f64 * period / f64::from(d_mid)).fract();
        let err = (f64::from(phase) - want).abs();
        assert!(
            err.min(1.0 - err) < 2e-4,
            "frame {k}: phase {phase} vs {want}"
        );
    }
}

/// Per servo, the largest joint-angle step of one frame over a trace, as a
/// fraction of the servo's speed limit for a 1 ms frame.
fn worst_steps(t: &Trace, servos: &[marionette_core::rig::ServoDesc]) -> Vec<f32> {
    let mut worst = vec![0.0f32; servos.len()];
    for pair in t.angles.windows(2) {
        for ((w, (a, b)), s) in worst
            .iter_mut()
            .zip(pair[0].iter().zip(&pair[1]))
            .zip(servos)
        {
            *w = w.max((b - a).abs() / (s.max_speed * 1e-3));
        }
    }
    worst
}

/// A constant-speed trace's joint angles as a function of the phase
/// (linear between the frames, sorted by phase), at `phase`.
fn at_phase(t: &Trace, channel: usize, phase: f32) -> f32 {
    let mut pts: Vec<(f32, f32)> = t
        .layer0
        .iter()
        .zip(&t.angles)
        .map(|(l, a)| (l.1, a[channel]))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let i = pts
        .partition_point(|p| p.0 <= phase)
        .clamp(1, pts.len() - 1);
    let ((p0, a0), (p1, a1)) = (pts[i - 1], pts[i]);
    a0 + (a1 - a0) * ((phase - p0) / (p1 - p0)).clamp(0.0, 1.0)
}

#[test]
fn a_speed_ramp_adds_no_pop_and_keeps_joints_within_their_servo_speed() {
    let p = puppet();
    let (slow, fast) = walk_speeds();
    let servos = p.rig.desc().servos.as_slice().to_vec();
    let frames = 2000;
    // The walk at constant speeds across the table's range: its own
    // largest steps per joint.
    let mut own = vec![0.0f32; servos.len()];
    let mut ends = Vec::new();
    for k in 0..=4 {
        let v = slow + (fast - slow) * k as f32 / 4.0;
        let t = trace(
            &walk_region(Source::Const(v), Root::Drop, Source::Const(1.0)),
            frames,
        );
        for (o, w) in own.iter_mut().zip(worst_steps(&t, &servos)) {
            *o = o.max(w);
        }
        if k % 4 == 0 {
            ends.push(t);
        }
    }
    // From the slowest walk to the fastest in `seconds` (the cycle shortens
    // from 0.95 s to 0.70 s while the phase goes on).
    let seconds = 0.5;
    let up = Source::Ramp {
        from: slow,
        to: fast,
        seconds,
    };
    let t = trace(&walk_region(up, Root::Drop, Source::Const(1.0)), frames);
    let ramp = worst_steps(&t, &servos);
    for (ch, ((s, r), o)) in servos.iter().zip(&ramp).zip(&own).enumerate() {
        // What the parameter itself moves a joint in one frame: the largest
        // difference between the slow and the fast cycle at equal phase,
        // per unit of speed, times the ramp's speed change per frame.
        let spread = (0..256)
            .map(|i| {
                let ph = i as f32 / 256.0;
                (at_phase(&ends[1], ch, ph) - at_phase(&ends[0], ch, ph)).abs()
            })
            .fold(0.0f32, f32::max);
        let by_param = spread * 1e-3 / seconds / (s.max_speed * 1e-3);
        // No pop: the ramp's largest step is the motion's own plus what the
        // parameter moves (a phase jump would add a fraction of a cycle).
        assert!(
            *r <= o * 1.02 + by_param * 1.25,
            "channel {}: {r} of the speed limit under the ramp, {o} at constant speeds, \
             {by_param} from the parameter",
            s.channel
        );
        // Within the servo's speed wherever the table's own motion and the
        // parameter's keep it.
        if o + by_param <= 1.0 {
            assert!(*r <= 1.0, "channel {}: {r} of its speed limit", s.channel);
        }
    }
    // The walk moves the joints (a test that could not fail would not),
    // and several joints stay within their servos' speed.
    assert!(ramp.iter().all(|&r| r > 0.05), "{ramp:?}");
    assert!(ramp.iter().filter(|&&r| r <= 1.0).count() >= 3, "{ramp:?}");
}

#[test]
fn at_a_rate_its_servos_can_follow_a_speed_ramp_stays_within_their_slew_limits() {
    let p = puppet();
    let (slow, fast) = walk_speeds();
    let servos = p.rig.desc().servos.as_slice().to_vec();
    let frames = 2000;
    // The captured walk at constant speeds, at its own tempo: its largest
    // step per joint as a fraction of the servo's speed limit.
    let own = (0..=4)
        .map(|k| {
            let v = slow + (fast - slow) * k as f32 / 4.0;
            let t = trace(
                &walk_region(Source::Const(v), Root::Drop, Source::Const(1.0)),
                frames,
            );
            worst_steps(&t, &servos).into_iter().fold(0.0f32, f32::max)
        })
        .fold(0.0f32, f32::max);
    assert!(
        own > 1.0,
        "the captured walk is faster than humanoid16's servos: {own}"
    );
    // The tempo at which every joint's own motion uses 80 % of its servo's
    // speed, then the speed ramped from the slowest walk to the fastest
    // over 2 s: every step stays within the slew limits.
    let rate = 0.8 / own;
    let up = Source::Ramp {
        from: slow,
        to: fast,
        seconds: 2.0,
    };
    let t = trace(
        &walk_region_at(rate, up, Root::Drop, Source::Const(1.0)),
        frames,
    );
    let ramp = worst_steps(&t, &servos);
    for (s, r) in servos.iter().zip(&ramp) {
        assert!(*r <= 1.0, "channel {}: {r} of its speed limit", s.channel);
    }
    // The walk moves every joint, some near their servo's speed.
    assert!(ramp.iter().all(|&r| r > 0.01), "{ramp:?}");
    assert!(ramp.iter().any(|&r| r > 0.3), "{ramp:?}");
    // The phase advances at the rate: by rate · dt / duration per frame at
    // a constant speed.
    let table = Table::parse(&p.walk).unwrap();
    let clips = Clips::new(table.grid().unwrap(), table.param_grid().unwrap(), 1).unwrap();
    let d = clips.motion(&table, &[slow]).unwrap().duration();
    let t = trace(
        &walk_region_at(rate, Source::Const(slow), Root::Drop, Source::Const(1.0)),
        500,
    );
    for (k, &(_, phase)) in t.layer0.iter().enumerate() {
        let want = ((k + 1) as f64 * 1e-3 * f64::from(rate) / f64::from(d)).fract();
        let err = (f64::from(phase) - want).abs();
        assert!(
            err.min(1.0 - err) < 2e-4,
            "frame {k}: phase {phase} vs {want}"
        );
    }
}

#[test]
fn root_travel_moves_the_figure_or_is_dropped_as_the_layer_says() {
    let (slow, fast) = walk_speeds();
    let p = puppet();
    let table = Table::parse(&p.walk).unwrap();
    let clips = Clips::new(table.grid().unwrap(), table.param_grid().unwrap(), 1).unwrap();
    let mid = 0.5 * (slow + fast);
    let motion = clips.motion(&table, &[mid]).unwrap();
    let frames = 1200;
    let applied = trace(
        &walk_region(Source::Const(mid), Root::Apply, Source::Const(1.0)),
        frames,
    );
    let dropped = trace(
        &walk_region(Source::Const(mid), Root::Drop, Source::Const(1.0)),
        frames,
    );
    // Dropped: the root is the rig's, every frame.
    let rest = dropped.roots[0];
    assert!(dropped.roots.iter().all(|r| *r == rest));
    // Applied: after whole cycles the root has moved by the travel per
    // cycle times the cycles played (the pose loops in place, so at equal
    // phase only the travel differs).
    let cycle = (f64::from(motion.duration()) / 1e-3).round() as usize;
    let (a, b) = (100, 100 + cycle);
    let moved = applied.roots[b] - applied.roots[a];
    let want = motion.travel() * (cycle as f32 * 1e-3 / motion.duration());
    assert!(motion.travel().length() > 0.3, "{:?}", motion.travel());
    assert!(
        (moved - want).length() < 0.02,
        "moved {moved:?}, travel {want:?}"
    );
}

#[test]
fn a_live_layer_weight_cross_fades_over_its_stated_time() {
    let p = puppet();
    let segments = p.rig.segment_names().len();
    let mask = vec![255u8; segments];
    // The weight is rig parameter 5, a dial; fade 0.2 s. Off at the start,
    // turned on before frame 300, off again before frame 600.
    let mut layer = one(
        &[Source::Const(1.2)],
        0,
        Root::Drop,
        Source::Param(5),
        &mask,
    );
    layer.fade_s = 0.2;
    let l = list(&[layer], segments);
    let region = region_of(&[
        Entry::rig(&p.rig_blob),
        Entry::table(&p.walk),
        Entry::layers(&l),
    ]);
    let on = [0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let t = trace_with(&region, 900, &[(300, on), (600, [0.0; 6])]);
    let w: Vec<f32> = t.layer0.iter().map(|x| x.0).collect();
    // Off until the dial, then 1/200 per 1 ms frame: 200 frames to full,
    // and 200 back to 0.
    assert!(w[..300].iter().all(|&x| x == 0.0));
    for pair in w.windows(2) {
        assert!((pair[1] - pair[0]).abs() <= 1.0 / 200.0 + 1e-6);
    }
    let full = w.iter().position(|&x| x == 1.0).unwrap();
    assert!((498..=500).contains(&full), "full weight at frame {full}");
    let off = 600 + w[600..].iter().position(|&x| x == 0.0).unwrap();
    assert!((798..=800).contains(&off), "off again at frame {off}");
    // The pose follows the weight: at weight 0 every joint is at rest.
    assert_eq!(t.angles[0], t.angles[299]);
    assert_eq!(t.angles[0], t.angles[850]);
    assert_ne!(t.angles[400], t.angles[0]);
}

// ---------------------------------------------------------------------------
// `marionette demo --layers` on the emulated board.

#[test]
fn demo_layers_runs_on_the_emulated_board_bit_for_bit_with_the_native_core() {
    let p = puppet();
    let rig_path = repo().join("rigs/humanoid16.toml");
    let recording = repo().join("data/recordings/reach_hdm05_007.csv");
    let mut inputs = demo::inputs(&rig_path, &p.reach, &recording).unwrap();
    let seconds = demo::make_layered(&mut inputs, &rig_path, &p.reach, &p.walk).unwrap();
    assert!(
        (seconds - 2.133).abs() < 1e-3,
        "the ramp spans the take: {seconds}"
    );
    let r = Region::parse(&inputs.region);
    assert_eq!(r.reason, StatusReason::Ok);
    assert_eq!(r.layers.map(|l| l.as_slice().len()), Some(2));

    // Natively: every frame performed, the walk moves the legs (the feet's
    // goals are off), the right hand follows its tracker.
    let native = perform::simulate(&inputs.region, &inputs.session).unwrap();
    assert_eq!(native.frame_targets.len(), inputs.frames);
    let span = |ch: usize| {
        let v: Vec<u16> = native.frame_targets.iter().map(|t| t[ch]).collect();
        v.iter().max().unwrap() - v.iter().min().unwrap()
    };
    // l_thigh.x (8), r_thigh.x (12): over 200 µs (×4 quarter units) of swing.
    assert!(span(8) > 800 && span(12) > 800, "{} {}", span(8), span(12));
    assert!(span(5) > 800, "the right arm reaches: {}", span(5));

    let out = tempfile::tempdir().unwrap();
    let compared = marionette_host::cmd::emulate::compare(
        &inputs,
        out.path(),
        perform::Pacing::AsFastAsPossible,
    )
    .unwrap();
    assert!(compared.stop.is_none(), "{:?}", compared.stop);
    assert_eq!(compared.summary.frame_outputs, inputs.frames);
    assert_eq!(
        compared.summary.mismatches, 0,
        "board and native core differ"
    );
}
