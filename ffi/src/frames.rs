//! Blittable frame structs and coordinate conversions.
//!
//! The engine's convention is SMPL-X: right-handed, y up, metres; a dancer
//! at rest faces +z with the left side on +x (docs/SKELETON.md).
//!
//! - Unity: left-handed, y up, metres, +z forward, +x right.
//!   `p_unity = (-x, y, z)`; a rotation by angle t about axis a becomes a
//!   rotation by t about `(a.x, -a.y, -a.z)`: `q_unity = (qx, -qy, -qz, qw)`.
//! - Unreal: left-handed, z up, centimetres, +x forward, +y right.
//!   `p_unreal = 100 * (z, -x, y)`; `q_unreal = (-qz, qx, -qy, qw)`.
//!
//! Both are changes of basis by a reflection `P` (det -1): a position maps
//! to `P p`, a rotation matrix to `P R P^T`, which for a quaternion is
//! `(-P q.xyz, q.w)`. The same formula holds for world and local (parent
//! relative) rotations, since conjugation commutes with the joint chain.

use duolando_core::duolando::config::{N_JOINTS, POSE_DIM};
use duolando_runtime::skeleton::math::Mat3;
use duolando_runtime::skeleton::rotation::{nearest_rotation, quat_from_mat};

/// `duo_vec3`: x, y, z.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DuoVec3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

/// `duo_quat`: x, y, z, w (unit; w >= 0 as produced by the library).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DuoQuat {
    pub x: f32,
    pub y: f32,
    pub z: f32,
    pub w: f32,
}

/// `duo_leader_frame`: one leader pose, 55 SMPL-X joints (world xyz,
/// metres, SMPL-X axes). 660 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DuoLeaderFrame {
    pub joints: [DuoVec3; N_JOINTS],
}

impl Default for DuoLeaderFrame {
    fn default() -> Self {
        DuoLeaderFrame {
            joints: [DuoVec3::default(); N_JOINTS],
        }
    }
}

// 55 joints x 3 floats, no padding: the layout `DuoLeaderFrame::pos3d` reads.
const _: () = assert!(
    std::mem::size_of::<DuoVec3>() == 12 && std::mem::size_of::<DuoLeaderFrame>() == POSE_DIM * 4
);
const _: () = assert!(std::mem::align_of::<DuoLeaderFrame>() == std::mem::align_of::<f32>());

impl DuoLeaderFrame {
    /// The frame's 165 floats in place (x, y, z of each joint, in joint
    /// order): what the engine takes, without a copy.
    pub fn pos3d(&self) -> &[f32; POSE_DIM] {
        // SAFETY: `DuoLeaderFrame` is `repr(C)` over `[DuoVec3; 55]`, and
        // `DuoVec3` is `repr(C)` over three f32: 165 f32 with no padding
        // (both sizes asserted above), aligned as f32; the borrow is `self`'s.
        unsafe { &*(self as *const DuoLeaderFrame).cast::<[f32; POSE_DIM]>() }
    }
}

/// `duo_follower_frame`: one follower pose. 1560 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DuoFollowerFrame {
    /// Frame number since the session started (or was reset): 0, 1, 2, ...
    pub index: u64,
    /// World joint positions (the leader's coordinates), SMPL-X order.
    pub positions: [DuoVec3; N_JOINTS],
    /// Local joint rotations (relative to the parent joint; joint 0
    /// relative to the world), the nearest proper rotation of the decoder's
    /// raw 3x3 output, as unit quaternions.
    pub rotations: [DuoQuat; N_JOINTS],
    /// Root translation (the pelvis world position).
    pub root: DuoVec3,
}

impl Default for DuoFollowerFrame {
    fn default() -> Self {
        DuoFollowerFrame {
            index: 0,
            positions: [DuoVec3::default(); N_JOINTS],
            rotations: [DuoQuat {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }; N_JOINTS],
            root: DuoVec3::default(),
        }
    }
}

const _: () = {
    assert!(std::mem::size_of::<DuoVec3>() == 12);
    assert!(std::mem::size_of::<DuoQuat>() == 16);
    assert!(std::mem::size_of::<DuoLeaderFrame>() == 660);
    assert!(std::mem::size_of::<DuoFollowerFrame>() == 1560);
    assert!(std::mem::offset_of!(DuoFollowerFrame, positions) == 8);
    assert!(std::mem::offset_of!(DuoFollowerFrame, rotations) == 668);
    assert!(std::mem::offset_of!(DuoFollowerFrame, root) == 1548);
};

/// The unit quaternion of the proper rotation nearest to a raw row-major
/// 3x3 matrix (SVD projection; a zero or non-finite matrix gives identity).
pub fn quat_of_raw(m9: &[f32]) -> DuoQuat {
    let m: Mat3 = [
        [m9[0], m9[1], m9[2]],
        [m9[3], m9[4], m9[5]],
        [m9[6], m9[7], m9[8]],
    ];
    let q = quat_from_mat(&nearest_rotation(&m));
    DuoQuat {
        x: q[0],
        y: q[1],
        z: q[2],
        w: q[3],
    }
}

/// Target coordinate systems (`duo_coords`).
pub const COORDS_SMPLX: u32 = 0;
pub const COORDS_UNITY: u32 = 1;
pub const COORDS_UNREAL: u32 = 2;

pub fn vec3_to_unity(v: DuoVec3) -> DuoVec3 {
    DuoVec3 {
        x: -v.x,
        y: v.y,
        z: v.z,
    }
}
pub fn vec3_from_unity(v: DuoVec3) -> DuoVec3 {
    DuoVec3 {
        x: -v.x,
        y: v.y,
        z: v.z,
    }
}
pub fn quat_to_unity(q: DuoQuat) -> DuoQuat {
    DuoQuat {
        x: q.x,
        y: -q.y,
        z: -q.z,
        w: q.w,
    }
}
pub fn quat_from_unity(q: DuoQuat) -> DuoQuat {
    DuoQuat {
        x: q.x,
        y: -q.y,
        z: -q.z,
        w: q.w,
    }
}
pub fn vec3_to_unreal(v: DuoVec3) -> DuoVec3 {
    DuoVec3 {
        x: 100.0 * v.z,
        y: -100.0 * v.x,
        z: 100.0 * v.y,
    }
}
pub fn vec3_from_unreal(v: DuoVec3) -> DuoVec3 {
    DuoVec3 {
        x: -0.01 * v.y,
        y: 0.01 * v.z,
        z: 0.01 * v.x,
    }
}
pub fn quat_to_unreal(q: DuoQuat) -> DuoQuat {
    DuoQuat {
        x: -q.z,
        y: q.x,
        z: -q.y,
        w: q.w,
    }
}
pub fn quat_from_unreal(q: DuoQuat) -> DuoQuat {
    DuoQuat {
        x: q.y,
        y: -q.z,
        z: -q.x,
        w: q.w,
    }
}

macro_rules! value_fn {
    ($(#[$doc:meta])* $name:ident, $ty:ty, $f:path) => {
        $(#[$doc])*
        #[no_mangle]
        pub extern "C" fn $name(v: $ty) -> $ty {
            // Pure arithmetic cannot panic; the boundary is kept for the rule.
            std::panic::catch_unwind(|| $f(v)).unwrap_or_default()
        }
    };
}

value_fn!(
    /// SMPL-X position -> Unity (metres). Thread-safe.
    duo_vec3_to_unity, DuoVec3, vec3_to_unity
);
value_fn!(
    /// Unity position -> SMPL-X. Thread-safe.
    duo_vec3_from_unity, DuoVec3, vec3_from_unity
);
value_fn!(
    /// SMPL-X rotation -> Unity. Thread-safe.
    duo_quat_to_unity, DuoQuat, quat_to_unity
);
value_fn!(
    /// Unity rotation -> SMPL-X. Thread-safe.
    duo_quat_from_unity, DuoQuat, quat_from_unity
);
value_fn!(
    /// SMPL-X position (metres) -> Unreal (centimetres). Thread-safe.
    duo_vec3_to_unreal, DuoVec3, vec3_to_unreal
);
value_fn!(
    /// Unreal position (centimetres) -> SMPL-X (metres). Thread-safe.
    duo_vec3_from_unreal, DuoVec3, vec3_from_unreal
);
value_fn!(
    /// SMPL-X rotation -> Unreal. Thread-safe.
    duo_quat_to_unreal, DuoQuat, quat_to_unreal
);
value_fn!(
    /// Unreal rotation -> SMPL-X. Thread-safe.
    duo_quat_from_unreal, DuoQuat, quat_from_unreal
);

use crate::result::{guard, DuoResult, Failure};

/// Position to, rotation to, position from a coordinate system.
type CoordFns = (
    fn(DuoVec3) -> DuoVec3,
    fn(DuoQuat) -> DuoQuat,
    fn(DuoVec3) -> DuoVec3,
);

fn coords_fns(coords: u32) -> Result<CoordFns, Failure> {
    match coords {
        COORDS_SMPLX => Ok((|v| v, |q| q, |v| v)),
        COORDS_UNITY => Ok((vec3_to_unity, quat_to_unity, vec3_from_unity)),
        COORDS_UNREAL => Ok((vec3_to_unreal, quat_to_unreal, vec3_from_unreal)),
        c => Err(Failure::invalid(format!(
            "coords {c} is not a duo_coords value (0 SMPL-X, 1 Unity, 2 Unreal)"
        ))),
    }
}

/// Converts a follower frame in place from SMPL-X to `coords`
/// (`duo_coords`): positions, rotations and root. DUO_COORDS_SMPLX leaves
/// it unchanged.
///
/// # Safety
/// `frame` must be NULL or point to a valid, writable `duo_follower_frame`.
#[no_mangle]
pub unsafe extern "C" fn duo_follower_frame_convert(
    frame: *mut DuoFollowerFrame,
    coords: u32,
) -> DuoResult {
    guard("duo_follower_frame_convert", || {
        let (pos, rot, _) = coords_fns(coords)?;
        // SAFETY: checked non-NULL; the caller promises a valid frame.
        let f = unsafe { frame.as_mut() }.ok_or_else(|| Failure::null("frame"))?;
        for p in f.positions.iter_mut() {
            *p = pos(*p);
        }
        for q in f.rotations.iter_mut() {
            *q = rot(*q);
        }
        f.root = pos(f.root);
        Ok(DuoResult::Ok)
    })
}

/// Converts a leader frame in place from `coords` (`duo_coords`: the
/// engine's system the joints were written in) to SMPL-X, ready for
/// `duo_session_push_leader`.
///
/// # Safety
/// `frame` must be NULL or point to a valid, writable `duo_leader_frame`.
#[no_mangle]
pub unsafe extern "C" fn duo_leader_frame_convert(
    frame: *mut DuoLeaderFrame,
    coords: u32,
) -> DuoResult {
    guard("duo_leader_frame_convert", || {
        let (_, _, from) = coords_fns(coords)?;
        // SAFETY: checked non-NULL; the caller promises a valid frame.
        let f = unsafe { frame.as_mut() }.ok_or_else(|| Failure::null("frame"))?;
        for p in f.joints.iter_mut() {
            *p = from(*p);
        }
        Ok(DuoResult::Ok)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use duolando_runtime::skeleton::math::{axis_angle, mat_vec};
    use duolando_runtime::skeleton::rotation::mat_from_quat;

    fn v(x: f32, y: f32, z: f32) -> DuoVec3 {
        DuoVec3 { x, y, z }
    }
    fn close(a: DuoVec3, b: DuoVec3, tol: f32) -> bool {
        (a.x - b.x).abs() <= tol && (a.y - b.y).abs() <= tol && (a.z - b.z).abs() <= tol
    }
    fn q_of(m: &Mat3) -> DuoQuat {
        let q = quat_from_mat(m);
        DuoQuat {
            x: q[0],
            y: q[1],
            z: q[2],
            w: q[3],
        }
    }
    fn rotate(q: DuoQuat, p: DuoVec3) -> DuoVec3 {
        let r = mat_from_quat([q.x, q.y, q.z, q.w]);
        let o = mat_vec(&r, [p.x, p.y, p.z]);
        v(o[0], o[1], o[2])
    }

    #[test]
    fn hand_checked_positions() {
        // SMPL-X: up +y, forward +z, the dancer's left +x.
        let up = v(0.0, 1.0, 0.0);
        let fwd = v(0.0, 0.0, 1.0);
        let left = v(1.0, 0.0, 0.0);
        // Unity: up +y, forward +z, right +x -> left is -x.
        assert_eq!(duo_vec3_to_unity(up), v(0.0, 1.0, 0.0));
        assert_eq!(duo_vec3_to_unity(fwd), v(0.0, 0.0, 1.0));
        assert_eq!(duo_vec3_to_unity(left), v(-1.0, 0.0, 0.0));
        // Unreal: up +z, forward +x, right +y -> left is -y; centimetres.
        assert_eq!(duo_vec3_to_unreal(up), v(0.0, 0.0, 100.0));
        assert_eq!(duo_vec3_to_unreal(fwd), v(100.0, 0.0, 0.0));
        assert_eq!(duo_vec3_to_unreal(left), v(0.0, -100.0, 0.0));
    }

    #[test]
    fn hand_checked_rotations() {
        // A dancer turning to her left (counter-clockwise seen from above,
        // +90 degrees about +y in right-handed SMPL-X) ends facing +x
        // (her former left). In Unity she must face the engine's left (-x).
        let turn = q_of(&axis_angle([0.0, 1.0, 0.0], std::f32::consts::FRAC_PI_2));
        let fwd = v(0.0, 0.0, 1.0);
        assert!(close(rotate(turn, fwd), v(1.0, 0.0, 0.0), 1e-6));
        let tu = duo_quat_to_unity(turn);
        assert!(close(
            rotate(tu, duo_vec3_to_unity(fwd)),
            v(-1.0, 0.0, 0.0),
            1e-6
        ));
        // Unity's own convention: a positive angle about +y turns +z towards
        // +x (left-handed, clockwise from above), so turning left is -90.
        let expect = (-std::f32::consts::FRAC_PI_4).sin();
        assert!((tu.y - expect).abs() < 1e-6 && tu.x.abs() < 1e-7 && tu.z.abs() < 1e-7);
        // Unreal: facing left = -y (unit vectors in cm).
        let tr = duo_quat_to_unreal(turn);
        assert!(close(
            rotate(tr, duo_vec3_to_unreal(fwd)),
            v(0.0, -100.0, 0.0),
            1e-4
        ));
        // Unreal yaw: positive about +z turns +x towards +y (right); left = -90.
        assert!((tr.z - expect).abs() < 1e-6 && tr.x.abs() < 1e-7 && tr.y.abs() < 1e-7);
    }

    #[test]
    fn conversions_commute_with_rotation_and_round_trip() {
        // For any rotation q and point p: convert(q p) == convert(q) convert(p).
        let mut seed = 0x2545F491u32;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            (seed as f32 / u32::MAX as f32) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let axis = [rnd(), rnd(), rnd()];
            let q = q_of(&axis_angle(axis, 3.0 * rnd()));
            let p = v(rnd(), rnd(), rnd());
            let qp = rotate(q, p);
            assert!(close(
                duo_vec3_to_unity(qp),
                rotate(duo_quat_to_unity(q), duo_vec3_to_unity(p)),
                1e-5
            ));
            assert!(close(
                duo_vec3_to_unreal(qp),
                rotate(duo_quat_to_unreal(q), duo_vec3_to_unreal(p)),
                1e-3
            ));
            assert!(close(duo_vec3_from_unity(duo_vec3_to_unity(p)), p, 0.0));
            assert!(close(duo_vec3_from_unreal(duo_vec3_to_unreal(p)), p, 1e-6));
            assert_eq!(duo_quat_from_unity(duo_quat_to_unity(q)), q);
            assert_eq!(duo_quat_from_unreal(duo_quat_to_unreal(q)), q);
        }
    }

    #[test]
    fn frame_conversion_in_place() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let mut f = DuoFollowerFrame::default();
        f.positions[3] = v(1.0, 2.0, 3.0);
        f.root = v(0.5, 0.9, -0.25);
        f.rotations[7] = DuoQuat {
            x: 0.5,
            y: 0.5,
            z: 0.5,
            w: 0.5,
        };
        let before = f;
        assert_eq!(
            unsafe { duo_follower_frame_convert(&mut f, COORDS_SMPLX) },
            DuoResult::Ok
        );
        assert_eq!(f, before);
        assert_eq!(
            unsafe { duo_follower_frame_convert(&mut f, COORDS_UNREAL) },
            DuoResult::Ok
        );
        assert_eq!(f.positions[3], v(300.0, -100.0, 200.0));
        assert_eq!(f.root, v(-25.0, -50.0, 90.0));
        assert_eq!(
            f.rotations[7],
            DuoQuat {
                x: -0.5,
                y: 0.5,
                z: -0.5,
                w: 0.5
            }
        );
        assert_eq!(
            unsafe { duo_follower_frame_convert(&mut f, 3) },
            DuoResult::InvalidArgument
        );
        assert_eq!(
            unsafe { duo_follower_frame_convert(std::ptr::null_mut(), 1) },
            DuoResult::NullParameter
        );
        let mut l = DuoLeaderFrame::default();
        l.joints[0] = v(-100.0, 20.0, 50.0); // Unreal cm
        assert_eq!(
            unsafe { duo_leader_frame_convert(&mut l, COORDS_UNREAL) },
            DuoResult::Ok
        );
        assert!(close(l.joints[0], v(-0.2, 0.5, -1.0), 1e-6));
    }

    #[test]
    fn raw_rotation_projection() {
        // A scaled, slightly sheared rotation projects back to the rotation.
        let r = axis_angle([0.3, -0.8, 0.5], 1.1);
        let mut raw = [0.0f32; 9];
        for i in 0..3 {
            for j in 0..3 {
                raw[3 * i + j] = 1.7 * r[i][j] + if i == 0 && j == 1 { 0.01 } else { 0.0 };
            }
        }
        let q = quat_of_raw(&raw);
        let back = mat_from_quat([q.x, q.y, q.z, q.w]);
        for i in 0..3 {
            for j in 0..3 {
                assert!((back[i][j] - r[i][j]).abs() < 1e-2);
            }
        }
        let n = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
        assert!((n - 1.0).abs() < 1e-6 && q.w >= 0.0);
        assert_eq!(
            quat_of_raw(&[f32::NAN; 9]),
            DuoQuat {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0
            }
        );
        assert_eq!(
            quat_of_raw(&[0.0; 9]),
            DuoQuat {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0
            }
        );
    }
}
