//! Host benchmarks for pose synthesis: a 31-segment trilinear grid pose
//! (3 linear axes, 8-sample window, 7 slerps + 7 lerps per segment) with the
//! core's fast slerp, against the same tree built from glam's `Quat::slerp`
//! and `Vec3::lerp`, plus the W&H pedalling layout (2 linear axes and a cyclic
//! Catmull-Rom axis) and the query alone. Throughput is reported per pose
//! (criterion's `elem/s` is poses per second).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Quat, Vec3};
use marionette_core::grid::{Axis, Grid, Interp, SliceSamples, Wrap};
use marionette_core::pose::Pose;

const SEGMENTS: usize = 31;

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn samples(count: usize, rng: &mut Lcg) -> (Vec<Vec3>, Vec<Quat>) {
    let n = count * SEGMENTS;
    let p = (0..n)
        .map(|_| Vec3::new(rng.next(), rng.next(), rng.next()))
        .collect();
    let q = (0..n)
        .map(|_| {
            Quat::from_xyzw(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5, 1.0).normalize()
        })
        .collect();
    (p, q)
}

/// The baseline: the same window and tree with glam's slerp (libm sin/acos).
fn glam_tree(
    p: &[Vec3],
    q: &[Quat],
    base: [usize; 3],
    strides: [usize; 3],
    t: [f32; 3],
    out: &mut Pose<32>,
) {
    out.count = SEGMENTS;
    for seg in 0..SEGMENTS {
        let mut ps = [Vec3::ZERO; 8];
        let mut qs = [Quat::IDENTITY; 8];
        for (j, (pp, qq)) in ps.iter_mut().zip(qs.iter_mut()).enumerate() {
            let idx = (base[0] + (j & 1)) * strides[0]
                + (base[1] + (j >> 1 & 1)) * strides[1]
                + (base[2] + (j >> 2)) * strides[2];
            *pp = p[idx * SEGMENTS + seg];
            *qq = q[idx * SEGMENTS + seg];
        }
        let mut len = 8;
        for &ta in &t {
            len /= 2;
            for i in 0..len {
                ps[i] = ps[2 * i].lerp(ps[2 * i + 1], ta);
                qs[i] = qs[2 * i].slerp(qs[2 * i + 1], ta);
            }
        }
        out.positions[seg] = ps[0];
        out.rotations[seg] = qs[0];
    }
}

fn bench(c: &mut Criterion) {
    let mut rng = Lcg(42);
    let axes = [
        Axis::linear(-0.4, 0.1, 9),
        Axis::linear(0.6, 0.1, 9),
        Axis::linear(0.1, 0.1, 9),
    ];
    let grid = Grid::new(&axes, None).expect("grid");
    let (p, q) = samples(grid.sample_count(), &mut rng);
    let src = SliceSamples::new(SEGMENTS, &p, &q).expect("samples");
    let params: Vec<[f32; 3]> = (0..256)
        .map(|_| {
            [
                -0.4 + 0.8 * rng.next(),
                0.6 + 0.8 * rng.next(),
                0.1 + 0.8 * rng.next(),
            ]
        })
        .collect();
    let mut out = Pose::<32>::default();

    let mut group = c.benchmark_group("trilinear_31seg");
    group.throughput(Throughput::Elements(1));
    let mut i = 0usize;
    group.bench_function("core_fast_slerp", |b| {
        b.iter(|| {
            i = (i + 1) % params.len();
            grid.synthesize(&src, black_box(&params[i]), &mut out)
                .expect("synth");
            black_box(&out);
        })
    });

    let mut i = 0usize;
    group.bench_function("glam_slerp_baseline", |b| {
        b.iter(|| {
            i = (i + 1) % params.len();
            let x = black_box(params[i]);
            let mut base = [0usize; 3];
            let mut t = [0f32; 3];
            for a in 0..3 {
                let u =
                    ((x[a] - axes[a].min) / axes[a].step).clamp(0.0, (axes[a].count - 1) as f32);
                let k = (u.floor() as usize).min(axes[a].count as usize - 2);
                base[a] = k;
                t[a] = u - k as f32;
            }
            glam_tree(&p, &q, base, [1, 9, 81], t, &mut out);
            black_box(&out);
        })
    });

    let mut i = 0usize;
    group.bench_function("query_only", |b| {
        b.iter(|| {
            i = (i + 1) % params.len();
            black_box(grid.query(black_box(&params[i])).expect("query"));
        })
    });
    group.finish();

    // W&H pedalling: cylindrical axis x, radius r (linear), angle (cyclic Catmull-Rom).
    let tau = std::f32::consts::TAU;
    let pedal_axes = [
        Axis::linear(-0.1, 0.1, 3),
        Axis::linear(0.1, 0.05, 3),
        Axis {
            min: 0.0,
            step: tau / 8.0,
            count: 8,
            wrap: Wrap::Cyclic { period: tau },
            interp: Interp::CatmullRom,
        },
    ];
    let pedal = Grid::new(&pedal_axes, None).expect("grid");
    let (pp, pq) = samples(pedal.sample_count(), &mut rng);
    let psrc = SliceSamples::new(SEGMENTS, &pp, &pq).expect("samples");
    let mut angle = 0.0f32;
    let mut group = c.benchmark_group("pedal_31seg");
    group.throughput(Throughput::Elements(1));
    group.bench_function("linear_linear_cyclic_catmull_rom", |b| {
        b.iter(|| {
            angle += 0.01;
            pedal
                .synthesize(&psrc, black_box(&[0.03, 0.17, angle]), &mut out)
                .expect("synth");
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
