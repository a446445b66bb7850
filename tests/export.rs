//! glb / bvh / npy export: structural round trips and FK agreement.

use duolando::export::{bvh, glb, write_all, Motion};
use duolando::skeleton::math::{add, mat_mul, mat_vec, norm, sub, unflatten, Vec3};
use duolando::skeleton::rotation::{mat_from_quat, quat_from_mat};
use duolando::skeleton::{parent, JOINTS, POS_DIM, ROT_DIM};
use duolando::synth::{demo_take, rng::Rng};
use serde_json::Value;

/// f32 FK over ~10 joints; glb stores exact f32 quaternions.
const GLB_TOL_M: f32 = 1e-4;
/// BVH text keeps 5 decimals of degrees and 6 of centimetres.
const BVH_TOL_M: f32 = 5e-4;
/// Retargeting a rigid clip made on the same joint tree.
const RETARGET_TOL_M: f32 = 1e-4;

fn motions() -> (Motion, Motion) {
    let take = demo_take(21, 4.0);
    (
        Motion::from_track(&take.leader),
        Motion::from_track(&take.follower),
    )
}

fn joint(pos: &[f32], t: usize, j: usize) -> Vec3 {
    let o = t * POS_DIM + 3 * j;
    [pos[o], pos[o + 1], pos[o + 2]]
}

fn floats(bin: &[u8], offset: usize, n: usize) -> Vec<f32> {
    bin[offset..offset + 4 * n]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// The accessor's data (offset in BIN, count, components).
fn accessor(doc: &Value, bin: &[u8], i: usize) -> (Vec<f32>, usize) {
    let a = &doc["accessors"][i];
    let v = &doc["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
    let comps = match a["type"].as_str().unwrap() {
        "SCALAR" => 1,
        "VEC3" => 3,
        "VEC4" => 4,
        t => panic!("unexpected type {t}"),
    };
    assert_eq!(a["componentType"], 5126);
    let count = a["count"].as_u64().unwrap() as usize;
    let off =
        v["byteOffset"].as_u64().unwrap() as usize + a["byteOffset"].as_u64().unwrap_or(0) as usize;
    assert_eq!(off % 4, 0, "accessor {i} misaligned");
    assert!(
        off + 4 * comps * count
            <= v["byteOffset"].as_u64().unwrap() as usize
                + v["byteLength"].as_u64().unwrap() as usize
    );
    (floats(bin, off, comps * count), count)
}

#[test]
fn glb_round_trip_structure_and_fk() {
    let (l, f) = motions();
    let bytes = glb::to_bytes(&[("leader", &l), ("follower", &f)], 30.0).unwrap();
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(u32::from_le_bytes(bytes[4..8].try_into().unwrap()), 2);
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
        bytes.len()
    );
    let (doc, bin) = glb::parse(&bytes, "test.glb").unwrap();
    assert_eq!(doc["asset"]["version"], "2.0");
    assert_eq!(
        doc["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
        bin.len()
    );
    let nodes = doc["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 2 * glb::NODES_PER_DANCER);
    let mut names: Vec<&str> = nodes.iter().map(|n| n["name"].as_str().unwrap()).collect();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), nodes.len(), "node names must be unique");
    // Times: accessor 0, with min/max.
    let (times, n) = accessor(&doc, &bin, 0);
    assert_eq!(n, l.frames);
    assert_eq!(
        doc["accessors"][0]["max"][0].as_f64().unwrap() as f32,
        times[n - 1]
    );
    assert!((times[1] - 1.0 / 30.0).abs() < 1e-7);
    // Rebuild every frame's FK from the glb's own data and compare.
    let anim = &doc["animations"][0];
    assert_eq!(anim["channels"].as_array().unwrap().len(), 2 * (JOINTS + 1));
    let mut worst = 0.0f32;
    for (d, m) in [&l, &f].iter().enumerate() {
        let base = d * glb::NODES_PER_DANCER + 1;
        let mut rot = vec![Vec::new(); JOINTS];
        let mut root = Vec::new();
        for ch in anim["channels"].as_array().unwrap() {
            let node = ch["target"]["node"].as_u64().unwrap() as usize;
            if node < base || node >= base + JOINTS {
                continue;
            }
            let s = &anim["samplers"][ch["sampler"].as_u64().unwrap() as usize];
            assert_eq!(s["input"], 0);
            let (data, count) = accessor(&doc, &bin, s["output"].as_u64().unwrap() as usize);
            assert_eq!(count, m.frames);
            match ch["target"]["path"].as_str().unwrap() {
                "rotation" => rot[node - base] = data,
                "translation" => root = data,
                p => panic!("unexpected path {p}"),
            }
        }
        // First-frame values sit in the nodes too.
        let q0 = quat_from_mat(&unflatten(&m.rotmats[9 * 3..9 * 4]));
        let nq: Vec<f32> = nodes[base + 3]["rotation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        assert!(
            q0.iter().zip(&nq).all(|(a, b)| (a - b).abs() < 1e-6),
            "{q0:?} vs {nq:?}"
        );
        for t in 0..m.frames {
            let mut world = vec![[[0.0f32; 3]; 3]; JOINTS];
            let mut pos = vec![[0.0f32; 3]; JOINTS];
            for j in 0..JOINTS {
                let q = [
                    rot[j][4 * t],
                    rot[j][4 * t + 1],
                    rot[j][4 * t + 2],
                    rot[j][4 * t + 3],
                ];
                let r = mat_from_quat(q);
                let tr: Vec<f32> = nodes[base + j]["translation"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap() as f32)
                    .collect();
                match parent(j) {
                    None => {
                        pos[j] = [root[3 * t], root[3 * t + 1], root[3 * t + 2]];
                        world[j] = r;
                    }
                    Some(p) => {
                        pos[j] = add(pos[p], mat_vec(&world[p], [tr[0], tr[1], tr[2]]));
                        world[j] = mat_mul(&world[p], &r);
                    }
                }
                worst = worst.max(norm(sub(pos[j], joint(&m.positions, t, j))));
            }
        }
    }
    println!("glb FK worst joint error {worst:.2e} m");
    assert!(worst < GLB_TOL_M, "{worst}");
}

#[test]
fn bvh_round_trip_reproduces_positions() {
    let (l, _) = motions();
    let text = bvh::to_string(&l, 30.0, bvh::Units::Centimetres);
    assert!(text.contains("Frame Time: 0.0333333"));
    let clip = bvh::parse(&text, "leader.bvh").unwrap();
    assert_eq!(clip.joints.len(), JOINTS);
    assert_eq!(clip.frames, l.frames);
    let order = bvh::depth_first_order();
    let mut worst = 0.0f32;
    for t in 0..clip.frames {
        let p = clip.positions(t);
        for (k, &j) in order.iter().enumerate() {
            let got = [p[k][0] / 100.0, p[k][1] / 100.0, p[k][2] / 100.0];
            worst = worst.max(norm(sub(got, joint(&l.positions, t, j))));
        }
    }
    println!("bvh FK worst joint error {worst:.2e} m");
    assert!(worst < BVH_TOL_M, "{worst}");
    // Metres variant has the same shape.
    let m = bvh::parse(&bvh::to_string(&l, 30.0, bvh::Units::Metres), "m.bvh").unwrap();
    assert!((m.positions(0)[0][1] - clip.positions(0)[0][1] / 100.0).abs() < 1e-5);
}

#[test]
fn bvh_reader_rejects_broken_files() {
    let (l, _) = motions();
    let text = bvh::to_string(&l, 30.0, bvh::Units::Centimetres);
    let cut = &text[..text.len() - 40];
    let e = bvh::parse(cut, "cut.bvh").unwrap_err().to_string();
    assert!(e.contains("cut.bvh") && e.contains("values"), "{e}");
    assert!(bvh::parse("HELLO", "x.bvh")
        .unwrap_err()
        .to_string()
        .contains("HIERARCHY"));
    let bad = text.replacen("Zrotation", "Wrotation", 1);
    assert!(bvh::parse(&bad, "w.bvh")
        .unwrap_err()
        .to_string()
        .contains("unknown channel"));
}

#[test]
fn motion_from_positions_retargets_exactly_on_rigid_input() {
    let (l, _) = motions();
    let m = Motion::from_positions(&l.positions, "leader positions").unwrap();
    println!("from_positions fit error {:.2e} m", m.fit_error_m);
    assert!(m.fit_error_m < RETARGET_TOL_M);
    let worst = m
        .positions
        .iter()
        .zip(&l.positions)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(worst < RETARGET_TOL_M);
}

#[test]
fn decoded_rotations_are_projected_before_fk() {
    let (l, _) = motions();
    let mut rng = Rng::new(9, 0);
    let noisy: Vec<f32> = l.rotmats.iter().map(|v| v + 0.05 * rng.normal()).collect();
    let m = Motion::from_decoded(&l.positions, Some(&noisy), "decoded").unwrap();
    for r in m.rotmats.chunks_exact(9) {
        let r = unflatten(r);
        let rrt = mat_mul(&r, &duolando::skeleton::math::transpose(&r));
        assert!(
            duolando::skeleton::math::max_abs_diff(&rrt, &duolando::skeleton::math::IDENTITY)
                < 1e-5
        );
    }
    // Noise of 0.05 per entry moves joints by centimetres, not metres.
    println!("decoded-rotation fit error {:.3} m", m.fit_error_m);
    assert!(
        m.fit_error_m > 1e-3 && m.fit_error_m < 0.3,
        "{}",
        m.fit_error_m
    );
    // Clean rotations reproduce the positions.
    let clean = Motion::from_decoded(&l.positions, Some(&l.rotmats), "decoded").unwrap();
    assert!(clean.fit_error_m < RETARGET_TOL_M, "{}", clean.fit_error_m);
}

#[test]
fn bad_inputs_are_named_errors() {
    let e = Motion::from_positions(&[0.0; 100], "leader.npy")
        .unwrap_err()
        .to_string();
    assert!(e.contains("leader.npy") && e.contains("165"), "{e}");
    let mut p = vec![0.0; POS_DIM];
    p[7] = f32::NAN;
    assert!(Motion::from_positions(&p, "nan.npy")
        .unwrap_err()
        .to_string()
        .contains("not finite"));
    let e = Motion::from_decoded(&vec![0.0; POS_DIM * 2], Some(&vec![0.0; ROT_DIM]), "dec")
        .unwrap_err()
        .to_string();
    assert!(e.contains("495"), "{e}");
    let (l, f) = motions();
    let mut short = f.clone();
    short.frames -= 1;
    assert!(glb::to_bytes(&[("leader", &l), ("follower", &short)], 30.0).is_err());
    assert!(glb::parse(b"glTF\x02\0\0\0\x10\0\0\0", "tiny.glb")
        .unwrap_err()
        .to_string()
        .contains("tiny.glb"));
}

#[test]
fn write_all_writes_the_export_set() {
    let (l, f) = motions();
    // DUO_KEEP_EXPORT=DIR keeps the files (e.g. for gltf-validator).
    let keep = std::env::var_os("DUO_KEEP_EXPORT").map(std::path::PathBuf::from);
    let dir = keep
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join(format!("duo-export-{}", std::process::id())));
    let files = write_all(&dir, Some(&l), &f).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for want in [
        "follower.glb",
        "leader.bvh",
        "follower.bvh",
        "leader_pos3d.npy",
        "follower_rotmat.npy",
    ] {
        assert!(
            names.iter().any(|n| n == want),
            "{want} missing from {names:?}"
        );
    }
    let pos =
        duolando::npy::read_f32_2d(&dir.join("follower_pos3d.npy"), Some(POS_DIM), "pos").unwrap();
    assert_eq!(pos.rows, f.frames);
    assert_eq!(pos.data, f.positions);
    let rot =
        duolando::npy::read_f32_2d(&dir.join("leader_rotmat.npy"), Some(ROT_DIM), "rot").unwrap();
    assert_eq!(rot.data, l.rotmats);
    if keep.is_none() {
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// Bytes of accessor `i` (offset into BIN and element count).
fn accessor_bytes<'a>(doc: &Value, bin: &'a [u8], i: usize, elem: usize) -> (&'a [u8], usize) {
    let a = &doc["accessors"][i];
    let v = &doc["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
    let count = a["count"].as_u64().unwrap() as usize;
    let off =
        v["byteOffset"].as_u64().unwrap() as usize + a["byteOffset"].as_u64().unwrap_or(0) as usize;
    assert!(
        off + elem * count
            <= v["byteOffset"].as_u64().unwrap() as usize
                + v["byteLength"].as_u64().unwrap() as usize
    );
    (&bin[off..off + elem * count], count)
}

/// The mannequin mesh: a skin over the 55 joint nodes, rigid weights, and,
/// skinned by hand with the animation's FK, every vertex sits on its
/// capsule's surface around the FK joint positions (the capsules of the
/// interpenetration measure) at every sampled frame.
#[test]
fn glb_mannequin_is_skinned_to_the_animation() {
    use duolando::skeleton::body::{end_point, radius_scale, CAPSULES};
    use duolando::skeleton::fk::{forward_kinematics, frame_rotations};
    let (l, f) = motions();
    let (doc, bin) = glb::parse(
        &glb::to_bytes(&[("leader", &l), ("follower", &f)], 30.0).unwrap(),
        "t.glb",
    )
    .unwrap();
    assert_eq!(doc["skins"].as_array().unwrap().len(), 2);
    assert_eq!(doc["meshes"].as_array().unwrap().len(), 2);
    for (d, m) in [&l, &f].iter().enumerate() {
        let base = d * glb::NODES_PER_DANCER;
        let mesh_node = &doc["nodes"][base + glb::NODES_PER_DANCER - 1];
        assert!(
            doc["scenes"][0]["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .any(|n| n.as_u64() == Some((base + glb::NODES_PER_DANCER - 1) as u64)),
            "mesh node is a scene root"
        );
        assert!(mesh_node.get("translation").is_none() && mesh_node.get("rotation").is_none());
        let skin = &doc["skins"][mesh_node["skin"].as_u64().unwrap() as usize];
        let joints: Vec<usize> = skin["joints"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(joints, (base + 1..base + 1 + JOINTS).collect::<Vec<_>>());
        let prim = &doc["meshes"][mesh_node["mesh"].as_u64().unwrap() as usize]["primitives"][0];
        let attr = |k: &str| prim["attributes"][k].as_u64().unwrap() as usize;
        let (pos, n) = accessor(&doc, &bin, attr("POSITION"));
        let (jb, nj) = accessor_bytes(&doc, &bin, attr("JOINTS_0"), 4);
        let (wb, nw) = accessor_bytes(&doc, &bin, attr("WEIGHTS_0"), 4);
        assert_eq!((nj, nw), (n, n));
        let (ibm_b, ni) = accessor_bytes(
            &doc,
            &bin,
            skin["inverseBindMatrices"].as_u64().unwrap() as usize,
            64,
        );
        assert_eq!(ni, JOINTS);
        let ibm: Vec<f32> = ibm_b
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let per = n / CAPSULES.len();
        assert_eq!(per * CAPSULES.len(), n);
        let k = radius_scale(&m.skeleton).clamp(0.25, 4.0);
        let mut worst = 0.0f32;
        for t in (0..m.frames).step_by(17) {
            let root = [m.roots[3 * t], m.roots[3 * t + 1], m.roots[3 * t + 2]];
            let pose = forward_kinematics(&m.skeleton, root, &frame_rotations(&m.rotmats, t));
            for (i, c) in CAPSULES.iter().enumerate() {
                let (a, b) = (
                    end_point(c.a, &pose.positions),
                    end_point(c.b, &pose.positions),
                );
                for v in i * per..(i + 1) * per {
                    assert_eq!(
                        (jb[4 * v] as usize, &wb[4 * v..4 * v + 4]),
                        (c.bind, &[255u8, 0, 0, 0][..]),
                        "vertex {v}"
                    );
                    let j = c.bind;
                    let local = [
                        pos[3 * v] + ibm[16 * j + 12],
                        pos[3 * v + 1] + ibm[16 * j + 13],
                        pos[3 * v + 2] + ibm[16 * j + 14],
                    ];
                    let world = add(pose.positions[j], mat_vec(&pose.world[j], local));
                    let dist = duolando::skeleton::body::segment_distance(world, world, a, b);
                    worst = worst.max((dist - c.radius * k).abs());
                }
            }
        }
        println!("dancer {d}: {n} vertices, worst distance from the capsule surface {worst:.2e} m");
        assert!(worst < 1e-4, "{worst}");
    }
}
