//! The table blob: host writer → core reader round trips, the quantization
//! error bound against an `f64` reference, the documented bytes of a tiny
//! blob, and corruption (bit flips, truncation, bad fields) → typed errors,
//! never a panic.

use glam::{DQuat, DVec3, Quat, Vec3};
use marionette_core::crc::crc32;
use marionette_core::grid::Samples;
use marionette_core::table::{
    self, Axis, Header, Interp, Kind, MAX_AXES, NAME_LEN, Span, Table, TableError, Wrap, quant,
};
use marionette_host::blob::{self, AxisSpec, BlobError, TableSpec};

// ---------------------------------------------------------------------------
// Helpers (all in f64, independent of the code under test)

/// xorshift64*: a small deterministic generator.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform random rotation (Shoemake's subgroup algorithm), `[w, x, y, z]`.
    fn quat(&mut self) -> [f64; 4] {
        let (u1, u2, u3) = (self.unit(), self.unit(), self.unit());
        let tau = std::f64::consts::TAU;
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        [
            b * (tau * u3).cos(),
            a * (tau * u2).sin(),
            a * (tau * u2).cos(),
            b * (tau * u3).sin(),
        ]
    }
}

/// `[w, x, y, z]` to an `f32` quaternion.
fn q32([w, x, y, z]: [f64; 4]) -> Quat {
    Quat::from_xyzw(x as f32, y as f32, z as f32, w as f32)
}

/// Rotation angle (radians, f64) between two quaternions, sign-independent:
/// `2·atan2(|vec(a*·b)|, |scalar(a*·b)|)` of the normalized inputs.
fn angle_f64(a: Quat, b: Quat) -> f64 {
    let a = DQuat::from_xyzw(a.x.into(), a.y.into(), a.z.into(), a.w.into());
    let b = DQuat::from_xyzw(b.x.into(), b.y.into(), b.z.into(), b.w.into());
    let (na, nb) = (a.dot(a).sqrt(), b.dot(b).sqrt());
    let r = a.conjugate() * b;
    let v = (r.x * r.x + r.y * r.y + r.z * r.z).sqrt() / (na * nb);
    let w = r.w.abs() / (na * nb);
    2.0 * v.atan2(w)
}

/// Largest coordinate error (metres, f64).
fn position_error(a: Vec3, b: Vec3) -> f64 {
    (DVec3::from(a.to_array().map(f64::from)) - DVec3::from(b.to_array().map(f64::from)))
        .abs()
        .max_element()
}

/// Edge-case rotations: axis-aligned, two equal largest components (±1/√2,
/// the "smallest three" tie), four equal (±½), three equal, each nudged so
/// that either neighbour of the tie wins, and with every sign pattern.
fn edge_quats() -> Vec<[f64; 4]> {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let t = 1.0 / 3.0_f64.sqrt();
    let mut base: Vec<[f64; 4]> = Vec::new();
    for i in 0..4 {
        let mut q = [0.0; 4];
        q[i] = 1.0;
        base.push(q);
        for j in (i + 1)..4 {
            let mut q = [0.0; 4];
            q[i] = h;
            q[j] = h;
            base.push(q);
            for k in (j + 1)..4 {
                let mut q = [0.0; 4];
                q[i] = t;
                q[j] = t;
                q[k] = t;
                base.push(q);
            }
        }
    }
    base.push([0.5; 4]);
    let mut out = Vec::new();
    for q in base {
        for signs in 0..16 {
            for nudge in [0.0, 1e-7, -1e-7, 1e-5, -1e-5, 1e-3, -1e-3] {
                for n_at in 0..4 {
                    let mut r = q;
                    for (c, v) in r.iter_mut().enumerate() {
                        if signs >> c & 1 == 1 {
                            *v = -*v;
                        }
                    }
                    r[n_at] += nudge;
                    out.push(r);
                }
            }
        }
    }
    out
}

/// The analytic worst case: three stored components equal to the dropped one
/// (all ≈ ½) and each just below a half-step of the 15-bit code, so every
/// rounding error has the same sign and the rebuilt component moves most.
/// Step from the documented code: `(1/√2) / 16383`.
fn half_step_quats() -> Vec<[f64; 4]> {
    let step = std::f64::consts::FRAC_1_SQRT_2 / 16383.0;
    let mut out = Vec::new();
    for k in 11_570..11_590 {
        for eps in [1e-3, 1e-2, 0.1] {
            for sign in [1.0, -1.0] {
                let v = sign * (k as f64 + 0.5 - eps) * step;
                let l = (1.0 - 3.0 * v * v).sqrt();
                if l >= v.abs() {
                    out.push([l, v, v, v]);
                    out.push([v, v, l, v]);
                }
            }
        }
    }
    out
}

// ---------------------------------------------------------------------------
// Quantization error bound

#[test]
fn rotation_error_within_stated_bound() {
    assert!(
        quant::ROTATION_BOUND <= 0.05_f32.to_radians(),
        "stated bound must be ≤ 0.05°"
    );
    let mut rng = Rng(0x1234_5678_9ABC_DEF1);
    let mut quats = edge_quats();
    quats.extend(half_step_quats());
    quats.extend((0..1_000_000).map(|_| rng.quat()));
    let mut worst = (0.0_f64, [0.0; 4]);
    for q in quats {
        let input = q32(q);
        let decoded = quant::dequantize_rotation(&quant::quantize_rotation(input));
        let e = angle_f64(input, decoded);
        if e > worst.0 {
            worst = (e, q);
        }
    }
    println!(
        "max rotation error {:.3e} rad = {:.5}° at {:?}",
        worst.0,
        worst.0.to_degrees(),
        worst.1
    );
    assert!(worst.0 <= f64::from(quant::ROTATION_BOUND), "{worst:?}");
}

#[test]
fn position_error_within_stated_bound() {
    let mut rng = Rng(0xDEAD_BEEF_CAFE_F00D);
    let mut worst_mm: f64 = 0.0;
    let ranges = [quant::MAX_POSITION, 32.0, 17.3, 2.0, 1.0, 0.25, 1e-3, 0.0];
    let random: Vec<f32> = (0..200).map(|_| rng.range(0.0, 32.0) as f32).collect();
    for (k, max_abs) in ranges.into_iter().chain(random).enumerate() {
        let scale = quant::position_scale(max_abs).unwrap();
        let bound = f64::from(quant::position_bound(scale));
        assert!(bound <= 0.5e-3, "{max_abs}: bound {bound}");
        let m = f64::from(max_abs);
        let mut points: Vec<Vec3> = vec![Vec3::splat(max_abs), Vec3::splat(-max_abs), Vec3::ZERO];
        points.extend(
            (0..if k < ranges.len() { 100_000 } else { 5_000 }).map(|_| {
                Vec3::new(
                    rng.range(-m, m) as f32,
                    rng.range(-m, m) as f32,
                    rng.range(-m, m) as f32,
                )
            }),
        );
        for p in points {
            let decoded = quant::dequantize_position(quant::quantize_position(p, scale), scale);
            let e = position_error(p, decoded);
            assert!(e <= bound, "{p} → {decoded}: {e} > {bound}");
            worst_mm = worst_mm.max(e * 1e3);
        }
    }
    println!("max position error {worst_mm:.4} mm");
}

// ---------------------------------------------------------------------------
// Writer → reader round trips

fn axis(name: &str, min: f32, step: f32, count: u16, wrap: Wrap, interp: Interp) -> AxisSpec {
    AxisSpec {
        name: name.into(),
        min,
        step,
        count,
        wrap,
        interp,
    }
}

/// A 3-axis grid (4 × 3 × 5, the last cyclic Catmull-Rom) of `segments`
/// random samples within ±`range` metres; every 7th cell invalid.
fn random_grid(rng: &mut Rng, segments: usize, range: f64) -> TableSpec {
    let axes = vec![
        axis("hand_x", -0.4, 0.2, 4, Wrap::Bounded, Interp::Linear),
        axis("hand_y", 0.8, 0.25, 3, Wrap::Bounded, Interp::Linear),
        axis(
            "pedal",
            0.0,
            0.4 * std::f32::consts::PI,
            5,
            Wrap::Cyclic {
                period: 2.0 * std::f32::consts::PI,
            },
            Interp::CatmullRom,
        ),
    ];
    let mut quats = edge_quats().into_iter().step_by(13).cycle();
    let samples = (0..4 * 3 * 5)
        .map(|i| {
            (0..segments)
                .map(|s| {
                    let p = Vec3::new(
                        rng.range(-range, range) as f32,
                        rng.range(-range, range) as f32,
                        rng.range(-range, range) as f32,
                    );
                    let q = if (i + s) % 3 == 0 {
                        quats.next().unwrap()
                    } else {
                        rng.quat()
                    };
                    (p, q32(q))
                })
                .collect()
        })
        .collect();
    TableSpec {
        rig_hash: 0xFEED_FACE_0123_4567,
        kind: Kind::Grid,
        axes,
        segment_names: (0..segments).map(|s| format!("segment_{s:02}")).collect(),
        samples,
        // 3 × 2 × 5 cells.
        valid: (0..30).map(|c| c % 7 != 3).collect(),
        durations: vec![],
        travel: vec![],
    }
}

#[test]
fn grid_round_trip_within_bound() {
    let mut rng = Rng(7);
    let spec = random_grid(&mut rng, 31, 1.8);
    let bytes = blob::write(&spec).unwrap();
    let t = Table::parse(&bytes).unwrap();
    assert_eq!(t.len(), bytes.len());
    assert_eq!(t.rig_hash(), 0xFEED_FACE_0123_4567);
    assert_eq!(t.kind(), Kind::Grid);
    assert_eq!(
        (t.grid_samples(), t.param_samples(), t.param_cells()),
        (60, 60, 30)
    );
    assert_eq!(t.segment_count(), 31);
    assert_eq!(t.segment_name(30), Some("segment_30"));
    assert_eq!(t.segment_name(31), None);
    assert_eq!(t.segment_index("segment_07"), Some(7));
    let names: Vec<_> = t.axes().iter().map(|a| a.name().unwrap()).collect();
    assert_eq!(names, ["hand_x", "hand_y", "pedal"]);
    assert_eq!(
        t.axes()[2].wrap,
        Wrap::Cyclic {
            period: 2.0 * std::f32::consts::PI
        }
    );
    assert_eq!(t.axes()[2].interp, Interp::CatmullRom);
    for c in 0..30 {
        assert_eq!(t.cell_valid(c), Some(c % 7 != 3), "cell {c}");
    }
    assert_eq!(t.cell_valid(30), None);
    assert_eq!(t.duration(0, 0), None);

    let h = t.header();
    let (pos_bound, rot_bound) = (f64::from(h.position_bound), f64::from(h.rotation_bound));
    assert!(pos_bound <= 0.5e-3 && rot_bound <= 0.05_f64.to_radians());
    let (mut worst_p, mut worst_r) = (0.0_f64, 0.0_f64);
    for (i, poses) in spec.samples.iter().enumerate() {
        for (s, &(p, q)) in poses.iter().enumerate() {
            let (dp, dq) = t.sample(i, s).unwrap();
            worst_p = worst_p.max(position_error(p, dp));
            worst_r = worst_r.max(angle_f64(q, dq));
            // The trait view reads the same bytes.
            assert_eq!(Samples::sample(&t, i, s), Some((dp, dq)));
        }
    }
    println!(
        "round trip: max position error {:.4} mm, max rotation error {:.5}°",
        worst_p * 1e3,
        worst_r.to_degrees()
    );
    assert!(worst_p <= pos_bound, "{worst_p} > {pos_bound}");
    assert!(worst_r <= rot_bound, "{worst_r} > {rot_bound}");
    assert_eq!(t.sample(60, 0), None);
    assert_eq!(t.sample(0, 31), None);
    assert_eq!(t.sample(usize::MAX, 0), None);
    assert_eq!(Samples::sample_count(&t), 60);
    assert_eq!(Samples::segment_count(&t), 31);
}

/// The grid built from the table reads the quantized samples straight from
/// the blob: at a valid grid point it returns the decoded sample bit for bit.
#[test]
fn grid_query_reads_samples_in_place() {
    let mut rng = Rng(11);
    let mut spec = random_grid(&mut rng, 4, 1.0);
    spec.valid = vec![true; 30];
    let bytes = blob::write(&spec).unwrap();
    let t = Table::parse(&bytes).unwrap();
    let grid = t.grid().unwrap();
    assert_eq!(grid.sample_count(), 60);
    assert_eq!(grid.cell_count(), 30);
    // Grid point (1, 2, 3): -0.4 + 0.2, 0.8 + 0.5, 3·0.4π; index 1 + 4·(2 + 3·3).
    let q = grid
        .query(&[-0.2, 1.3, 1.2 * std::f32::consts::PI])
        .unwrap();
    for s in 0..4 {
        let got = q.segment(&t, s).unwrap();
        let want = t.sample(1 + 4 * (2 + 3 * 3), s).unwrap();
        assert!(position_error(got.0, want.0) < 1e-6, "{got:?} {want:?}");
        assert!(angle_f64(got.1, want.1) < 1e-5, "{got:?} {want:?}");
    }
    // The validity mask travels with the grid.
    spec.valid = (0..30).map(|c| c != 0).collect();
    let bytes = blob::write(&spec).unwrap();
    let t = Table::parse(&bytes).unwrap();
    let grid = t.grid().unwrap();
    assert!(!grid.cell_valid(0) && grid.cell_valid(1));
}

/// Synthesis reads the quantized samples in place exactly as it reads the
/// same samples decoded into memory: the same bits, on the host's blocks and
/// on the Cortex-M's one-segment-at-a-time path, for a three-linear-axis
/// table (the hand grid's own tree) and the pedal layout with its mask.
#[test]
fn grid_pose_from_the_blob_equals_pose_from_decoded_samples() {
    use marionette_core::grid::SliceSamples;
    use marionette_core::pose::Pose;
    let mut rng = Rng(17);
    let pedal = random_grid(&mut rng, 31, 1.5);
    let mut hand = random_grid(&mut rng, 31, 1.5);
    hand.axes[2] = axis("hand_z", -0.2, 0.1, 5, Wrap::Bounded, Interp::Linear);
    hand.valid = vec![true; 3 * 2 * 4];
    for spec in [hand, pedal] {
        let bytes = blob::write(&spec).unwrap();
        let t = Table::parse(&bytes).unwrap();
        let grid = t.grid().unwrap();
        let (mut p, mut q) = (Vec::new(), Vec::new());
        for i in 0..t.grid_samples() {
            for s in 0..31 {
                let (dp, dq) = t.sample(i, s).unwrap();
                p.push(dp);
                q.push(dq);
            }
        }
        let decoded = SliceSamples::new(31, &p, &q).unwrap();
        let bits = |o: &Pose<31>| {
            let pos = o
                .positions
                .iter()
                .flat_map(|v| v.to_array().map(f32::to_bits));
            let rot = o
                .rotations
                .iter()
                .flat_map(|q| q.to_array().map(f32::to_bits));
            pos.chain(rot).collect::<Vec<u32>>()
        };
        let (mut a, mut b) = (Pose::<31>::default(), Pose::<31>::default());
        for _ in 0..300 {
            let params: Vec<f32> = t
                .axes()
                .iter()
                .map(|ax| {
                    let span = f64::from(ax.step) * f64::from(ax.count);
                    rng.range(f64::from(ax.min) - 0.1, f64::from(ax.min) + span) as f32
                })
                .collect();
            let query = grid.query(&params).unwrap();
            query.pose(&decoded, &mut a).unwrap();
            query.pose(&t, &mut b).unwrap();
            assert_eq!(bits(&a), bits(&b), "{params:?}");
            query.pose_scalar(&t, &mut b).unwrap();
            assert_eq!(bits(&a), bits(&b), "scalar, {params:?}");
        }
    }
}

#[test]
fn clip_table_round_trip() {
    let mut rng = Rng(3);
    // 3 slopes × 2 speeds, each a looping 8-frame clip with 2 phases (cyclic phase axis, period 2).
    let axes = vec![
        axis("slope", 0.0, 0.1, 3, Wrap::Bounded, Interp::Linear),
        axis("speed", 1.0, 0.5, 2, Wrap::Bounded, Interp::Linear),
        axis(
            "phase",
            0.0,
            0.25,
            8,
            Wrap::Cyclic { period: 2.0 },
            Interp::CatmullRom,
        ),
    ];
    let samples: Vec<Vec<(Vec3, Quat)>> = (0..3 * 2 * 8)
        .map(|_| {
            (0..2)
                .map(|_| {
                    (
                        Vec3::new(rng.range(-3.0, 3.0) as f32, 0.9, 0.0),
                        q32(rng.quat()),
                    )
                })
                .collect()
        })
        .collect();
    let durations: Vec<f32> = (0..3 * 2 * 2).map(|i| 0.5 + i as f32 * 0.125).collect();
    let spec = TableSpec {
        rig_hash: 1,
        kind: Kind::Clips { phases: 2 },
        axes,
        segment_names: vec!["hips".into(), "a_segment_name_24_bytes!".into()],
        samples: samples.clone(),
        valid: vec![true, false],
        durations: durations.clone(),
        travel: (0..6).map(|i| [0.1 * i as f32, 0.02, 1.0]).collect(),
    };
    let bytes = blob::write(&spec).unwrap();
    let t = Table::parse(&bytes).unwrap();
    assert_eq!(t.kind(), Kind::Clips { phases: 2 });
    assert_eq!(
        (t.grid_samples(), t.param_samples(), t.param_cells()),
        (48, 6, 2)
    );
    assert_eq!(t.param_axes().len(), 2);
    assert_eq!(t.segment_name(1), Some("a_segment_name_24_bytes!"));
    assert_eq!(
        (t.cell_valid(0), t.cell_valid(1), t.cell_valid(2)),
        (Some(true), Some(false), None)
    );
    for p in 0..6 {
        for ph in 0..2 {
            assert_eq!(t.duration(p, ph), Some(durations[p * 2 + ph]));
        }
        assert_eq!(t.duration(p, 2), None);
        assert_eq!(t.travel(p), Some(Vec3::new(0.1 * p as f32, 0.02, 1.0)));
    }
    assert_eq!((t.duration(6, 0), t.travel(6)), (None, None));
    for (i, poses) in samples.iter().enumerate() {
        for (s, &(p, q)) in poses.iter().enumerate() {
            let (dp, dq) = t.sample(i, s).unwrap();
            assert!(position_error(p, dp) <= f64::from(t.header().position_bound));
            assert!(angle_f64(q, dq) <= f64::from(quant::ROTATION_BOUND));
        }
    }
    let pg = t.param_grid().unwrap();
    assert_eq!((pg.sample_count(), pg.cell_count()), (6, 2));
    assert!(pg.cell_valid(0) && !pg.cell_valid(1));
    assert_eq!(t.grid().unwrap().sample_count(), 48);
}

#[test]
fn writer_rejects_bad_specs() {
    let mut rng = Rng(5);
    let good = random_grid(&mut rng, 2, 1.0);
    assert!(blob::write(&good).is_ok());
    let check = |f: &dyn Fn(&mut TableSpec), want: &dyn Fn(&BlobError) -> bool| {
        let mut s = good.clone();
        f(&mut s);
        let e = blob::write(&s).unwrap_err();
        assert!(want(&e), "{e:?}");
        assert!(!e.to_string().is_empty());
    };
    check(&|s| s.axes.clear(), &|e| {
        matches!(e, BlobError::AxisCount(0))
    });
    check(&|s| s.axes[0].step = 0.0, &|e| {
        matches!(e, BlobError::Axis { index: 0, .. })
    });
    check(&|s| s.axes[1].count = 1, &|e| {
        matches!(e, BlobError::Axis { index: 1, .. })
    });
    check(&|s| s.axes[2].wrap = Wrap::Cyclic { period: 6.0 }, &|e| {
        matches!(e, BlobError::Axis { index: 2, .. })
    });
    check(&|s| s.axes[0].name = "x".repeat(NAME_LEN + 1), &|e| {
        matches!(e, BlobError::Name(_))
    });
    check(&|s| s.segment_names[0] = "a\0b".into(), &|e| {
        matches!(e, BlobError::Name(_))
    });
    check(&|s| s.samples.pop().map(drop).unwrap(), &|e| {
        matches!(
            e,
            BlobError::SampleCount {
                expected: 60,
                found: 59
            }
        )
    });
    check(&|s| s.samples[5].pop().map(drop).unwrap(), &|e| {
        matches!(e, BlobError::SampleSegments { sample: 5, .. })
    });
    check(&|s| s.samples[2][1].0.x = f32::NAN, &|e| {
        matches!(
            e,
            BlobError::BadSample {
                sample: 2,
                segment: 1
            }
        )
    });
    check(
        &|s| s.samples[2][1].1 = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        &|e| matches!(e, BlobError::BadSample { .. }),
    );
    check(&|s| s.samples[9][0].0.y = -33.0, &|e| {
        matches!(e, BlobError::PositionRange { .. })
    });
    check(&|s| s.valid.push(true), &|e| {
        matches!(
            e,
            BlobError::ValidCount {
                expected: 30,
                found: 31
            }
        )
    });
    check(&|s| s.durations.push(1.0), &|e| {
        matches!(e, BlobError::Durations { expected: 0, .. })
    });
    check(&|s| s.kind = Kind::Clips { phases: 1 }, &|e| {
        matches!(e, BlobError::Axis { index: 2, .. })
    });
    check(&|s| s.segment_names.clear(), &|e| {
        matches!(e, BlobError::SegmentCount(0))
    });
}

// ---------------------------------------------------------------------------
// Exact bytes of a tiny blob

/// One bounded axis "x" (min 0, step 0.5, 2 samples), one segment "root",
/// rig hash 0x1234. Sample 0: origin, identity. Sample 1: (1, −0.25, 0) m,
/// 180° about X.
fn tiny_spec() -> TableSpec {
    TableSpec {
        rig_hash: 0x1234,
        kind: Kind::Grid,
        axes: vec![axis("x", 0.0, 0.5, 2, Wrap::Bounded, Interp::Linear)],
        segment_names: vec!["root".into()],
        samples: vec![
            vec![(Vec3::ZERO, Quat::IDENTITY)],
            vec![(
                Vec3::new(1.0, -0.25, 0.0),
                Quat::from_xyzw(1.0, 0.0, 0.0, 0.0),
            )],
        ],
        valid: vec![true],
        durations: vec![],
        travel: vec![],
    }
}

/// Every byte of the tiny blob derived by hand from the documented format
/// (postcard: varints, raw `u8`, `f32` LE; arrays LE; CRC at the end). The
/// three header floats depend on the scale choice and are checked apart.
#[test]
fn tiny_blob_exact_bytes() {
    let bytes = blob::write(&tiny_spec()).unwrap();
    // Header: total 2 + rig 2 + kind 1 + axis_count 1 + 6 axes × 35 + segment_count 1
    // + names 1 + 24 + floats 12 + spans 4 × 3 = 266 bytes; data start align4(10 + 266) = 276;
    // samples 276..300, valid 300..301, durations and travel at 304 (empty), CRC 304..308.
    assert_eq!(bytes.len(), 308);
    let mut want: Vec<u8> = Vec::new();
    want.extend_from_slice(b"MRNT");
    want.extend_from_slice(&[0x02, 0x00]); // version 2
    want.extend_from_slice(&[0x0A, 0x01, 0x00, 0x00]); // header length 266 = 0x10A
    want.extend_from_slice(&[0xB4, 0x02]); // total_len 308 = 0b10_0110100
    want.extend_from_slice(&[0xB4, 0x24]); // rig_hash 0x1234 = 4660 = 36·128 + 52
    want.push(0x00); // kind Grid
    want.push(0x01); // axis_count
    want.push(b'x');
    want.extend_from_slice(&[0; NAME_LEN - 1]);
    want.extend_from_slice(&[0x00, 0x00, 0x00, 0x00]); // min 0.0
    want.extend_from_slice(&[0x00, 0x00, 0x00, 0x3F]); // step 0.5
    want.extend_from_slice(&[0x02, 0x00, 0x00]); // count 2, Bounded, Linear
    want.extend_from_slice(&[0; 5 * 35]); // 5 unused axes
    want.push(0x01); // segment_count
    want.push(24); // names length
    want.extend_from_slice(b"root");
    want.extend_from_slice(&[0; NAME_LEN - 4]);
    let floats_at = want.len();
    want.extend_from_slice(&bytes[floats_at..floats_at + 12]); // checked below
    want.extend_from_slice(&[0x94, 0x02, 24]); // samples: offset 276, len 24
    want.extend_from_slice(&[0xAC, 0x02, 1]); // valid: offset 300, len 1
    want.extend_from_slice(&[0xB0, 0x02, 0]); // durations: offset 304, len 0
    want.extend_from_slice(&[0xB0, 0x02, 0]); // travel: offset 304, len 0
    assert_eq!(want.len(), 276); // no padding: 276 is 4-aligned
    // Sample 0: (0, 0, 0), identity: w dropped, x = y = z = code 16383.
    want.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0xFC, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F]);
    // Sample 1: codes 32767 (1 m is the largest coordinate), −8192 (−0.25 m ≈ −8191.75 LSB), 0;
    // 180° about X: index 1, w = y = z = code 16383.
    want.extend_from_slice(&[
        0xFF, 0x7F, 0x00, 0xE0, 0x00, 0x00, 0xFD, 0xFF, 0xFE, 0x7F, 0xFF, 0x3F,
    ]);
    want.push(0x01); // validity: cell 0 valid
    want.extend_from_slice(&[0; 3]); // padding to 304
    assert_eq!(&bytes[..304], &want[..]);
    assert_eq!(&bytes[304..], &crc32(&want).to_le_bytes());

    // The floats: scale ≈ 1 m / 32767, position bound 0.51 · scale, rotation bound.
    let f = |i: usize| {
        f32::from_le_bytes(
            bytes[floats_at + 4 * i..floats_at + 4 * i + 4]
                .try_into()
                .unwrap(),
        )
    };
    let scale = f(0);
    assert!((f64::from(scale) * 32767.0 - 1.0).abs() < 1e-6, "{scale}");
    assert!(1.0 / scale <= 32767.0);
    assert_eq!(f(1), scale * 0.51);
    assert_eq!(f(2), 1.75e-4);
}

/// A version 1 blob (no travel span) is still read in place: the tiny blob
/// rewritten by hand as version 1 (header 3 bytes shorter, same data start).
#[test]
fn version_1_blob_is_still_read() {
    let v2 = blob::write(&tiny_spec()).unwrap();
    let mut v1: Vec<u8> = Vec::new();
    v1.extend_from_slice(b"MRNT");
    v1.extend_from_slice(&[0x01, 0x00]);
    v1.extend_from_slice(&263u32.to_le_bytes());
    v1.extend_from_slice(&v2[10..10 + 263]); // every field up to `durations`
    v1.extend_from_slice(&[0; 3]); // padding to 276
    v1.extend_from_slice(&v2[276..304]); // samples, mask, padding
    let crc = crc32(&v1);
    v1.extend_from_slice(&crc.to_le_bytes());
    let (a, b) = (Table::parse(&v1).unwrap(), Table::parse(&v2).unwrap());
    assert_eq!(a.len(), 308);
    assert_eq!(
        (a.sample(1, 0), a.cell_valid(0)),
        (b.sample(1, 0), b.cell_valid(0))
    );
    assert_eq!(a.travel(0), None);
    // Version 3 is not read.
    let mut v3 = v2.clone();
    v3[4] = 3;
    assert_eq!(
        Table::parse(&v3).unwrap_err(),
        TableError::BadVersion { found: 3 }
    );
}

/// A looping clip table's travel round-trips through the writer and the
/// in-place reader, and its bytes sit where the header says.
#[test]
fn looping_travel_round_trips() {
    let axes = vec![
        axis("slope", 0.0, 1.0, 2, Wrap::Bounded, Interp::Linear),
        axis(
            "phase",
            0.0,
            0.5,
            2,
            Wrap::Cyclic { period: 1.0 },
            Interp::Linear,
        ),
    ];
    let spec = TableSpec {
        rig_hash: 5,
        kind: Kind::Clips { phases: 1 },
        axes,
        segment_names: vec!["hips".into()],
        samples: vec![vec![(Vec3::ZERO, Quat::IDENTITY)]; 4],
        valid: vec![true],
        durations: vec![1.0, 1.5],
        travel: vec![[0.0, 0.1, 0.9], [-0.25, 0.2, 1.5]],
    };
    let bytes = blob::write(&spec).unwrap();
    let t = Table::parse(&bytes).unwrap();
    assert_eq!(t.travel(0), Some(Vec3::new(0.0, 0.1, 0.9)));
    assert_eq!(t.travel(1), Some(Vec3::new(-0.25, 0.2, 1.5)));
    assert_eq!(t.travel(2), None);
    // The last 12 bytes before the CRC are sample 1's travel, f32 LE.
    let end = bytes.len() - 4;
    let want: Vec<u8> = [-0.25f32, 0.2, 1.5]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    assert_eq!(&bytes[end - 12..end], &want[..]);
    // Wrong count or a bounded phase with travel is refused by the writer.
    let mut short = spec.clone();
    short.travel.pop();
    let travel_error = |s: &TableSpec| matches!(blob::write(s), Err(BlobError::Travel { .. }));
    assert!(travel_error(&short));
    let mut bounded = spec;
    bounded.axes[1] = axis("phase", 0.0, 1.0, 2, Wrap::Bounded, Interp::Linear);
    assert!(travel_error(&bounded));
    bounded.travel.clear();
    assert!(blob::write(&bounded).is_ok());
}

// ---------------------------------------------------------------------------
// Corruption

#[test]
fn every_bit_flip_is_an_error() {
    let bytes = blob::write(&tiny_spec()).unwrap();
    for i in 0..bytes.len() * 8 {
        let mut b = bytes.clone();
        b[i / 8] ^= 1 << (i % 8);
        assert!(Table::parse(&b).is_err(), "bit {i} flipped was accepted");
    }
    // A larger blob as well (the flips inside the sample array).
    let mut rng = Rng(9);
    let bytes = blob::write(&random_grid(&mut rng, 2, 0.5)).unwrap();
    for i in (0..bytes.len() * 8).step_by(3) {
        let mut b = bytes.clone();
        b[i / 8] ^= 1 << (i % 8);
        assert!(Table::parse(&b).is_err(), "bit {i} flipped was accepted");
    }
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = blob::write(&tiny_spec()).unwrap();
    for n in 0..bytes.len() {
        assert!(Table::parse(&bytes[..n]).is_err(), "length {n}");
    }
    assert_eq!(Table::parse(&[]).unwrap_err(), TableError::Truncated);
    assert_eq!(
        Table::parse(&bytes[..9]).unwrap_err(),
        TableError::Truncated
    );
    assert_eq!(
        Table::parse(&bytes[..100]).unwrap_err(),
        TableError::Truncated
    );
    assert_eq!(
        Table::parse(&bytes[..307]).unwrap_err(),
        TableError::Truncated
    );
}

#[test]
fn trailing_flash_is_ignored() {
    let bytes = blob::write(&tiny_spec()).unwrap();
    for fill in [0xFF_u8, 0x00] {
        let mut region = bytes.clone();
        region.resize(64 * 1024, fill);
        let t = Table::parse(&region).unwrap();
        assert_eq!(t.len(), bytes.len());
        assert_eq!(t.sample(1, 0), Table::parse(&bytes).unwrap().sample(1, 0));
    }
    // Erased or empty regions are not blobs.
    assert_eq!(
        Table::parse(&[0xFF; 1024]).unwrap_err(),
        TableError::BadMagic
    );
    assert_eq!(
        Table::parse(&[0x00; 1024]).unwrap_err(),
        TableError::BadMagic
    );
}

#[test]
fn wrong_magic_and_version() {
    let bytes = blob::write(&tiny_spec()).unwrap();
    let mut b = bytes.clone();
    b[0] = b'm';
    assert_eq!(Table::parse(&b).unwrap_err(), TableError::BadMagic);
    let mut b = bytes.clone();
    b[4] = 3;
    assert_eq!(
        Table::parse(&b).unwrap_err(),
        TableError::BadVersion { found: 3 }
    );
    let mut b = bytes.clone();
    b[4..6].copy_from_slice(&0xFFFF_u16.to_le_bytes());
    assert_eq!(
        Table::parse(&b).unwrap_err(),
        TableError::BadVersion { found: 0xFFFF }
    );
    let mut b = bytes;
    b[6..10].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(Table::parse(&b).unwrap_err(), TableError::BadBounds);
}

/// Rebuilds a blob around an edited header with a correct CRC, so that the
/// checks after the CRC are reached. Arrays are copied from `base` at their
/// original offsets when they still fit.
fn reheader(base: &[u8], edit: impl Fn(&mut Header<'_>)) -> Vec<u8> {
    let t = Table::parse(base).unwrap();
    let mut h = *t.header();
    let old_start = table::align4(
        table::PREFIX_LEN + u32::from_le_bytes(base[6..10].try_into().unwrap()) as usize,
    )
    .unwrap();
    edit(&mut h);
    let mut buf = vec![0; table::MAX_HEADER_LEN];
    let n = table::encode_header(&h, &mut buf).unwrap();
    let mut out = table::prefix(n as u32).to_vec();
    out.extend_from_slice(&buf[..n]);
    out.resize(table::align4(out.len()).unwrap(), 0);
    let start = out.len();
    // Keep the arrays where the edited header says, as far as possible.
    out.extend_from_slice(&base[old_start..base.len() - 4]);
    // A total beyond 1 MB is only used to test `Truncated`: keep the arrays.
    let total = (h.total_len as usize).max(start + 4);
    if total <= 1 << 20 {
        out.resize(total - 4, 0);
    }
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

#[test]
fn bad_header_fields_after_the_crc() {
    let base = blob::write(&tiny_spec()).unwrap();
    // Sanity: an unedited rebuild parses.
    assert!(Table::parse(&reheader(&base, |_| {})).is_ok());
    #[track_caller]
    fn check(base: &[u8], edit: &dyn Fn(&mut Header<'_>), want: TableError) {
        let b = reheader(base, edit);
        assert_eq!(Table::parse(&b).unwrap_err(), want);
    }
    // Huge lengths and offsets: bounds errors, not overflow.
    check(&base, &|h| h.samples.len = u32::MAX, TableError::BadBounds);
    check(
        &base,
        &|h| h.samples.offset = u32::MAX,
        TableError::BadBounds,
    );
    check(
        &base,
        &|h| {
            h.valid = Span {
                offset: u32::MAX - 1,
                len: u32::MAX,
            }
        },
        TableError::BadBounds,
    );
    check(
        &base,
        &|h| h.durations.offset = u32::MAX,
        TableError::BadBounds,
    );
    check(&base, &|h| h.samples.offset = 0, TableError::BadBounds); // inside the header
    check(&base, &|h| h.samples.offset += 2, TableError::BadBounds); // misaligned
    // Wrong sizes.
    check(&base, &|h| h.samples.len -= 12, TableError::BadSize);
    check(&base, &|h| h.valid.len = 0, TableError::BadSize);
    check(
        &base,
        &|h| {
            h.durations = Span {
                offset: 300,
                len: 4,
            }
        },
        TableError::BadSize,
    );
    check(&base, &|h| h.durations.len = 4, TableError::BadBounds); // runs into the CRC
    // Shape.
    // (A count of one varint byte keeps the data start where it was.)
    check(&base, &|h| h.axes[0].count = 100, TableError::BadSize);
    check(
        &base,
        &|h| h.axes[0].step = f32::NAN,
        TableError::BadAxis { index: 0 },
    );
    check(
        &base,
        &|h| h.axes[0].count = 1,
        TableError::BadAxis { index: 0 },
    );
    check(&base, &|h| h.axis_count = 0, TableError::BadHeader);
    check(
        &base,
        &|h| h.axis_count = MAX_AXES as u8 + 1,
        TableError::BadHeader,
    );
    check(
        &base,
        &|h| h.kind = Kind::Clips { phases: 0 },
        TableError::BadHeader,
    );
    check(&base, &|h| h.segment_count = 2, TableError::BadHeader);
    check(&base, &|h| h.segment_count = 0, TableError::BadHeader);
    check(&base, &|h| h.position_scale = 0.0, TableError::BadHeader);
    check(
        &base,
        &|h| h.position_scale = f32::INFINITY,
        TableError::BadHeader,
    );
    // Huge axis counts overflow the sample count: a bounds error.
    check(
        &base,
        &|h| {
            h.axis_count = 6;
            h.axes = [Axis {
                count: u16::MAX,
                ..h.axes[0]
            }; MAX_AXES];
        },
        TableError::BadBounds,
    );
    // total_len: beyond the slice, too short for the CRC, before the data start.
    check(&base, &|h| h.total_len = u32::MAX, TableError::Truncated);
    let b = reheader(&base, |h| h.total_len = 3);
    assert_eq!(Table::parse(&b).unwrap_err(), TableError::BadBounds);
}

#[test]
fn header_encoding_errors() {
    let base = blob::write(&tiny_spec()).unwrap();
    // Header length one byte short / long: postcard fails or leaves bytes.
    let mut b = base.clone();
    b[6] -= 1;
    assert_eq!(Table::parse(&b).unwrap_err(), TableError::BadHeader);
    let mut b = base.clone();
    b[6] += 1;
    assert_eq!(Table::parse(&b).unwrap_err(), TableError::BadHeader);
    // A header that does not fit the buffer.
    let h = *Table::parse(&base).unwrap().header();
    assert_eq!(
        table::encode_header(&h, &mut [0; 16]).unwrap_err(),
        TableError::BufferFull
    );
}

/// Random bytes after a valid prefix, and random multi-byte corruption of a
/// valid blob, never panic.
#[test]
fn random_garbage_never_panics() {
    let base = blob::write(&tiny_spec()).unwrap();
    let mut rng = Rng(42);
    for _ in 0..20_000 {
        let mut b = base.clone();
        for _ in 0..1 + rng.next_u64() % 8 {
            let i = (rng.next_u64() % b.len() as u64) as usize;
            b[i] = rng.next_u64() as u8;
        }
        let _ = Table::parse(&b);
        let n = (rng.next_u64() % 400) as usize;
        let mut g: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
        if g.len() >= 10 {
            g[..4].copy_from_slice(b"MRNT");
            g[4..6].copy_from_slice(&[1, 0]);
        }
        let _ = Table::parse(&g);
    }
}
