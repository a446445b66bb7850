//! Geometric ("manual") features (the "g" of FID_g / Div_g): 32 boolean
//! pose/velocity tests per frame in the style of Müller et al.'s
//! relational features, averaged over frames 1..T-1, as the extractor the
//! Duolando evaluation imports (`manual_new`) computes them on the 24-joint
//! skeleton of [`super::smpl24_rooted`]:
//!
//! - thresholds are multiples of a humerus length, shoulder width and hip
//!   width measured once on a fixed SMPL rest pose (not on the dancer);
//! - velocities use a hard-coded frame time of 1/120 s (the data is 30 fps);
//! - the floor height is the lowest joint of the current frame;
//! - angle tests are strict on both ends, and a NaN angle is false.
//!
//! The result is the fraction of frames where each test holds, as f32.

use super::{cross, dot, norm, smpl24_rooted, sub, EvalError, V3};

/// Frame time (s) of the velocity tests: 1/120, hard-coded by the authors.
pub const FRAME_TIME: f64 = 1.0 / 120.0;
/// Features per clip.
pub const DIM: usize = 32;
/// Shortest clip: one frame pair.
pub const MIN_FRAMES: usize = 2;

// SMPL 24 joint indices.
const ROOT: usize = 0;
const LHIP: usize = 1;
const RHIP: usize = 2;
const BELLY: usize = 3;
const LKNEE: usize = 4;
const RKNEE: usize = 5;
const LANKLE: usize = 7;
const RANKLE: usize = 8;
const CHEST: usize = 9;
const LTOES: usize = 10;
const RTOES: usize = 11;
const NECK: usize = 12;
const LSHOULDER: usize = 16;
const RSHOULDER: usize = 17;
const LELBOW: usize = 18;
const RELBOW: usize = 19;
const LWRIST: usize = 20;
const RWRIST: usize = 21;

// The fixed rest-pose points the thresholds are measured on (metres).
const REST_LSHOULDER: V3 = [1.99113488e-01, 2.36807942e-01, -1.80702247e-02];
const REST_LELBOW: V3 = [4.54445392e-01, 2.21158922e-01, -4.10167128e-02];
const REST_RSHOULDER: V3 = [-1.91692337e-01, 2.36928746e-01, -1.23055102e-02];
const REST_LHIP: V3 = [5.64076714e-02, -3.23069185e-01, 1.09197125e-02];
const REST_RHIP: V3 = [-6.24834076e-02, -3.31302464e-01, 1.50412619e-02];

/// A point a test reads: a joint, or one of the fixed points.
#[derive(Clone, Copy, Debug)]
enum P {
    J(usize),
    Zero,
    YUp,
    YDown,
    /// (0, lowest joint height of the frame, 0).
    Floor,
}

/// Unit of a threshold.
#[derive(Clone, Copy, Debug)]
enum U {
    Humerus,
    Shoulders,
    Hips,
}

/// One relational test.
#[derive(Clone, Copy, Debug)]
enum Test {
    /// Velocity of c relative to a, along b - a, above k units per second.
    /// The fourth point is named by the authors' table but never read
    /// (so "belly, chest, chest, rwrist" tests the chest, not the wrist).
    Along(P, P, P, P, f64, U),
    /// Velocity of d relative to a, along the normal (c - a) x (b - a), above k.
    AlongNormal(P, P, P, P, f64, U),
    /// Signed distance of d from the plane through a, b, c (normal (c-a) x (b-a)) above k.
    Plane(P, P, P, P, f64, U),
    /// Signed distance of d from the plane through c with normal b - a above k.
    NormalPlane(P, P, P, P, f64, U),
    /// Angle between b - a and d - c strictly inside (lo, hi) degrees.
    Angle(P, P, P, P, f64, f64),
    /// Speed of a above k units per second.
    Fast(P, f64, U),
}

use Test::*;
use P::J;
use U::*;

/// The 32 tests, in the extractor's order.
const TESTS: [Test; DIM] = [
    AlongNormal(J(NECK), J(RHIP), J(LHIP), J(RWRIST), 1.8, Humerus),
    AlongNormal(J(NECK), J(LHIP), J(RHIP), J(LWRIST), 1.8, Humerus),
    NormalPlane(J(CHEST), J(NECK), J(NECK), J(RWRIST), 0.2, Humerus),
    NormalPlane(J(CHEST), J(NECK), J(NECK), J(LWRIST), 0.2, Humerus),
    Along(J(BELLY), J(CHEST), J(CHEST), J(RWRIST), 1.8, Humerus),
    Along(J(BELLY), J(CHEST), J(CHEST), J(LWRIST), 1.8, Humerus),
    Angle(J(RELBOW), J(RSHOULDER), J(RELBOW), J(RWRIST), 0.0, 110.0),
    Angle(J(LELBOW), J(LSHOULDER), J(LELBOW), J(LWRIST), 0.0, 110.0),
    NormalPlane(
        J(LSHOULDER),
        J(RSHOULDER),
        J(LWRIST),
        J(RWRIST),
        2.5,
        Shoulders,
    ),
    Along(J(LWRIST), J(RWRIST), J(RWRIST), J(LWRIST), 1.4, Humerus),
    Along(J(RWRIST), J(ROOT), J(LWRIST), J(ROOT), 1.4, Humerus),
    Along(J(LWRIST), J(ROOT), J(RWRIST), J(ROOT), 1.4, Humerus),
    Fast(J(RWRIST), 2.5, Humerus),
    Fast(J(LWRIST), 2.5, Humerus),
    Plane(J(ROOT), J(LHIP), J(LTOES), J(RANKLE), 0.38, Humerus),
    Plane(J(ROOT), J(RHIP), J(RTOES), J(LANKLE), 0.38, Humerus),
    NormalPlane(P::Zero, P::YUp, P::Floor, J(RANKLE), 1.2, Humerus),
    NormalPlane(P::Zero, P::YUp, P::Floor, J(LANKLE), 1.2, Humerus),
    NormalPlane(J(LHIP), J(RHIP), J(LANKLE), J(RANKLE), 2.1, Hips),
    Angle(J(RKNEE), J(RHIP), J(RKNEE), J(RANKLE), 0.0, 110.0),
    Angle(J(LKNEE), J(LHIP), J(LKNEE), J(LANKLE), 0.0, 110.0),
    Fast(J(RANKLE), 2.5, Humerus),
    Fast(J(LANKLE), 2.5, Humerus),
    Angle(J(NECK), J(ROOT), J(RSHOULDER), J(RELBOW), 25.0, 180.0),
    Angle(J(NECK), J(ROOT), J(LSHOULDER), J(LELBOW), 25.0, 180.0),
    Angle(J(NECK), J(ROOT), J(RHIP), J(RKNEE), 50.0, 180.0),
    Angle(J(NECK), J(ROOT), J(LHIP), J(LKNEE), 50.0, 180.0),
    Plane(J(RANKLE), J(NECK), J(LANKLE), J(ROOT), 0.5, Humerus),
    Angle(J(NECK), J(ROOT), P::Zero, P::YUp, 70.0, 110.0),
    NormalPlane(P::Zero, P::YDown, P::Floor, J(RWRIST), -1.2, Humerus),
    NormalPlane(P::Zero, P::YDown, P::Floor, J(LWRIST), -1.2, Humerus),
    Fast(J(ROOT), 2.3, Humerus),
];

/// What geometric feature `i` tests, in words (`None` past [`DIM`]): the
/// test and its points as the authors' table names them, e.g. feature 4,
/// "velocity of chest relative to belly along belly->chest > 1.8
/// humerus/s" (the table's fourth point, never read, is left out).
pub fn feature_name(i: usize) -> Option<String> {
    let p = |p: P| -> String {
        match p {
            J(j) => match j {
                ROOT => "root",
                LHIP => "lhip",
                RHIP => "rhip",
                BELLY => "belly",
                LKNEE => "lknee",
                RKNEE => "rknee",
                LANKLE => "lankle",
                RANKLE => "rankle",
                CHEST => "chest",
                LTOES => "ltoes",
                RTOES => "rtoes",
                NECK => "neck",
                LSHOULDER => "lshoulder",
                RSHOULDER => "rshoulder",
                LELBOW => "lelbow",
                RELBOW => "relbow",
                LWRIST => "lwrist",
                RWRIST => "rwrist",
                _ => "joint",
            }
            .to_string(),
            P::Zero => "origin".into(),
            P::YUp => "+y".into(),
            P::YDown => "-y".into(),
            P::Floor => "floor".into(),
        }
    };
    let u = |u: U| match u {
        Humerus => "humerus",
        Shoulders => "shoulder width",
        Hips => "hip width",
    };
    Some(match *TESTS.get(i)? {
        Along(a, b, c, _, k, un) => format!(
            "velocity of {} relative to {} along {}->{} > {k} {}/s",
            p(c),
            p(a),
            p(a),
            p(b),
            u(un)
        ),
        AlongNormal(a, b, c, d, k, un) => format!(
            "velocity of {} relative to {} along the normal of ({}, {}, {}) > {k} {}/s",
            p(d),
            p(a),
            p(a),
            p(b),
            p(c),
            u(un)
        ),
        Plane(a, b, c, d, k, un) => format!(
            "{} in front of the plane ({}, {}, {}) by > {k} {}",
            p(d),
            p(a),
            p(b),
            p(c),
            u(un)
        ),
        NormalPlane(a, b, c, d, k, un) => format!(
            "{} past the plane through {} normal to {}->{} by > {k} {}",
            p(d),
            p(c),
            p(a),
            p(b),
            u(un)
        ),
        Angle(a, b, c, d, lo, hi) => format!(
            "angle of {}->{} and {}->{} in ({lo}, {hi}) degrees",
            p(a),
            p(b),
            p(c),
            p(d)
        ),
        Fast(a, k, un) => format!("speed of {} > {k} {}/s", p(a), u(un)),
    })
}

struct Units {
    humerus: f64,
    shoulders: f64,
    hips: f64,
}

impl Units {
    fn rest() -> Self {
        Units {
            humerus: norm(sub(REST_LSHOULDER, REST_LELBOW)),
            shoulders: norm(sub(REST_LSHOULDER, REST_RSHOULDER)),
            hips: norm(sub(REST_LHIP, REST_RHIP)),
        }
    }
    fn of(&self, k: f64, u: U) -> f64 {
        k * match u {
            Humerus => self.humerus,
            Shoulders => self.shoulders,
            Hips => self.hips,
        }
    }
}

fn at(frame: &[V3; 24], p: P) -> V3 {
    match p {
        J(j) => frame[j],
        P::Zero => [0.0, 0.0, 0.0],
        P::YUp => [0.0, 1.0, 0.0],
        P::YDown => [0.0, -1.0, 0.0],
        P::Floor => [
            0.0,
            frame.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min),
            0.0,
        ],
    }
}

/// Velocity of `p` relative to `a` between two frames, projected on `dir`, per second.
fn along(cur: &[V3; 24], prev: &[V3; 24], a: P, p: P, dir: V3) -> f64 {
    let v = sub(sub(at(cur, p), at(cur, a)), sub(at(prev, p), at(prev, a)));
    dot(v, dir) / norm(dir) / FRAME_TIME
}

fn holds(t: Test, cur: &[V3; 24], prev: &[V3; 24], u: &Units) -> bool {
    match t {
        Along(a, b, c, _unused, k, unit) => {
            let dir = sub(at(cur, b), at(cur, a));
            along(cur, prev, a, c, dir) > u.of(k, unit)
        }
        AlongNormal(a, b, c, d, k, unit) => {
            let dir = cross(sub(at(cur, c), at(cur, a)), sub(at(cur, b), at(cur, a)));
            along(cur, prev, a, d, dir) > u.of(k, unit)
        }
        Plane(a, b, c, d, k, unit) => {
            let pa = at(cur, a);
            let n = cross(sub(at(cur, c), pa), sub(at(cur, b), pa));
            dot(n, sub(at(cur, d), pa)) / norm(n) > u.of(k, unit)
        }
        NormalPlane(a, b, c, d, k, unit) => {
            let n = sub(at(cur, b), at(cur, a));
            dot(n, sub(at(cur, d), at(cur, c))) / norm(n) > u.of(k, unit)
        }
        Angle(a, b, c, d, lo, hi) => {
            let x = sub(at(cur, b), at(cur, a));
            let y = sub(at(cur, d), at(cur, c));
            let deg = (dot(x, y) / (norm(x) * norm(y))).acos().to_degrees();
            deg > lo && deg < hi
        }
        Fast(a, k, unit) => norm(sub(at(cur, a), at(prev, a))) / FRAME_TIME > u.of(k, unit),
    }
}

/// Geometric features of one SMPL-X clip ((T, 165) positions).
pub fn features(pos: &[f32]) -> Result<Vec<f32>, EvalError> {
    let joints = smpl24_rooted(pos)?;
    features_smpl24(&joints)
}

/// Geometric features of 24-joint positions (already rooted as the authors do).
pub fn features_smpl24(p: &[[V3; 24]]) -> Result<Vec<f32>, EvalError> {
    if p.len() < MIN_FRAMES {
        return Err(EvalError::TooShort {
            what: "geometric features",
            frames: p.len(),
            need: MIN_FRAMES,
        });
    }
    let units = Units::rest();
    let mut counts = [0u32; DIM];
    for t in 1..p.len() {
        for (count, test) in counts.iter_mut().zip(TESTS) {
            if holds(test, &p[t], &p[t - 1], &units) {
                *count += 1;
            }
        }
    }
    // numpy: float32 mean of 0/1 values = f32(count) / f32(frames).
    let n = (p.len() - 1) as f32;
    Ok(counts.iter().map(|&c| c as f32 / n).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rest_units_are_the_smpl_rest_lengths() {
        let u = Units::rest();
        assert!((u.humerus - 0.2560).abs() < 1e-3, "{}", u.humerus);
        assert!((u.shoulders - 0.3908).abs() < 1e-3, "{}", u.shoulders);
        assert!((u.hips - 0.1192).abs() < 1e-3, "{}", u.hips);
    }

    #[test]
    fn features_are_named_after_their_tests() {
        assert_eq!(
            feature_name(4).as_deref(),
            Some("velocity of chest relative to belly along belly->chest > 1.8 humerus/s")
        );
        assert_eq!(
            feature_name(12).as_deref(),
            Some("speed of rwrist > 2.5 humerus/s")
        );
        assert!((0..DIM).all(|i| feature_name(i).is_some()));
        assert_eq!(feature_name(DIM), None);
    }

    #[test]
    fn one_frame_is_a_named_error() {
        let err = features(&[0.0; 165]).unwrap_err();
        assert_eq!(
            err,
            EvalError::TooShort {
                what: "geometric features",
                frames: 1,
                need: 2
            }
        );
    }

    #[test]
    fn fast_root_counts_frames() {
        // All joints still except a pelvis that jumps 5 cm per frame (> 2.3 humerus lengths / s at 1/120 s).
        let t = 5;
        let mut pos = vec![0.0f32; t * 165];
        for f in 0..t {
            for j in 0..55 {
                pos[f * 165 + j * 3 + 1] = j as f32 * 0.01;
            }
            pos[f * 165] = f as f32 * 0.05;
        }
        let g = features(&pos).unwrap();
        assert_eq!(g[31], 1.0);
    }
}
