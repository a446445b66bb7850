//! Rotation conversions: matrix <-> quaternion (x, y, z, w), matrix <->
//! BVH Euler angles (ZXY), and the nearest rotation of an arbitrary 3x3.

use super::math::{cross, dot, from_cols, mat_mul, rot_x, rot_y, rot_z, Mat3, IDENTITY};

/// A unit quaternion stored as (x, y, z, w), the glTF order.
pub type Quat = [f32; 4];

/// The quaternion of a rotation matrix (Shepperd's method; `w >= 0`).
pub fn quat_from_mat(m: &Mat3) -> Quat {
    let (m00, m11, m22) = (m[0][0] as f64, m[1][1] as f64, m[2][2] as f64);
    let tr = m00 + m11 + m22;
    let g = |r: usize, c: usize| m[r][c] as f64;
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0; // 4w
        [
            (g(2, 1) - g(1, 2)) / s,
            (g(0, 2) - g(2, 0)) / s,
            (g(1, 0) - g(0, 1)) / s,
            0.25 * s,
        ]
    } else if m00 > m11 && m00 > m22 {
        let s = (1.0 + m00 - m11 - m22).sqrt() * 2.0; // 4x
        [
            0.25 * s,
            (g(0, 1) + g(1, 0)) / s,
            (g(0, 2) + g(2, 0)) / s,
            (g(2, 1) - g(1, 2)) / s,
        ]
    } else if m11 > m22 {
        let s = (1.0 + m11 - m00 - m22).sqrt() * 2.0; // 4y
        [
            (g(0, 1) + g(1, 0)) / s,
            0.25 * s,
            (g(1, 2) + g(2, 1)) / s,
            (g(0, 2) - g(2, 0)) / s,
        ]
    } else {
        let s = (1.0 + m22 - m00 - m11).sqrt() * 2.0; // 4z
        [
            (g(0, 2) + g(2, 0)) / s,
            (g(1, 2) + g(2, 1)) / s,
            0.25 * s,
            (g(1, 0) - g(0, 1)) / s,
        ]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let sign = if q[3] < 0.0 { -1.0 } else { 1.0 };
    [
        (sign * q[0] / n) as f32,
        (sign * q[1] / n) as f32,
        (sign * q[2] / n) as f32,
        (sign * q[3] / n) as f32,
    ]
}

/// The rotation matrix of a quaternion (normalized first).
pub fn mat_from_quat(q: Quat) -> Mat3 {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if n.is_nan() || n <= 1e-12 {
        return IDENTITY;
    }
    let [x, y, z, w] = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Euler angles (z, x, y) in radians with `R = Rz(z) Rx(x) Ry(y)`: the BVH
/// channel order `Zrotation Xrotation Yrotation`. At gimbal lock
/// (|x| = 90 degrees) the y angle is set to 0.
pub fn euler_zxy_from_mat(m: &Mat3) -> [f32; 3] {
    let sx = m[2][1].clamp(-1.0, 1.0);
    let x = sx.asin();
    if sx.abs() < 0.999_999 {
        let y = (-m[2][0]).atan2(m[2][2]);
        let z = (-m[0][1]).atan2(m[1][1]);
        [z, x, y]
    } else {
        [m[1][0].atan2(m[0][0]), x, 0.0]
    }
}

/// Inverse of [`euler_zxy_from_mat`].
pub fn mat_from_euler_zxy(e: [f32; 3]) -> Mat3 {
    mat_mul(&rot_z(e[0]), &mat_mul(&rot_x(e[1]), &rot_y(e[2])))
}

/// Symmetric 3x3 eigen-decomposition by cyclic Jacobi rotations (f64).
/// Returns (eigenvalues, eigenvectors as columns of the matrix).
fn sym_eigen(a: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = a;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..64 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A <- J^T A J with J the (p, q) rotation.
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

fn norm64(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}
fn cross64(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit64(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm64(a);
    (n > 1e-12).then(|| [a[0] / n, a[1] / n, a[2] / n])
}
fn any_perp(a: [f64; 3]) -> [f64; 3] {
    let h = if a[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    unit64(cross64(a, h)).unwrap_or([0.0, 0.0, 1.0])
}

/// The proper rotation nearest to `m` in the Frobenius norm: `U V^T` from
/// the SVD `m = U S V^T`, with the last singular direction flipped when
/// `det(m) < 0` (so the result always has determinant +1). This is the
/// projection applied to decoder rotation outputs. A zero or non-finite
/// matrix yields the identity.
pub fn nearest_rotation(m: &Mat3) -> Mat3 {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return IDENTITY;
    }
    let md: [[f64; 3]; 3] = [
        [m[0][0] as f64, m[0][1] as f64, m[0][2] as f64],
        [m[1][0] as f64, m[1][1] as f64, m[1][2] as f64],
        [m[2][0] as f64, m[2][1] as f64, m[2][2] as f64],
    ];
    // M^T M = V diag(s^2) V^T.
    let mut mtm = [[0.0f64; 3]; 3];
    for (r, row) in mtm.iter_mut().enumerate() {
        for (c, out) in row.iter_mut().enumerate() {
            *out = (0..3).map(|k| md[k][r] * md[k][c]).sum();
        }
    }
    let (vals, vecs) = sym_eigen(mtm);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| {
        vals[j]
            .partial_cmp(&vals[i])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let col = |i: usize| [vecs[0][i], vecs[1][i], vecs[2][i]];
    let v1 = col(order[0]);
    let v2 = unit64({
        let c = col(order[1]);
        let d = c[0] * v1[0] + c[1] * v1[1] + c[2] * v1[2];
        [c[0] - d * v1[0], c[1] - d * v1[1], c[2] - d * v1[2]]
    })
    .unwrap_or_else(|| any_perp(v1));
    let v3 = cross64(v1, v2);
    let mv = |v: [f64; 3]| {
        [
            md[0][0] * v[0] + md[0][1] * v[1] + md[0][2] * v[2],
            md[1][0] * v[0] + md[1][1] * v[1] + md[1][2] * v[2],
            md[2][0] * v[0] + md[2][1] * v[1] + md[2][2] * v[2],
        ]
    };
    let Some(u1) = unit64(mv(v1)) else {
        return IDENTITY;
    };
    let mv2 = mv(v2);
    let d = mv2[0] * u1[0] + mv2[1] * u1[1] + mv2[2] * u1[2];
    let u2 = unit64([mv2[0] - d * u1[0], mv2[1] - d * u1[1], mv2[2] - d * u1[2]])
        .unwrap_or_else(|| any_perp(u1));
    let u3 = cross64(u1, u2);
    // R = U V^T = sum_i u_i v_i^T.
    let mut r = [[0.0f32; 3]; 3];
    for (a, row) in r.iter_mut().enumerate() {
        for (b, out) in row.iter_mut().enumerate() {
            *out = (u1[a] * v1[b] + u2[a] * v2[b] + u3[a] * v3[b]) as f32;
        }
    }
    r
}

/// Re-orthonormalizes an almost-rotation cheaply (Gram-Schmidt on the
/// columns); used after long products of f32 matrices.
pub fn orthonormalize(m: &Mat3) -> Mat3 {
    let c0 = [m[0][0], m[1][0], m[2][0]];
    let c1 = [m[0][1], m[1][1], m[2][1]];
    let a = super::math::normalize_or(c0, [1.0, 0.0, 0.0]);
    let b = super::math::normalize_or(
        super::math::sub(c1, super::math::scale(a, dot(c1, a))),
        [0.0, 1.0, 0.0],
    );
    from_cols(a, b, cross(a, b))
}
