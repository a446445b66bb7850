//! Exponential map -> rotation matrix (Rodrigues). pymo stores each joint's
//! rotation as `axis * angle` (radians; `<joint>_alpha/_beta/_gamma` =
//! x, y, z) and goes back through Euler angles (rotation_tools.expmap2euler,
//! then Quaternions.from_euler in the joint's channel order); that round
//! trip is the same rotation, which this computes directly:
//! `R = I + (sin t / t) K + 2 (sin(t/2) / t)^2 K^2`, `K = [v]x`, `t = |v|`
//! (the second coefficient written with the half angle so that small
//! angles lose nothing to `1 - cos t`; below 1e-8 rad the series).

/// A row-major 3x3 matrix acting on column vectors, f64.
pub type Mat3d = [[f64; 3]; 3];

/// The rotation whose exponential map is `v` (axis * angle, radians).
pub fn rotation(v: [f64; 3]) -> Mat3d {
    let t2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    let t = t2.sqrt();
    let (a, b) = if t < 1e-8 {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        let h = (0.5 * t).sin() / t;
        (t.sin() / t, 2.0 * h * h)
    };
    let [x, y, z] = v;
    // I + a K + b K^2 with K = [[0,-z,y],[z,0,-x],[-y,x,0]], K^2 = v v^T - t^2 I.
    [
        [
            1.0 + b * (x * x - t2),
            -a * z + b * x * y,
            a * y + b * x * z,
        ],
        [
            a * z + b * x * y,
            1.0 + b * (y * y - t2),
            -a * x + b * y * z,
        ],
        [
            -a * y + b * x * z,
            a * x + b * y * z,
            1.0 + b * (z * z - t2),
        ],
    ]
}

/// A rotation about +y by `angle` radians (the heading).
pub fn about_y(angle: f64) -> Mat3d {
    let (s, c) = angle.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}

pub fn mul(a: &Mat3d, b: &Mat3d) -> Mat3d {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    m
}

pub fn apply(a: &Mat3d, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Mat3d, b: &Mat3d, tol: f64) -> bool {
        a.iter()
            .flatten()
            .zip(b.iter().flatten())
            .all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn known_rotations() {
        let q = std::f64::consts::FRAC_PI_2;
        // 90 degrees about z takes x to y.
        let r = rotation([0.0, 0.0, q]);
        let v = apply(&r, [1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-15 && (v[1] - 1.0).abs() < 1e-15);
        // About y agrees with the heading helper (pymo's Quaternions.from_angle_axis about +y).
        assert!(close(&rotation([0.0, 0.7, 0.0]), &about_y(0.7), 1e-15));
        assert!(close(&rotation([0.0; 3]), &about_y(0.0), 0.0));
    }

    /// Orthonormal with det 1 for angles from 0 to past pi, and continuous
    /// across the series threshold.
    #[test]
    fn proper_and_continuous() {
        for &t in &[
            0.0,
            1e-12,
            9.9e-9,
            1.01e-8,
            1e-4,
            0.5,
            3.1,
            std::f64::consts::PI,
            4.0,
        ] {
            let axis = [0.48, -0.6, 0.64];
            let r = rotation(axis.map(|a| a * t));
            let rt = [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[j][i]));
            let id = mul(&r, &rt);
            assert!(
                close(&id, &about_y(0.0), 1e-15),
                "angle {t}: R R^T = {id:?}"
            );
        }
        // Just below the series threshold: the closed form, evaluated here.
        let t = 0.999_999e-8f64;
        let r = rotation([0.0, 0.0, t]);
        let (sn, cs) = t.sin_cos();
        assert_eq!(r[0][1], -sn);
        assert!((r[0][0] - cs).abs() <= 1e-16 && (r[1][0] - sn).abs() <= 1e-16 * sn);
    }
}
