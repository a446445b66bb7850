//! A simple body made of capsules between joints: the mannequin mesh in
//! the glTF export (export::mannequin) and the interpenetration measure of
//! two dancers ([`interpenetration`]) use the same capsules, so what the
//! measure calls an overlap is what a viewer of the .glb shows.
//!
//! Each capsule is the set of points within `radius` of a segment whose
//! ends are joint positions (or a point on a bone's extension, for the
//! head), so it is defined from world joint positions alone. Both ends move
//! rigidly with the `bind` joint's world rotation (they are that joint's
//! children, or the joint itself), which is what the skinned mesh needs.

use super::math::{add, dot, norm, scale, sub, Vec3};
use super::{Skeleton, JOINTS, POS_DIM};

/// One end of a capsule's segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum End {
    /// The joint's position.
    Joint(usize),
    /// `P[to] + k (P[to] - P[from])`: the bone `from -> to` extended by `k`
    /// of its length beyond `to`.
    Beyond { from: usize, to: usize, k: f32 },
}

/// Which part of the body a capsule belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// Pelvis, spine, collars, shoulders, neck and head.
    Trunk,
    /// Thighs, shins and feet.
    Leg,
    /// Upper arms, forearms and hands (arms reach the partner in a hold).
    Arm,
}

/// A capsule: the points within `radius` (metres, for the adult rig at
/// scale 1.0) of the segment `a -> b`, moving with joint `bind`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    pub a: End,
    pub b: End,
    pub radius: f32,
    pub bind: usize,
    pub part: Part,
}

const fn bone(parent: usize, child: usize, radius: f32, part: Part) -> Capsule {
    Capsule {
        a: End::Joint(parent),
        b: End::Joint(child),
        radius,
        bind: parent,
        part,
    }
}

/// The mannequin: 47 capsules (trunk, head, legs, arms, palms and finger
/// bones; the jaw and eyes have none). Radii are for the adult rig.
pub const CAPSULES: [Capsule; 47] = {
    use Part::{Arm, Leg, Trunk};
    [
        bone(0, 1, 0.085, Trunk),   // pelvis -> left hip
        bone(0, 2, 0.085, Trunk),   // pelvis -> right hip
        bone(0, 3, 0.11, Trunk),    // pelvis -> spine1
        bone(3, 6, 0.11, Trunk),    // spine1 -> spine2
        bone(6, 9, 0.12, Trunk),    // spine2 -> spine3
        bone(9, 12, 0.06, Trunk),   // spine3 -> neck
        bone(9, 13, 0.06, Trunk),   // spine3 -> left collar
        bone(9, 14, 0.06, Trunk),   // spine3 -> right collar
        bone(13, 16, 0.055, Trunk), // collar -> shoulder
        bone(14, 17, 0.055, Trunk),
        bone(12, 15, 0.05, Trunk), // neck -> head
        // The skull: the neck -> head bone continued by its own length.
        Capsule {
            a: End::Joint(15),
            b: End::Beyond {
                from: 12,
                to: 15,
                k: 1.0,
            },
            radius: 0.095,
            bind: 12,
            part: Trunk,
        },
        bone(1, 4, 0.075, Leg), // thighs
        bone(2, 5, 0.075, Leg),
        bone(4, 7, 0.055, Leg), // shins
        bone(5, 8, 0.055, Leg),
        bone(7, 10, 0.045, Leg), // feet
        bone(8, 11, 0.045, Leg),
        bone(16, 18, 0.045, Arm), // upper arms
        bone(17, 19, 0.045, Arm),
        bone(18, 20, 0.038, Arm), // forearms
        bone(19, 21, 0.038, Arm),
        bone(20, 28, 0.032, Arm), // palms: wrist -> middle1
        bone(21, 43, 0.032, Arm),
        // Fingers (index, middle, pinky, ring: 2 bones each; thumb: 3).
        bone(25, 26, 0.009, Arm),
        bone(26, 27, 0.009, Arm),
        bone(28, 29, 0.009, Arm),
        bone(29, 30, 0.009, Arm),
        bone(31, 32, 0.008, Arm),
        bone(32, 33, 0.008, Arm),
        bone(34, 35, 0.009, Arm),
        bone(35, 36, 0.009, Arm),
        bone(20, 37, 0.012, Arm),
        bone(37, 38, 0.011, Arm),
        bone(38, 39, 0.01, Arm),
        bone(40, 41, 0.009, Arm),
        bone(41, 42, 0.009, Arm),
        bone(43, 44, 0.009, Arm),
        bone(44, 45, 0.009, Arm),
        bone(46, 47, 0.008, Arm),
        bone(47, 48, 0.008, Arm),
        bone(49, 50, 0.009, Arm),
        bone(50, 51, 0.009, Arm),
        bone(21, 52, 0.012, Arm),
        bone(52, 53, 0.011, Arm),
        bone(53, 54, 0.01, Arm),
        // Between the palm and the index/pinky knuckles (a flat hand).
        bone(20, 31, 0.02, Arm),
    ]
};

/// The world position of a capsule end given the joint positions.
pub fn end_point(e: End, p: &[Vec3; JOINTS]) -> Vec3 {
    match e {
        End::Joint(j) => p[j],
        End::Beyond { from, to, k } => add(p[to], scale(sub(p[to], p[from]), k)),
    }
}

/// The rig's radius scale: its thigh length over the adult rig's.
pub fn radius_scale(skel: &Skeleton) -> f32 {
    let s = skel.scale_hint();
    if s.is_finite() && s > 0.0 {
        s
    } else {
        1.0
    }
}

/// Distance between segments `p1 -> q1` and `p2 -> q2` (closest points,
/// after Ericson, Real-Time Collision Detection 5.1.9; degenerate segments
/// are points).
pub fn segment_distance(p1: Vec3, q1: Vec3, p2: Vec3, q2: Vec3) -> f32 {
    const EPS: f32 = 1e-12;
    let d1 = sub(q1, p1);
    let d2 = sub(q2, p2);
    let r = sub(p1, p2);
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    let (s, t);
    if a <= EPS && e <= EPS {
        return norm(r);
    }
    if a <= EPS {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = dot(d1, r);
        if e <= EPS {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > EPS {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    let c1 = add(p1, scale(d1, s));
    let c2 = add(p2, scale(d2, t));
    norm(sub(c1, c2))
}

/// Per frame, how deep two bodies overlap: the largest penetration depth
/// `r_a + r_b - distance(segment_a, segment_b)` (0 when apart) over every
/// pair of capsules of `parts`, one from each dancer. `a` and `b` are
/// (T, 165) world positions (the shorter length is used); `scale_a` and
/// `scale_b` scale the radii (see [`radius_scale`]).
pub fn overlap_depths(
    a: &[f32],
    b: &[f32],
    scale_a: f32,
    scale_b: f32,
    parts: &[Part],
) -> Vec<f32> {
    let caps: Vec<&Capsule> = CAPSULES
        .iter()
        .filter(|c| parts.contains(&c.part))
        .collect();
    let frame = |row: &[f32]| -> [Vec3; JOINTS] {
        let mut p = [[0.0f32; 3]; JOINTS];
        for (j, q) in p.iter_mut().enumerate() {
            *q = [row[3 * j], row[3 * j + 1], row[3 * j + 2]];
        }
        p
    };
    a.chunks_exact(POS_DIM)
        .zip(b.chunks_exact(POS_DIM))
        .map(|(ra, rb)| {
            let (pa, pb) = (frame(ra), frame(rb));
            let sa: Vec<(Vec3, Vec3, f32)> = caps
                .iter()
                .map(|c| (end_point(c.a, &pa), end_point(c.b, &pa), c.radius * scale_a))
                .collect();
            let sb: Vec<(Vec3, Vec3, f32)> = caps
                .iter()
                .map(|c| (end_point(c.a, &pb), end_point(c.b, &pb), c.radius * scale_b))
                .collect();
            let mut deepest = 0.0f32;
            for &(p1, q1, r1) in &sa {
                for &(p2, q2, r2) in &sb {
                    let depth = r1 + r2 - segment_distance(p1, q1, p2, q2);
                    if depth > deepest {
                        deepest = depth;
                    }
                }
            }
            deepest
        })
        .collect()
}

/// Pelvis distance below which two dancers count as too close (metres).
pub const CLOSE_PELVIS_M: f32 = 0.25;
/// Penetration depth counted as clearly visible (metres).
pub const VISIBLE_DEPTH_M: f32 = 0.02;

/// Mean, 5th percentile and minimum of a per-frame distance (metres).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct DistanceStats {
    pub min: f32,
    pub p5: f32,
    pub mean: f32,
}

/// Per-frame penetration depths of one set of capsules (metres): the share
/// of frames where any capsule of one dancer enters one of the other's,
/// the share where it goes deeper than [`VISIBLE_DEPTH_M`], and the
/// depth's mean (frames apart count 0), 95th percentile and maximum.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct OverlapStats {
    pub frames_overlapping: f32,
    pub frames_over_2cm: f32,
    pub depth_mean_m: f32,
    pub depth_p95_m: f32,
    pub depth_max_m: f32,
}

/// How much two dancers' bodies interpenetrate over a clip.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Interpenetration {
    pub frames: usize,
    /// 3-D distance between the two pelvis joints.
    pub pelvis_distance_m: DistanceStats,
    /// Share of frames with the pelvises closer than [`CLOSE_PELVIS_M`].
    pub frames_pelvis_under_0_25_m: f32,
    /// Capsules of the trunk and head ([`Part::Trunk`]) only.
    pub trunk_capsules: OverlapStats,
    /// Trunk, head and legs ([`Part::Trunk`], [`Part::Leg`]).
    pub body_capsules: OverlapStats,
    /// Every capsule, arms and hands included (a dance hold touches the
    /// partner by design, so some overlap here is expected).
    pub all_capsules: OverlapStats,
}

fn nearest_rank(sorted: &[f32], q: f64) -> f32 {
    let n = sorted.len();
    sorted[((q * n as f64).ceil() as usize).clamp(1, n) - 1]
}

fn overlap_stats(mut d: Vec<f32>) -> OverlapStats {
    if d.is_empty() {
        return OverlapStats::default();
    }
    let n = d.len() as f32;
    let over = d.iter().filter(|&&v| v > 0.0).count() as f32 / n;
    let visible = d.iter().filter(|&&v| v > VISIBLE_DEPTH_M).count() as f32 / n;
    let mean = (d.iter().map(|&v| v as f64).sum::<f64>() / d.len() as f64) as f32;
    d.sort_unstable_by(f32::total_cmp);
    OverlapStats {
        frames_overlapping: over,
        frames_over_2cm: visible,
        depth_mean_m: mean,
        depth_p95_m: nearest_rank(&d, 0.95),
        depth_max_m: d[d.len() - 1],
    }
}

/// Interpenetration of dancers `a` and `b` ((T, 165) world positions each;
/// the shorter length is used) whose capsule radii scale by `scale_a`,
/// `scale_b` (see [`radius_scale`]).
pub fn interpenetration(a: &[f32], b: &[f32], scale_a: f32, scale_b: f32) -> Interpenetration {
    let mut pelvis: Vec<f32> = a
        .chunks_exact(POS_DIM)
        .zip(b.chunks_exact(POS_DIM))
        .map(|(fa, fb)| norm(sub([fa[0], fa[1], fa[2]], [fb[0], fb[1], fb[2]])))
        .collect();
    let frames = pelvis.len();
    if frames == 0 {
        return Interpenetration::default();
    }
    let close = pelvis.iter().filter(|&&d| d < CLOSE_PELVIS_M).count() as f32 / frames as f32;
    let mean = (pelvis.iter().map(|&v| v as f64).sum::<f64>() / frames as f64) as f32;
    pelvis.sort_unstable_by(f32::total_cmp);
    Interpenetration {
        frames,
        pelvis_distance_m: DistanceStats {
            min: pelvis[0],
            p5: nearest_rank(&pelvis, 0.05),
            mean,
        },
        frames_pelvis_under_0_25_m: close,
        trunk_capsules: overlap_stats(overlap_depths(a, b, scale_a, scale_b, &[Part::Trunk])),
        body_capsules: overlap_stats(overlap_depths(
            a,
            b,
            scale_a,
            scale_b,
            &[Part::Trunk, Part::Leg],
        )),
        all_capsules: overlap_stats(overlap_depths(
            a,
            b,
            scale_a,
            scale_b,
            &[Part::Trunk, Part::Leg, Part::Arm],
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distance_cases() {
        // Parallel, 1 apart.
        assert!(
            (segment_distance([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]) - 1.0)
                .abs()
                < 1e-6
        );
        // Crossing at right angles, 0.5 apart in z.
        assert!(
            (segment_distance(
                [-1.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, -1.0, 0.5],
                [0.0, 1.0, 0.5]
            ) - 0.5)
                .abs()
                < 1e-6
        );
        // End to end along a line.
        assert!(
            (segment_distance([0.0; 3], [1.0, 0.0, 0.0], [3.0, 0.0, 0.0], [4.0, 0.0, 0.0]) - 2.0)
                .abs()
                < 1e-6
        );
        // Points.
        assert!(
            (segment_distance([0.0; 3], [0.0; 3], [0.0, 3.0, 4.0], [0.0, 3.0, 4.0]) - 5.0).abs()
                < 1e-6
        );
        // Point against a segment.
        assert!(
            (segment_distance([0.5, 2.0, 0.0], [0.5, 2.0, 0.0], [0.0; 3], [1.0, 0.0, 0.0]) - 2.0)
                .abs()
                < 1e-6
        );
    }

    #[test]
    fn capsules_move_with_their_bind_joint() {
        for c in CAPSULES {
            for e in [c.a, c.b] {
                match e {
                    End::Joint(j) => assert!(
                        j == c.bind || super::super::parent(j) == Some(c.bind),
                        "{c:?}"
                    ),
                    End::Beyond { from, to, .. } => assert!(
                        from == c.bind && super::super::parent(to) == Some(from),
                        "{c:?}"
                    ),
                }
            }
            assert!(c.radius > 0.0);
        }
    }

    #[test]
    fn overlap_of_two_bodies() {
        let rest = Skeleton::default().rest_positions();
        let row =
            |dz: f32| -> Vec<f32> { rest.iter().flat_map(|p| [p[0], p[1], p[2] + dz]).collect() };
        // The same body twice: the deepest pair is the chest (2 x 0.12).
        let same = overlap_depths(&row(0.0), &row(0.0), 1.0, 1.0, &[Part::Trunk]);
        assert!((same[0] - 0.24).abs() < 1e-5, "{same:?}");
        // 2 m apart: none.
        assert_eq!(
            overlap_depths(
                &row(0.0),
                &row(2.0),
                1.0,
                1.0,
                &[Part::Trunk, Part::Leg, Part::Arm]
            ),
            vec![0.0]
        );
        // 0.2 m apart in z: the chest capsules (0.24) overlap by ~0.04 (the spine3 tilt aside).
        let near = overlap_depths(&row(0.0), &row(0.2), 1.0, 1.0, &[Part::Trunk])[0];
        assert!(near > 0.03 && near < 0.06, "{near}");
        // Over a clip: one frame 0.2 m apart, three 2 m apart.
        let a: Vec<f32> = (0..4).flat_map(|_| row(0.0)).collect();
        let b: Vec<f32> = [0.2, 2.0, 2.0, 2.0]
            .iter()
            .flat_map(|&dz| row(dz))
            .collect();
        let r = interpenetration(&a, &b, 1.0, 1.0);
        assert_eq!(r.frames, 4);
        assert!(
            (r.pelvis_distance_m.min - 0.2).abs() < 1e-6
                && (r.frames_pelvis_under_0_25_m - 0.25).abs() < 1e-6,
            "{r:?}"
        );
        assert!(
            (r.trunk_capsules.frames_overlapping - 0.25).abs() < 1e-6
                && (r.trunk_capsules.depth_max_m - near).abs() < 1e-6,
            "{r:?}"
        );
        assert!(
            r.body_capsules.depth_max_m >= near
                && r.all_capsules.depth_max_m >= r.body_capsules.depth_max_m,
            "{r:?}"
        );
        assert!(
            (r.trunk_capsules.depth_mean_m - near / 4.0).abs() < 1e-6,
            "{r:?}"
        );
    }
}
