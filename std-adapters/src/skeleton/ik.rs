//! Analytic two-bone inverse kinematics (legs and arms) used by the
//! synthesizer to place feet and hands.

use super::math::{add, align, dot, norm, normalize_or, scale, sub, Mat3, Vec3};
use super::Skeleton;

/// A two-bone chain `root -> mid -> end` (hip -> knee -> ankle,
/// shoulder -> elbow -> wrist) and the rest-frame direction the middle
/// joint bends towards (knee: +z, forward; elbow: -z, backward).
#[derive(Clone, Copy, Debug)]
pub struct Chain {
    pub root: usize,
    pub mid: usize,
    pub end: usize,
    pub rest_pole: Vec3,
}

/// The solved world rotations of the chain's first two joints.
#[derive(Clone, Copy, Debug)]
pub struct ChainSolution {
    pub root_world: Mat3,
    pub mid_world: Mat3,
    /// True when the target was out of reach and the end falls short of it.
    pub clamped: bool,
}

/// Solves the chain so that the end joint lands on `target` (when
/// reachable), bending the middle joint towards `pole` (a world
/// direction). `root_pos` is the world position of the chain's root joint.
pub fn solve(
    skel: &Skeleton,
    chain: Chain,
    root_pos: Vec3,
    target: Vec3,
    pole: Vec3,
) -> ChainSolution {
    let l1 = norm(skel.offsets[chain.mid]);
    let l2 = norm(skel.offsets[chain.end]);
    let to_target = sub(target, root_pos);
    let dist_raw = norm(to_target);
    let lo = (l1 - l2).abs() + 1e-4;
    let hi = l1 + l2 - 1e-4;
    let dist = dist_raw.clamp(lo, hi);
    let clamped = dist_raw > hi || dist_raw < lo;
    let u = normalize_or(to_target, [0.0, -1.0, 0.0]);
    let v = normalize_or(sub(pole, scale(u, dot(pole, u))), [0.0, 0.0, 1.0]);
    let cos_a = ((l1 * l1 + dist * dist - l2 * l2) / (2.0 * l1 * dist)).clamp(-1.0, 1.0);
    let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
    let mid_pos = add(root_pos, scale(add(scale(u, cos_a), scale(v, sin_a)), l1));
    let end_pos = add(root_pos, scale(u, dist));
    let root_world = align(
        skel.offsets[chain.mid],
        chain.rest_pole,
        sub(mid_pos, root_pos),
        pole,
    );
    let mid_world = align(
        skel.offsets[chain.end],
        chain.rest_pole,
        sub(end_pos, mid_pos),
        pole,
    );
    ChainSolution {
        root_world,
        mid_world,
        clamped,
    }
}

/// Largest distance a chain can reach (just under full extension).
pub fn reach(skel: &Skeleton, chain: Chain) -> f32 {
    norm(skel.offsets[chain.mid]) + norm(skel.offsets[chain.end]) - 1e-4
}
