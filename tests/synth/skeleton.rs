//! FK/IK round trips, rotation conversions, nearest rotation.

use duolando::skeleton::fk::forward_kinematics;
use duolando::skeleton::ik::{self, Chain};
use duolando::skeleton::math::{
    self, axis_angle, det, mat_mul, max_abs_diff, norm, sub, transpose, Mat3, IDENTITY,
};
use duolando::skeleton::retarget::{measure_skeleton, retarget};
use duolando::skeleton::rotation::{
    euler_zxy_from_mat, mat_from_euler_zxy, mat_from_quat, nearest_rotation, quat_from_mat,
};
use duolando::skeleton::{children, parent, Skeleton, JOINTS, JOINT_NAMES, PARENTS};
use duolando::synth::rng::Rng;

/// f32 round-off on a chain of ~10 rotations over ~2 m.
const CLOSE_M: f32 = 1e-4;
/// Matrix entries after conversions.
const CLOSE_ROT: f32 = 2e-5;

fn random_rotation(rng: &mut Rng, max_angle: f32) -> Mat3 {
    let axis = math::normalize_or([rng.normal(), rng.normal(), rng.normal()], [0.0, 1.0, 0.0]);
    axis_angle(axis, rng.range(-max_angle, max_angle))
}

fn random_pose(rng: &mut Rng, max_angle: f32) -> [Mat3; JOINTS] {
    let mut local = [IDENTITY; JOINTS];
    for m in local.iter_mut() {
        *m = random_rotation(rng, max_angle);
    }
    local
}

#[test]
fn tree_is_the_smplx_tree() {
    assert_eq!(JOINT_NAMES[20], "left_wrist");
    assert_eq!(JOINT_NAMES[54], "right_thumb3");
    for j in 1..JOINTS {
        assert!((PARENTS[j] as usize) < j);
    }
    assert_eq!(children(0).collect::<Vec<_>>(), vec![1, 2, 3]);
    assert_eq!(children(20).count(), 5);
    // Our rig: adult proportions, left on +x, mirrored sides.
    let s = Skeleton::adult(1.0);
    let p = s.rest_positions();
    assert!(p[1][0] > 0.0 && p[2][0] < 0.0 && p[16][0] > 0.0);
    let h = s.standing_pelvis_height();
    assert!((0.85..1.0).contains(&h), "pelvis height {h}");
    let top = p[23][1] + h;
    assert!((1.6..1.8).contains(&top), "eye height {top}");
    for j in 1..JOINTS {
        let len = s.bone_length(j);
        assert!(len > 0.015 && len < 0.45, "{} bone {len}", JOINT_NAMES[j]);
        let m = duolando::skeleton::rest::mirror_of(j);
        assert!(
            (p[m][0] + p[j][0]).abs() < 1e-6 && (p[m][1] - p[j][1]).abs() < 1e-6,
            "{} not mirrored",
            JOINT_NAMES[j]
        );
    }
}

#[test]
fn fk_of_identity_is_the_rest_pose_and_bones_keep_length() {
    let s = Skeleton::adult(1.03);
    let rest = forward_kinematics(&s, [0.0; 3], &[IDENTITY; JOINTS]);
    let want = s.rest_positions();
    for j in 0..JOINTS {
        assert!(norm(sub(rest.positions[j], want[j])) < 1e-6);
    }
    let mut rng = Rng::new(1, 0);
    let pose = forward_kinematics(&s, [0.3, 0.9, -1.0], &random_pose(&mut rng, 2.0));
    for j in 1..JOINTS {
        let p = parent(j).unwrap();
        let d = norm(sub(pose.positions[j], pose.positions[p]));
        assert!((d - s.bone_length(j)).abs() < 1e-5);
    }
}

#[test]
fn retarget_reproduces_fk_positions() {
    // FK -> positions -> retarget -> FK gives back the positions.
    let s = Skeleton::adult(0.95);
    let mut rng = Rng::new(2, 0);
    let mut worst = 0.0f32;
    for _ in 0..50 {
        let local = random_pose(&mut rng, 1.5);
        let root = [
            rng.range(-2.0, 2.0),
            rng.range(0.5, 1.0),
            rng.range(-2.0, 2.0),
        ];
        let pos = forward_kinematics(&s, root, &local).positions;
        let back = retarget(&s, &pos);
        let again = forward_kinematics(&s, root, &back).positions;
        for j in 0..JOINTS {
            worst = worst.max(norm(sub(again[j], pos[j])));
        }
        for m in back.iter() {
            assert!((det(m) - 1.0).abs() < 1e-4);
        }
    }
    println!("retarget round trip worst joint error {worst:.2e} m");
    assert!(worst < CLOSE_M, "{worst}");
}

#[test]
fn retarget_onto_a_measured_rig_fits_foreign_proportions() {
    // Positions from a rig with longer limbs: measuring bone lengths first
    // makes the fit exact (directions of single-child bones are free).
    let mut other = Skeleton::adult(1.0);
    for j in [4, 5, 7, 8, 18, 19] {
        other.offsets[j] = math::scale(other.offsets[j], 1.1);
    }
    let mut rng = Rng::new(3, 0);
    let clip: Vec<_> = (0..20)
        .map(|_| forward_kinematics(&other, [0.0, 0.9, 0.0], &random_pose(&mut rng, 1.0)).positions)
        .collect();
    let rig = measure_skeleton(&Skeleton::adult(1.0), &clip);
    let mut worst = 0.0f32;
    for pos in &clip {
        let again = forward_kinematics(&rig, pos[0], &retarget(&rig, pos)).positions;
        for j in 0..JOINTS {
            worst = worst.max(norm(sub(again[j], pos[j])));
        }
    }
    println!("foreign-proportion retarget worst joint error {worst:.2e} m");
    assert!(worst < CLOSE_M, "{worst}");
}

#[test]
fn two_bone_ik_reaches_reachable_targets() {
    let s = Skeleton::adult(1.0);
    let leg = Chain {
        root: 1,
        mid: 4,
        end: 7,
        rest_pole: [0.0, 0.0, 1.0],
    };
    let mut rng = Rng::new(4, 0);
    let hip = [0.06, 0.85, 0.0];
    for _ in 0..200 {
        let dir = math::normalize_or([rng.normal(), rng.normal(), rng.normal()], [0.0, -1.0, 0.0]);
        let r = rng.range(0.1, 0.98) * ik::reach(&s, leg);
        let target = math::add(hip, math::scale(dir, r));
        let sol = ik::solve(&s, leg, hip, target, [0.0, 0.0, 1.0]);
        assert!(!sol.clamped);
        let knee = math::add(hip, math::mat_vec(&sol.root_world, s.offsets[4]));
        let ankle = math::add(knee, math::mat_vec(&sol.mid_world, s.offsets[7]));
        assert!(
            norm(sub(ankle, target)) < 1e-4,
            "ankle misses by {}",
            norm(sub(ankle, target))
        );
    }
    let far = ik::solve(&s, leg, hip, [0.0, -2.0, 0.0], [0.0, 0.0, 1.0]);
    assert!(far.clamped);
}

#[test]
fn quaternion_round_trips() {
    let mut rng = Rng::new(5, 0);
    for _ in 0..500 {
        let m = random_rotation(&mut rng, std::f32::consts::PI);
        let q = quat_from_mat(&m);
        let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt();
        assert!((n - 1.0).abs() < 1e-5 && q[3] >= 0.0);
        assert!(max_abs_diff(&mat_from_quat(q), &m) < CLOSE_ROT);
    }
    // Known value: 90 degrees about +y is (0, sin 45, 0, cos 45).
    let q = quat_from_mat(&math::rot_y(std::f32::consts::FRAC_PI_2));
    assert!(
        (q[1] - 0.70710677).abs() < 1e-6 && (q[3] - 0.70710677).abs() < 1e-6 && q[0].abs() < 1e-6
    );
    // Half turns (w = 0) take the other branches.
    for m in [
        math::rot_x(std::f32::consts::PI),
        math::rot_y(std::f32::consts::PI),
        math::rot_z(std::f32::consts::PI),
    ] {
        assert!(max_abs_diff(&mat_from_quat(quat_from_mat(&m)), &m) < CLOSE_ROT);
    }
}

#[test]
fn euler_zxy_round_trips_including_gimbal_lock() {
    let mut rng = Rng::new(6, 0);
    for _ in 0..500 {
        let m = random_rotation(&mut rng, std::f32::consts::PI);
        let e = euler_zxy_from_mat(&m);
        assert!(max_abs_diff(&mat_from_euler_zxy(e), &m) < 1e-4);
    }
    let lock = mat_mul(
        &math::rot_z(0.4),
        &mat_mul(&math::rot_x(std::f32::consts::FRAC_PI_2), &math::rot_y(0.3)),
    );
    assert!(max_abs_diff(&mat_from_euler_zxy(euler_zxy_from_mat(&lock)), &lock) < 1e-4);
}

#[test]
fn nearest_rotation_properties() {
    let mut rng = Rng::new(7, 0);
    for _ in 0..300 {
        let r = random_rotation(&mut rng, std::f32::consts::PI);
        // A rotation is its own nearest rotation.
        assert!(max_abs_diff(&nearest_rotation(&r), &r) < CLOSE_ROT);
        // R S with S symmetric positive definite projects back to R.
        let q = random_rotation(&mut rng, std::f32::consts::PI);
        let d = [
            [rng.range(0.3, 2.0), 0.0, 0.0],
            [0.0, rng.range(0.3, 2.0), 0.0],
            [0.0, 0.0, rng.range(0.3, 2.0)],
        ];
        let spd = mat_mul(&q, &mat_mul(&d, &transpose(&q)));
        assert!(max_abs_diff(&nearest_rotation(&mat_mul(&r, &spd)), &r) < 1e-4);
        // Arbitrary matrices: a proper rotation, no farther than any sampled rotation.
        let m: Mat3 = [
            [rng.normal(), rng.normal(), rng.normal()],
            [rng.normal(), rng.normal(), rng.normal()],
            [rng.normal(), rng.normal(), rng.normal()],
        ];
        let p = nearest_rotation(&m);
        assert!(max_abs_diff(&mat_mul(&p, &transpose(&p)), &IDENTITY) < 1e-5);
        assert!((det(&p) - 1.0).abs() < 1e-5);
        let frob = |a: &Mat3| {
            math::flatten(a)
                .iter()
                .zip(math::flatten(&m).iter())
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f32>()
        };
        let best = frob(&p);
        for _ in 0..20 {
            let other = mat_mul(&p, &random_rotation(&mut rng, 0.5));
            assert!(
                frob(&other) >= best - 1e-4,
                "a neighbour is nearer: {} < {best}",
                frob(&other)
            );
        }
        // Equivariance: nearest(Q M) = Q nearest(M).
        assert!(max_abs_diff(&nearest_rotation(&mat_mul(&q, &m)), &mat_mul(&q, &p)) < 1e-4);
    }
    // Degenerate inputs give a rotation, never NaN.
    for m in [
        [[0.0; 3]; 3],
        [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
        [[f32::NAN; 3]; 3],
    ] {
        let p = nearest_rotation(&m);
        assert!((det(&p) - 1.0).abs() < 1e-5);
    }
}

#[test]
fn retarget_residual_at_branching_joints_is_bounded_by_the_shape_change() {
    // Wider hips change the angle between pelvis children: one rigid
    // pelvis rotation cannot match all three, so the hips keep a residual
    // no larger than the change itself, and nothing accumulates below them.
    let mut other = Skeleton::adult(1.0);
    let widen = 0.03;
    other.offsets[1][0] += widen;
    other.offsets[2][0] -= widen;
    let mut rng = Rng::new(8, 0);
    let clip: Vec<_> = (0..20)
        .map(|_| forward_kinematics(&other, [0.0, 0.9, 0.0], &random_pose(&mut rng, 1.0)).positions)
        .collect();
    let rig = measure_skeleton(&Skeleton::adult(1.0), &clip);
    let mut worst = 0.0f32;
    for pos in &clip {
        let again = forward_kinematics(&rig, pos[0], &retarget(&rig, pos)).positions;
        for j in 0..JOINTS {
            worst = worst.max(norm(sub(again[j], pos[j])));
        }
    }
    println!("wider-hips retarget worst joint error {worst:.4} m (hips widened by {widen} m)");
    assert!(worst > 1e-3, "a residual is expected here");
    assert!(worst < widen, "{worst}");
}
