//! Small 3-D vector and 3x3 matrix helpers used by the skeleton, the
//! synthesizer and the exporters.
//!
//! Conventions: a [`Mat3`] is row-major (`m[row][col]`) and acts on column
//! vectors (`v' = M v`), like `scipy.spatial.transform.Rotation.as_matrix`
//! and the dataset's `rotmat` files. Angles are radians.

/// A 3-vector (x, y, z).
pub type Vec3 = [f32; 3];
/// A row-major 3x3 matrix.
pub type Mat3 = [[f32; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub fn scale(a: Vec3, s: f32) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub fn dot(a: Vec3, b: Vec3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn norm(a: Vec3) -> f32 {
    dot(a, a).sqrt()
}
/// `a` scaled to unit length; `fallback` when `a` is (nearly) zero.
pub fn normalize_or(a: Vec3, fallback: Vec3) -> Vec3 {
    let n = norm(a);
    if n > 1e-9 && n.is_finite() {
        scale(a, 1.0 / n)
    } else {
        fallback
    }
}
/// Linear interpolation `a + (b - a) t`.
pub fn lerp(a: Vec3, b: Vec3, t: f32) -> Vec3 {
    add(a, scale(sub(b, a), t))
}

pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c];
        }
    }
    out
}
pub fn transpose(m: &Mat3) -> Mat3 {
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}
pub fn det(m: &Mat3) -> f32 {
    dot(m[0], cross(m[1], m[2]))
}
/// The matrix whose columns are `a`, `b`, `c`.
pub fn from_cols(a: Vec3, b: Vec3, c: Vec3) -> Mat3 {
    [[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]]
}
/// Row-major flattening (9 floats), the dataset's `rotmat` layout.
pub fn flatten(m: &Mat3) -> [f32; 9] {
    [
        m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
    ]
}
/// Inverse of [`flatten`].
pub fn unflatten(v: &[f32]) -> Mat3 {
    [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]
}
/// Largest absolute entry difference.
pub fn max_abs_diff(a: &Mat3, b: &Mat3) -> f32 {
    let (fa, fb) = (flatten(a), flatten(b));
    fa.iter()
        .zip(fb.iter())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Rotation about +x.
pub fn rot_x(a: f32) -> Mat3 {
    let (s, c) = a.sin_cos();
    [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
}
/// Rotation about +y (yaw; positive turns +z towards +x).
pub fn rot_y(a: f32) -> Mat3 {
    let (s, c) = a.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}
/// Rotation about +z.
pub fn rot_z(a: f32) -> Mat3 {
    let (s, c) = a.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}
/// Rotation by `angle` about the unit `axis` (Rodrigues).
pub fn axis_angle(axis: Vec3, angle: f32) -> Mat3 {
    let [x, y, z] = axis;
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// The smallest rotation taking unit vector `from` onto unit vector `to`
/// (a "swing": no twist about either vector).
pub fn swing(from: Vec3, to: Vec3) -> Mat3 {
    let axis = cross(from, to);
    let s = norm(axis);
    let c = dot(from, to).clamp(-1.0, 1.0);
    if s < 1e-7 {
        if c > 0.0 {
            return IDENTITY;
        }
        // Opposite vectors: half turn about any axis perpendicular to `from`.
        let helper = if from[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let perp = normalize_or(cross(from, helper), [0.0, 0.0, 1.0]);
        return axis_angle(perp, std::f32::consts::PI);
    }
    axis_angle(scale(axis, 1.0 / s), s.atan2(c))
}

/// An orthonormal right-handed basis (as matrix columns) whose first axis is
/// `primary` and whose second axis lies in the plane of `primary` and
/// `secondary`, on `secondary`'s side.
pub fn basis(primary: Vec3, secondary: Vec3) -> Mat3 {
    let a = normalize_or(primary, [0.0, 1.0, 0.0]);
    let mut b = sub(secondary, scale(a, dot(secondary, a)));
    if norm(b) < 1e-6 {
        let helper = if a[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        b = sub(helper, scale(a, dot(helper, a)));
    }
    let b = normalize_or(b, [0.0, 0.0, 1.0]);
    from_cols(a, b, cross(a, b))
}

/// The rotation taking direction `rest_dir` onto `dir` exactly while taking
/// the reference `rest_ref` as close as possible to `reference` (both
/// references projected perpendicular to their directions).
pub fn align(rest_dir: Vec3, rest_ref: Vec3, dir: Vec3, reference: Vec3) -> Mat3 {
    mat_mul(
        &basis(dir, reference),
        &transpose(&basis(rest_dir, rest_ref)),
    )
}
