//! Retargeting mocap to the rig's proportions.
//!
//! The rig is a skeleton with its own offsets (joint origins in the parent's
//! frame) and, per rig segment, the mocap segment it follows. Retargeting
//! keeps every segment's **world rotation** from the mocap and rebuilds all
//! positions by the core's forward kinematics with the **rig's offsets**:
//! the local rotation of rig segment `i` is `conj(W[parent]) · W[i]` (the
//! mocap world rotations of the mapped segments), the root is placed at the
//! mocap root position times the rig's root scale, and
//! [`marionette_core::pose::forward`] does the rest. Every limb therefore has
//! exactly the rig's length in every example (W&H's limb-length enforcement,
//! applied at the source), and the hand positions the parameters are measured
//! from are the rig's hand positions.
//!
//! The rig comes from one of:
//!
//! - **a rig file** (`[rig] file = "rigs/cmu31.toml"`, see
//!   [`crate::rigfile`]): its segments, offsets and `[retarget]` map (mocap
//!   joint → segment, with an optional `rotation_offset` applied after the
//!   mocap joint's world rotation: `W_rig = W_mocap · offset`; the file's
//!   default `[[retarget.joint]]` map, or the `[[retarget.map]]` the spec
//!   names with `[rig] retarget = "..."`, e.g. one for HDM05's ASF skeleton
//!   beside the default one for CMU BVH files). A segment
//!   with no mocap joint keeps its rest orientation relative to its parent.
//!   With `[rig] align_rest = true`, every segment whose map entry gives no
//!   `rotation_offset` gets one computed from the two rest poses: the
//!   shortest-arc rotation taking the rig's bone (towards its first mapped
//!   child) onto the mocap's bone at rest (a T-posed mocap arm onto a
//!   hanging puppet arm, the CMU thighs' 20° splay onto a straight leg).
//!   The root's path is scaled by the rig's rest hip height (`root_position`
//!   y) over the mocap skeleton's rest hip height (the drop from the root to
//!   its lowest joint with every rotation at zero). The table's rig hash is
//!   the rig file's, so the firmware can check the pairing;
//! - **the mocap skeleton itself** (no `file`), optionally scaled (`[rig]
//!   scale`, which also scales the root's path) and with per-segment length
//!   factors (`[rig] lengths`, a factor on the segment's offset from its
//!   parent). With neither, the retarget is the identity up to `f32`
//!   rounding; the rig hash is then an FNV-1a hash of the skeleton.
//!
//! Not handled: rest frames that differ between mocap and rig beyond what a
//! constant `rotation_offset` expresses, and floor contact after non-uniform
//! length changes (the root height is scaled uniformly, so feet may float or
//! sink when only the legs are lengthened).

use glam::{Quat, Vec3};
use marionette_core::pose::{self, Hierarchy, LocalPose, NO_PARENT, Pose};

use super::error::{InputError, Source};
use super::spec::{NameMap, RigSpec};
use crate::import::CoreSkeleton;
use crate::rigfile::RigFile;
use marionette_core::table::NAME_LEN;

/// Segment capacity of the poses used while building (the blob's limit).
pub const CAP: usize = 256;

/// The most segments a rig made from a skeleton may have (the core's pose
/// capacity, which the solver and the board work within).
pub const MAX_RIG_SEGMENTS: usize = marionette_core::pose::MAX_SEGMENTS;

/// A rig: names, topology, offsets, and the mocap segment each follows.
#[derive(Debug, Clone)]
pub struct Rig {
    /// Segment names (the table's segment names).
    pub names: Vec<String>,
    /// Parents ([`NO_PARENT`] for the root).
    pub parents: Vec<u8>,
    /// Offsets in the parent's frame, metres.
    pub offsets: Vec<Vec3>,
    /// Mocap segment followed by each rig segment (`None`: rigid with the
    /// parent).
    pub source: Vec<Option<usize>>,
    /// Rotation applied after the mocap segment's world rotation.
    pub rotation_offsets: Vec<Quat>,
    /// Factor on the mocap root position.
    pub root_scale: f32,
    /// The table's rig hash.
    pub hash: u64,
    /// The rig file, if the rig came from one.
    pub file: Option<Box<RigFile>>,
}

impl Rig {
    /// The mocap skeleton as a rig, scaled by `spec`; `src` locates errors
    /// in the spec, at `clip_line` (the first clip's `file`) when the spec
    /// has no `[rig]` table to point at.
    pub fn from_skeleton(
        sk: &CoreSkeleton,
        spec: &RigSpec,
        src: &Source,
        clip_line: usize,
    ) -> Result<Self, InputError> {
        let map = &spec.names;
        // Kept joints (the root always), parents first as in the skeleton.
        let kept: Vec<usize> = (0..sk.len())
            .filter(|&i| i == 0 || map.keeps(&sk.names[i]))
            .collect();
        let mut index = vec![None; sk.len()];
        for (k, &i) in kept.iter().enumerate() {
            index[i] = Some(k);
        }
        let names: Vec<String> = kept
            .iter()
            .map(|&i| map.segment_name(&sk.names[i]))
            .collect();
        check_names(&names, &sk.names, &kept, map, (src, clip_line))?;
        for name in spec.lengths.keys() {
            if !names.contains(name) {
                let field = format!("rig.lengths.{name}");
                return Err(src.error_line(
                    spec.line,
                    &field,
                    format!("no segment {name:?} in the rig"),
                ));
            }
        }
        let scale = spec.scale as f32;
        let mut parents = Vec::with_capacity(kept.len());
        let mut offsets = Vec::with_capacity(kept.len());
        for (&i, name) in kept.iter().zip(&names) {
            // Up to the nearest kept ancestor, summing the rest offsets of
            // the dropped joints between (rest rotations are zero).
            let (mut offset, mut at) = (sk.offsets[i], usize::from(sk.parents[i]));
            let parent = loop {
                match (at, index.get(at).copied().flatten()) {
                    (_, Some(k)) => break u8::try_from(k).unwrap_or(NO_PARENT),
                    (a, None) if a < sk.len() => {
                        offset += sk.offsets[a];
                        at = usize::from(sk.parents[a]);
                    }
                    _ => break NO_PARENT,
                }
            };
            parents.push(if i == 0 { NO_PARENT } else { parent });
            offsets.push(offset * scale * spec.lengths.get(name).map_or(1.0, |&f| f as f32));
        }
        let mut rig = Self {
            names,
            parents,
            offsets,
            source: kept.iter().map(|&i| Some(i)).collect(),
            rotation_offsets: vec![Quat::IDENTITY; kept.len()],
            root_scale: scale,
            hash: 0,
            file: None,
        };
        rig.hash = rig.skeleton_hash();
        Ok(rig)
    }

    /// The rig of a rig file, driven by the mocap skeleton `sk` through the
    /// file's retarget map; `src` and `line` locate errors in the spec.
    pub fn from_rigfile(
        file: RigFile,
        sk: &CoreSkeleton,
        src: &Source,
        spec: &RigSpec,
    ) -> Result<Self, InputError> {
        let line = spec.line;
        let desc = file.desc();
        let n = desc.segments.len();
        let mut source = vec![None; n];
        let mut rotation_offsets = vec![Quat::IDENTITY; n];
        let Some(map) = file.retarget_map(spec.retarget.as_deref()) else {
            let names: Vec<&str> = file.retarget_maps.iter().map(|m| m.name.as_str()).collect();
            let problem = format!(
                "{}: no [[retarget.map]] named {:?} (the file has: {})",
                file.file,
                spec.retarget.as_deref().unwrap_or_default(),
                if names.is_empty() {
                    "none".to_owned()
                } else {
                    names.join(", ")
                }
            );
            return Err(src.error_line(line, "rig.retarget", problem));
        };
        for r in map {
            let Some(j) = sk.index_of(&r.mocap) else {
                let seg = file
                    .segment_names()
                    .get(usize::from(r.segment))
                    .cloned()
                    .unwrap_or_default();
                let problem = format!(
                    "{}: the retarget map drives {seg:?} from mocap joint {:?}, which the mocap skeleton does not have",
                    file.file, r.mocap
                );
                return Err(src.error_line(line, "rig.file", problem));
            };
            let i = usize::from(r.segment);
            if i < n {
                source[i] = Some(j);
                let [w, x, y, z] = r.rotation_offset.map(|c| c as f32);
                rotation_offsets[i] = Quat::from_xyzw(x, y, z, w).normalize();
            }
        }
        if source.first().is_none_or(Option::is_none) {
            let problem = format!(
                "{}: the retarget map must drive the root segment",
                file.file
            );
            return Err(src.error_line(line, "rig.file", problem));
        }
        let parents: Vec<u8> = desc.segments.iter().map(|s| s.parent).collect();
        let offsets: Vec<Vec3> = desc
            .segments
            .iter()
            .map(|s| Vec3::from_array(s.origin))
            .collect();
        let touches: Vec<Vec3> = desc
            .segments
            .iter()
            .map(|s| Vec3::from_array(s.touch))
            .collect();
        if spec.align_rest {
            let given: Vec<bool> = rotation_offsets
                .iter()
                .map(|q| *q != Quat::IDENTITY)
                .collect();
            for (i, auto) in align_rest(sk, &parents, &offsets, &touches, &source)
                .into_iter()
                .enumerate()
            {
                if let (false, Some(q)) = (given[i], auto) {
                    rotation_offsets[i] = q;
                }
            }
        }
        let rig_height = desc.root_position[1];
        let mocap_height = rest_height(sk);
        let root_scale = if rig_height > 0.0 && mocap_height > 1e-3 {
            rig_height / mocap_height
        } else {
            1.0
        };
        Ok(Self {
            names: file.segment_names().to_vec(),
            parents,
            offsets,
            source,
            rotation_offsets,
            root_scale,
            hash: file.rig_hash(),
            file: Some(Box::new(file)),
        })
    }

    /// The rest placement of the root (position, rotation): the rig file's
    /// `root_position` and `root_rotation`, or the origin without a file.
    #[must_use]
    pub fn rest_root(&self) -> (glam::DVec3, glam::DQuat) {
        let Some(file) = &self.file else {
            return (glam::DVec3::ZERO, glam::DQuat::IDENTITY);
        };
        let desc = file.desc();
        let [w, x, y, z] = desc.root_rotation.map(f64::from);
        (
            Vec3::from_array(desc.root_position).as_dvec3(),
            glam::DQuat::from_xyzw(x, y, z, w).normalize(),
        )
    }

    /// The rig's hierarchy.
    #[must_use]
    pub fn hierarchy(&self) -> Hierarchy<'_> {
        Hierarchy {
            parents: &self.parents,
            offsets: &self.offsets,
        }
    }

    /// Index of a segment.
    #[must_use]
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// A 64-bit FNV-1a hash of the skeleton (names, parents, offset bits):
    /// the rig hash of a rig without a rig file.
    #[must_use]
    pub fn skeleton_hash(&self) -> u64 {
        let mut h = Fnv::new();
        for ((n, &p), o) in self.names.iter().zip(&self.parents).zip(&self.offsets) {
            h.bytes(n.as_bytes());
            h.bytes(&[0, p]);
            for c in o.to_array() {
                h.bytes(&c.to_bits().to_le_bytes());
            }
        }
        h.0
    }

    /// Retargets a mocap world pose (see the module doc) into `out`.
    pub fn retarget(&self, mocap: &Pose<CAP>, out: &mut Pose<CAP>) -> Result<(), pose::PoseError> {
        let n = self.names.len();
        let mut local = LocalPose::<CAP>::new(n)?;
        // World rotations of the rig's segments, parents first.
        let mut world = vec![Quat::IDENTITY; n];
        for i in 0..n {
            let parent = self.parents.get(i).copied().unwrap_or(NO_PARENT);
            let inherited = world
                .get(usize::from(parent))
                .copied()
                .unwrap_or(Quat::IDENTITY);
            world[i] = match self.source[i].and_then(|s| mocap.rotations().get(s)) {
                Some(&w) => w * self.rotation_offsets[i],
                None => inherited,
            };
            local.rotations[i] = if parent == NO_PARENT {
                world[i]
            } else {
                inherited.conjugate() * world[i]
            };
        }
        let root = self.source[0]
            .and_then(|s| mocap.positions().get(s))
            .copied();
        local.root_position = root.unwrap_or(Vec3::ZERO) * self.root_scale;
        pose::forward(&self.hierarchy(), &local, out)
    }
}

/// The segment names a table can hold: at most [`MAX_RIG_SEGMENTS`], each at
/// most 24 bytes without NUL, no two alike. Errors name the `[rig]` field
/// that shapes them, or the first clip's `file` (at `at.1`) when the spec
/// has no `[rig]` table, and say which rule to add. `joints` are the
/// skeleton's names, `kept` the joints `names` come from.
fn check_names(
    names: &[String],
    joints: &[String],
    kept: &[usize],
    map: &NameMap,
    at: (&Source, usize),
) -> Result<(), InputError> {
    let (src, clip_line) = at;
    let no_rig = map.lines == [0; 4];
    let place = |line: usize, field: &'static str| {
        if no_rig {
            (clip_line, "clip[0].file".to_owned(), " in a [rig] table")
        } else {
            (line, field.to_owned(), "")
        }
    };
    let [strip, rename, drop, _] = map.lines;
    if names.len() > MAX_RIG_SEGMENTS {
        let (line, field, table) = place(drop, "rig.drop");
        return Err(src.error_line(
            line,
            &field,
            format!(
                "the skeleton gives {} segments; a table holds at most {MAX_RIG_SEGMENTS}: drop joints{table} (`drop = [\"*Twist*\", ...]` or `keep = [...]`)",
                names.len()
            ),
        ));
    }
    if let Some(k) = names
        .iter()
        .position(|n| n.len() > NAME_LEN || n.contains('\0'))
    {
        let long = &names[k];
        let joint = kept.get(k).and_then(|&j| joints.get(j)).unwrap_or(long);
        let (line, field, table) = if map.strip_prefix.is_none() {
            place(strip, "rig.strip_prefix")
        } else {
            place(rename, "rig.rename")
        };
        let prefix = common_prefix(joints);
        let strip_hint = if map.strip_prefix.is_none() && !prefix.is_empty() {
            format!("`strip_prefix = {prefix:?}` (every joint starts with it), or ")
        } else {
            String::new()
        };
        return Err(src.error_line(
            line,
            &field,
            format!(
                "joint {joint:?} gives segment name {long:?}, longer than {NAME_LEN} bytes: add{table} {strip_hint}`rename = {{ {} = \"short_name\" }}`, or drop it (`drop = [{:?}]`)",
                map.stripped(joint),
                map.stripped(joint)
            ),
        ));
    }
    for (k, n) in names.iter().enumerate() {
        if names[..k].contains(n) {
            let (line, field, table) = place(rename, "rig.rename");
            return Err(src.error_line(
                line,
                &field,
                format!("two segments are named {n:?}: rename one{table}"),
            ));
        }
    }
    Ok(())
}

/// The longest prefix of every name in `names` that ends in `_` (or is
/// empty).
fn common_prefix(names: &[String]) -> String {
    let Some(first) = names.first() else {
        return String::new();
    };
    let mut len = first.len();
    for n in names {
        len = first
            .bytes()
            .zip(n.bytes())
            .take(len)
            .take_while(|(a, b)| a == b)
            .count();
    }
    let head = first.get(..len).unwrap_or("");
    head.rfind('_')
        .and_then(|i| head.get(..=i))
        .unwrap_or("")
        .to_owned()
}

/// Rest-pose alignment (`[rig] align_rest`): for each non-root rig segment
/// with a mocap joint, the shortest-arc rotation taking the rig's rest bone
/// direction onto the mocap's (all rotations zero). The bone runs to the
/// segment's first child that has a mocap joint (rig: the child's offset;
/// mocap: between the two joints); a rig leaf uses its touch point, and the
/// mocap joint's first child. With it as the rotation offset,
/// `W_mocap · offset` points the rig bone where the mocap bone points (the
/// twist about the bone is taken as zero).
fn align_rest(
    sk: &CoreSkeleton,
    parents: &[u8],
    offsets: &[Vec3],
    touches: &[Vec3],
    source: &[Option<usize>],
) -> Vec<Option<Quat>> {
    let mut rest = vec![Vec3::ZERO; sk.len()];
    for i in 1..sk.len() {
        rest[i] = rest
            .get(usize::from(sk.parents[i]))
            .copied()
            .unwrap_or(Vec3::ZERO)
            + sk.offsets[i];
    }
    let mocap_child = |j: usize| (j + 1..sk.len()).find(|&c| usize::from(sk.parents[c]) == j);
    (0..parents.len())
        .map(|i| {
            if parents[i] == NO_PARENT {
                return None;
            }
            let me = source[i]?;
            let child = (i + 1..parents.len())
                .find(|&j| usize::from(parents[j]) == i && source[j].is_some());
            let (d_rig, to) = match child {
                Some(c) => (offsets[c], source[c]?),
                None => (touches[i], mocap_child(me)?),
            };
            let d_rig = d_rig.as_dvec3().normalize_or_zero();
            let d_mocap = (rest[to] - rest[me]).as_dvec3().normalize_or_zero();
            if d_rig == glam::DVec3::ZERO || d_mocap == glam::DVec3::ZERO {
                return None;
            }
            Some(glam::DQuat::from_rotation_arc(d_rig, d_mocap).as_quat())
        })
        .collect()
}

/// The drop from the root to the lowest joint of the rest pose (every
/// rotation zero): the mocap skeleton's hip height.
fn rest_height(sk: &CoreSkeleton) -> f32 {
    let mut y = vec![0.0f32; sk.len()];
    for i in 1..sk.len() {
        let p = usize::from(sk.parents[i]);
        y[i] = y.get(p).copied().unwrap_or(0.0) + sk.offsets[i].y;
    }
    -y.iter().copied().fold(0.0, f32::min)
}

/// 64-bit FNV-1a.
pub struct Fnv(pub u64);

impl Fnv {
    /// The offset basis.
    #[must_use]
    pub fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    /// Hashes `bytes` in.
    pub fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

impl Default for Fnv {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn skeleton() -> CoreSkeleton {
        CoreSkeleton {
            names: vec!["root".into(), "upper".into(), "lower".into()],
            parents: vec![NO_PARENT, 0, 1],
            offsets: vec![
                Vec3::ZERO,
                Vec3::new(0.0, -0.3, 0.0),
                Vec3::new(0.0, -0.25, 0.0),
            ],
            joints: vec![0, 1, 2],
        }
    }

    #[test]
    fn keeps_rotations_and_imposes_rig_lengths() {
        let sk = skeleton();
        let src = Source {
            file: "s.toml".into(),
            text: String::new(),
        };
        let mut lengths = BTreeMap::new();
        lengths.insert("lower".to_owned(), 2.0);
        let rig = Rig::from_skeleton(
            &sk,
            &RigSpec {
                file: None,
                align_rest: false,
                retarget: None,
                scale: 0.5,
                lengths,
                names: NameMap::default(),
                line: 3,
            },
            &src,
            1,
        )
        .unwrap();
        // A mocap pose: root at (0, 2, 0) turned 90° about Y, elbow bent 90° about X.
        let mut local = LocalPose::<CAP>::new(3).unwrap();
        local.root_position = Vec3::new(0.0, 2.0, 0.0);
        local.rotations[0] = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        local.rotations[2] = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
        let mut mocap = Pose::<CAP>::default();
        pose::forward(&sk.hierarchy(), &local, &mut mocap).unwrap();
        let mut out = Pose::<CAP>::default();
        rig.retarget(&mocap, &mut out).unwrap();
        for i in 0..3 {
            assert!(out.rotations[i].dot(mocap.rotations[i]).abs() > 1.0 - 1e-6);
        }
        // Root scaled by 0.5 to (0, 1, 0); upper 0.3·0.5 m below it; lower
        // 0.25·0.5·2 m further down (upper is not rotated locally).
        assert!((out.positions[0] - Vec3::new(0.0, 1.0, 0.0)).length() < 1e-6);
        assert!((out.positions[1] - Vec3::new(0.0, 0.85, 0.0)).length() < 1e-6);
        assert!((out.positions[2] - Vec3::new(0.0, 0.6, 0.0)).length() < 1e-6);
        // A point below `lower` in its frame: the X bend takes −Y to −Z, the
        // root's 90° Y turn takes −Z to −X.
        let tip = out.positions[2] + out.rotations[2] * Vec3::new(0.0, -0.25, 0.0);
        assert!((tip - Vec3::new(-0.25, 0.6, 0.0)).length() < 1e-5, "{tip}");
        let bad = RigSpec {
            file: None,
            align_rest: false,
            retarget: None,
            scale: 1.0,
            lengths: [("elbow".to_owned(), 1.0)].into(),
            names: NameMap::default(),
            line: 3,
        };
        let e = Rig::from_skeleton(&sk, &bad, &src, 1).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (3, "rig.lengths.elbow"));
        // Dropping `upper` hangs `lower` from the root at the summed offset
        // (by hand: 0.3 + 0.25 m down), renamed; it still follows the
        // mocap's `lower` joint.
        let pruned = RigSpec {
            lengths: BTreeMap::new(),
            names: NameMap {
                drop: vec!["up*".into()],
                rename: [("lower".to_owned(), "forearm".to_owned())].into(),
                ..NameMap::default()
            },
            ..bad
        };
        let rig = Rig::from_skeleton(&sk, &pruned, &src, 1).unwrap();
        assert_eq!(rig.names, ["root", "forearm"]);
        assert_eq!(rig.parents, [NO_PARENT, 0]);
        assert!((rig.offsets[1] - Vec3::new(0.0, -0.55, 0.0)).length() < 1e-6);
        assert_eq!(rig.source, [Some(0), Some(2)]);
    }
}

#[cfg(test)]
mod align_tests {
    use super::*;

    #[test]
    fn rest_alignment_maps_a_t_posed_arm_onto_a_hanging_one() {
        // Mocap: root, shoulder, elbow, wrist with the arm along +X at rest
        // (T-pose). Rig: root, upper arm, forearm hanging along −Y, touch
        // point of the forearm at its end.
        let sk = CoreSkeleton {
            names: vec!["root".into(), "arm".into(), "fore".into(), "hand".into()],
            parents: vec![NO_PARENT, 0, 1, 2],
            offsets: vec![
                Vec3::ZERO,
                Vec3::new(0.2, 0.5, 0.0),
                Vec3::new(0.3, 0.0, 0.0),
                Vec3::new(0.25, 0.0, 0.0),
            ],
            joints: vec![0, 1, 2, 3],
        };
        let parents = [NO_PARENT, 0, 1];
        let offsets = [
            Vec3::ZERO,
            Vec3::new(0.1, 0.3, 0.0),
            Vec3::new(0.0, -0.16, 0.0),
        ];
        let touches = [
            Vec3::ZERO,
            Vec3::new(0.0, -0.16, 0.0),
            Vec3::new(0.0, -0.15, 0.0),
        ];
        let source = [Some(0), Some(1), Some(2)];
        let o = align_rest(&sk, &parents, &offsets, &touches, &source);
        assert_eq!(o[0], None);
        // Both bones: −Y onto +X, a quarter turn about +Z.
        let quarter = Quat::from_xyzw(
            0.0,
            0.0,
            std::f32::consts::FRAC_1_SQRT_2,
            std::f32::consts::FRAC_1_SQRT_2,
        );
        for q in [o[1].unwrap(), o[2].unwrap()] {
            assert!(q.dot(quarter).abs() > 1.0 - 1e-6, "{q:?}");
        }
        // With the arm lowered in the mocap (−90° about Z at the shoulder),
        // the rig's arm hangs at its rest orientation.
        let lowered = Quat::from_xyzw(
            0.0,
            0.0,
            -std::f32::consts::FRAC_1_SQRT_2,
            std::f32::consts::FRAC_1_SQRT_2,
        );
        assert!((lowered * quarter).dot(Quat::IDENTITY).abs() > 1.0 - 1e-6);
    }
}
