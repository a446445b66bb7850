//! A procedural mannequin mesh for the glTF export: one capsule per entry
//! of [`skeleton::body::CAPSULES`](crate::skeleton::body::CAPSULES), in the
//! rig's bind pose (rest pose, pelvis at the origin), each vertex skinned
//! rigidly (weight 1) to the capsule's joint. Normals are the capsule's
//! exact surface normals; triangles wind counter-clockwise seen from
//! outside (glTF front faces).

use crate::skeleton::body::{end_point, radius_scale, CAPSULES};
use crate::skeleton::math::{add, cross, normalize_or, scale, sub, Vec3};
use crate::skeleton::Skeleton;

/// Vertices around a capsule.
pub const SIDES: usize = 10;
/// Rings per hemisphere (the last one is the equator).
pub const RINGS: usize = 4;

/// A skinned triangle mesh in bind space (metres).
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// Index into the 55 joints (skin.joints order = joint order).
    pub joints: Vec<u8>,
    pub indices: Vec<u16>,
}

/// The mannequin of `skel`: capsule radii scaled with the rig's size.
pub fn mesh(skel: &Skeleton) -> Mesh {
    let rest = skel.rest_positions();
    let k = radius_scale(skel).clamp(0.25, 4.0);
    let mut m = Mesh::default();
    for c in CAPSULES.iter() {
        let a = end_point(c.a, &rest);
        let b = end_point(c.b, &rest);
        capsule(&mut m, a, b, c.radius * k, c.bind as u8);
    }
    m
}

fn capsule(m: &mut Mesh, a: Vec3, b: Vec3, r: f32, joint: u8) {
    let u = normalize_or(sub(b, a), [0.0, 1.0, 0.0]);
    let helper = if u[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let v = normalize_or(cross(helper, u), [0.0, 0.0, 1.0]);
    let w = cross(u, v); // v x w = u
    let base = m.positions.len() as u16;
    let push = |centre: Vec3, n: Vec3, m: &mut Mesh| {
        let n = normalize_or(n, u);
        m.positions.push(add(centre, scale(n, r)));
        m.normals.push(n);
        m.joints.push(joint);
    };
    push(b, u, m); // top pole: vertex base
                   // 2 * RINGS rings of SIDES vertices: the top hemisphere around b (from
                   // near the pole down to the equator), then the bottom one around a
                   // (from the equator down to near the pole).
    for ring in 0..2 * RINGS {
        let (centre, phi) = if ring < RINGS {
            (
                b,
                (ring + 1) as f32 / RINGS as f32 * std::f32::consts::FRAC_PI_2,
            )
        } else {
            (
                a,
                std::f32::consts::FRAC_PI_2 * (1.0 + (ring - RINGS) as f32 / RINGS as f32),
            )
        };
        for s in 0..SIDES {
            let theta = s as f32 / SIDES as f32 * std::f32::consts::TAU;
            let radial = add(scale(v, theta.cos()), scale(w, theta.sin()));
            let n = add(scale(u, phi.cos()), scale(radial, phi.sin()));
            push(centre, n, m);
        }
    }
    push(a, scale(u, -1.0), m); // bottom pole
    let ring_at = |ring: usize, s: usize| base + 1 + (ring * SIDES + s % SIDES) as u16;
    let bottom = base + 1 + (2 * RINGS * SIDES) as u16;
    for s in 0..SIDES {
        m.indices
            .extend_from_slice(&[base, ring_at(0, s), ring_at(0, s + 1)]);
        for ring in 0..2 * RINGS - 1 {
            let (uk, uk1, lk, lk1) = (
                ring_at(ring, s),
                ring_at(ring, s + 1),
                ring_at(ring + 1, s),
                ring_at(ring + 1, s + 1),
            );
            m.indices.extend_from_slice(&[uk, lk, lk1, uk, lk1, uk1]);
        }
        let last = 2 * RINGS - 1;
        m.indices
            .extend_from_slice(&[bottom, ring_at(last, s + 1), ring_at(last, s)]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::math::{dot, norm};

    #[test]
    fn mesh_is_closed_outward_and_skinned_to_capsule_joints() {
        let m = mesh(&Skeleton::default());
        let per = 2 + 2 * RINGS * SIDES;
        assert_eq!(m.positions.len(), CAPSULES.len() * per);
        assert!(m.positions.len() < u16::MAX as usize);
        assert_eq!(m.indices.len() % 3, 0);
        assert!(m.indices.iter().all(|&i| (i as usize) < m.positions.len()));
        for n in &m.normals {
            assert!((norm(*n) - 1.0).abs() < 1e-5);
        }
        // Every triangle faces outwards: its geometric normal agrees with
        // its vertices' normals, and none is degenerate.
        for t in m.indices.chunks_exact(3) {
            let [p0, p1, p2] = [0, 1, 2].map(|k| m.positions[t[k] as usize]);
            let g = cross(sub(p1, p0), sub(p2, p0));
            assert!(norm(g) > 1e-10, "degenerate triangle {t:?}");
            let n = add(
                add(m.normals[t[0] as usize], m.normals[t[1] as usize]),
                m.normals[t[2] as usize],
            );
            assert!(dot(g, n) > 0.0, "triangle {t:?} faces inwards");
        }
        // Each capsule's vertices belong to its bind joint.
        for (i, c) in CAPSULES.iter().enumerate() {
            assert!(m.joints[i * per..(i + 1) * per]
                .iter()
                .all(|&j| j as usize == c.bind));
        }
        // Standing height of the adult rig: about 1.75 m from sole to crown.
        let ys = m.positions.iter().map(|p| p[1]);
        let h = ys.clone().fold(f32::MIN, f32::max) - ys.fold(f32::MAX, f32::min);
        assert!(h > 1.6 && h < 1.85, "{h}");
    }
}
