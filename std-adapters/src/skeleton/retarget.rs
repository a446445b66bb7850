//! Retargeting raw joint positions onto the rig: world positions -> local
//! rotations (an approximation; see docs/SKELETON.md).
//!
//! Joints are visited parent before child. For each joint `j` the world
//! rotation `G[j]` is chosen from the directions towards its children,
//! measured from `j`'s *reconstructed* position (so residuals do not
//! accumulate down a chain):
//! - one child (or a chain joint): the swing — the smallest rotation that
//!   takes `G[parent] offset[child]` onto the observed direction — applied
//!   on top of `G[parent]`. Twist about the bone is inherited from the
//!   parent (zero local twist); positions do not depend on it.
//! - several children (pelvis, spine3, head, wrists): the primary child
//!   (spine1, neck, jaw, middle1) is matched exactly by a swing, then the
//!   twist about that bone is the angle that best aligns the other
//!   children (least squares in the plane perpendicular to the bone).
//! - leaves (feet, eyes, finger tips): local rotation identity.

use super::math::{
    axis_angle, cross, dot, mat_mul, mat_vec, norm, normalize_or, scale, sub, swing, Mat3, Vec3,
    IDENTITY,
};
use super::{children, parent, Skeleton, JOINTS};

/// The child whose direction is matched exactly at a branching joint.
pub fn primary_child(j: usize) -> Option<usize> {
    match j {
        0 => Some(3),
        9 => Some(12),
        15 => Some(22),
        20 => Some(28),
        21 => Some(43),
        _ => children(j).next(),
    }
}

/// Local rotations (55) whose FK on `skel` with root `positions[0]`
/// reproduces `positions` as closely as the rig's bone lengths allow.
pub fn retarget(skel: &Skeleton, positions: &[Vec3; JOINTS]) -> [Mat3; JOINTS] {
    let mut world = [IDENTITY; JOINTS];
    let mut local = [IDENTITY; JOINTS];
    let mut recon = [[0.0f32; 3]; JOINTS]; // (55, 3) reconstructed positions
    recon[0] = positions[0];
    for j in 0..JOINTS {
        let base = match parent(j) {
            Some(p) => {
                recon[j] = super::math::add(recon[p], mat_vec(&world[p], skel.offsets[j]));
                world[p]
            }
            None => IDENTITY,
        };
        let g = match primary_child(j) {
            None => base,
            Some(c) => {
                let rest_dir = normalize_or(mat_vec(&base, skel.offsets[c]), [0.0, 1.0, 0.0]);
                let obs = sub(positions[c], recon[j]);
                let obs_dir = normalize_or(obs, rest_dir);
                let g = mat_mul(&swing(rest_dir, obs_dir), &base);
                let others: Vec<usize> = children(j).filter(|&k| k != c).collect();
                if others.is_empty() {
                    g
                } else {
                    let angle = best_twist(&g, skel, obs_dir, &others, positions, recon[j]);
                    mat_mul(&axis_angle(obs_dir, angle), &g)
                }
            }
        };
        world[j] = g;
        local[j] = mat_mul(&super::math::transpose(&base), &g);
    }
    local
}

/// The twist angle about `axis` that best aligns `g offset[k]` with the
/// observed `positions[k] - origin` for the secondary children `ks`.
fn best_twist(
    g: &Mat3,
    skel: &Skeleton,
    axis: Vec3,
    ks: &[usize],
    positions: &[Vec3; JOINTS],
    origin: Vec3,
) -> f32 {
    let (mut s, mut c) = (0.0f32, 0.0f32);
    for &k in ks {
        let u = mat_vec(g, skel.offsets[k]);
        let v = sub(positions[k], origin);
        let up = sub(u, scale(axis, dot(u, axis)));
        let vp = sub(v, scale(axis, dot(v, axis)));
        if norm(up) < 1e-6 || norm(vp) < 1e-6 {
            continue;
        }
        s += dot(cross(up, vp), axis);
        c += dot(up, vp);
    }
    if s == 0.0 && c == 0.0 {
        0.0
    } else {
        s.atan2(c)
    }
}

/// A rig whose bone directions are `template`'s and whose bone lengths are
/// the median lengths measured in `clip` ((T, 55, 3) positions): one length
/// per bone for the whole clip (the rig stays rigid), so that FK of
/// retargeted rotations reproduces a rigid clip's joints exactly and a
/// non-rigid one (decoded positions) as closely as fixed bones allow. The
/// median ignores the frames where a decoder stretches a bone. Bones that
/// are degenerate in the clip keep the template length.
pub fn measure_skeleton(template: &Skeleton, clip: &[[Vec3; JOINTS]]) -> Skeleton {
    let mut out = *template;
    if clip.is_empty() {
        return out;
    }
    let mut lengths: Vec<f32> = Vec::with_capacity(clip.len());
    for j in 1..JOINTS {
        let p = parent(j).unwrap_or(0);
        lengths.clear();
        lengths.extend(clip.iter().map(|f| norm(sub(f[j], f[p]))));
        lengths.sort_unstable_by(f32::total_cmp);
        let n = lengths.len();
        let median = if n % 2 == 1 {
            lengths[n / 2]
        } else {
            0.5 * (lengths[n / 2 - 1] + lengths[n / 2])
        };
        let len = norm(template.offsets[j]);
        if median.is_finite() && median > 1e-5 && len > 1e-9 {
            out.offsets[j] = scale(template.offsets[j], median / len);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measured_bones_take_the_median_length_and_ignore_stretched_frames() {
        let rig = Skeleton::adult(1.0);
        let rest = rig.rest_positions();
        // 7 frames at rest; in 3 of them the right forearm is stretched to
        // twice its length (the wrist and hand pushed out along the bone).
        let fore = sub(rest[21], rest[19]);
        let clip: Vec<[Vec3; JOINTS]> = (0..7)
            .map(|t| {
                let mut f = rest;
                if t % 2 == 1 {
                    for j in [21usize].into_iter().chain(40..55) {
                        f[j] = crate::skeleton::math::add(f[j], fore);
                    }
                }
                f
            })
            .collect();
        let m = measure_skeleton(&Skeleton::default(), &clip);
        assert!(
            (m.bone_length(21) - rig.bone_length(21)).abs() < 1e-6,
            "{} vs {}",
            m.bone_length(21),
            rig.bone_length(21)
        );
        assert!((m.bone_length(19) - rig.bone_length(19)).abs() < 1e-6);
        // An even count takes the middle two's mean: 2 at rest, 2 stretched.
        let m = measure_skeleton(&Skeleton::default(), &clip[..4]);
        assert!(
            (m.bone_length(21) - 1.5 * rig.bone_length(21)).abs() < 1e-5,
            "{}",
            m.bone_length(21)
        );
    }
}
