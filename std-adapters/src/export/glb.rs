//! glTF 2.0 binary (.glb) export: each dancer is a node hierarchy of the
//! SMPL-X joint tree under a group node named after the dancer, plus a
//! skinned mannequin mesh (export::mannequin) on a root node
//! `<dancer>_mesh`. Joint nodes are named `<dancer>_<joint>` (unique), carry
//! the rest offsets as translations, and are animated by one animation
//! ("dance"): a LINEAR rotation channel (quaternion x, y, z, w) per joint
//! and a translation channel on the pelvis. The skin binds the mesh in the
//! rest pose (pelvis at the origin, every rotation identity), so inverse
//! bind matrices are translations. Metres, y up, 30 fps.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};

use super::Motion;
use crate::skeleton::math::unflatten;
use crate::skeleton::rotation::quat_from_mat;
use crate::skeleton::{children, JOINTS, JOINT_NAMES, ROT_DIM};

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"
const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_SHORT: u32 = 5123;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// Nodes per dancer: the group node, 55 joints, then the mesh node.
pub const NODES_PER_DANCER: usize = JOINTS + 2;

/// Base colour (linear RGBA) of a dancer's mannequin: the viewer's colours
/// (leader #3ea6ff, follower #ff7a1a) converted from sRGB; grey otherwise.
fn colour(name: &str) -> [f32; 4] {
    let srgb = match name {
        "leader" => [0x3e, 0xa6, 0xff],
        "follower" => [0xff, 0x7a, 0x1a],
        _ => [0xb0, 0xb0, 0xb0],
    };
    let lin = |c: u8| {
        let c = c as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    [lin(srgb[0]), lin(srgb[1]), lin(srgb[2]), 1.0]
}

fn push_view(
    views: &mut Vec<Value>,
    bin: &mut Vec<u8>,
    bytes: &[u8],
    target: Option<u32>,
) -> usize {
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut v = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()});
    if let Some(t) = target {
        v["target"] = json!(t);
    }
    bin.extend_from_slice(bytes);
    views.push(v);
    views.len() - 1
}

fn f32_bytes<'a>(vals: impl IntoIterator<Item = &'a f32>) -> Vec<u8> {
    vals.into_iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Per-joint quaternions (x, y, z, w) over the clip, sign-continuous so that
/// linear/slerp interpolation between frames takes the short way.
fn quaternions(m: &Motion) -> Vec<[f32; 4]> {
    let mut q = vec![[0.0f32; 4]; JOINTS * m.frames]; // (55, T, 4), joint-major
    for j in 0..JOINTS {
        let mut prev = [0.0f32, 0.0, 0.0, 1.0];
        for t in 0..m.frames {
            let r = unflatten(&m.rotmats[t * ROT_DIM + 9 * j..t * ROT_DIM + 9 * j + 9]);
            let mut cur = quat_from_mat(&r);
            if cur.iter().zip(prev.iter()).map(|(a, b)| a * b).sum::<f32>() < 0.0 {
                cur = cur.map(|v| -v);
            }
            q[j * m.frames + t] = cur;
            prev = cur;
        }
    }
    q
}

fn push_f32s(bin: &mut Vec<u8>, vals: impl IntoIterator<Item = f32>) {
    for v in vals {
        bin.extend_from_slice(&v.to_le_bytes());
    }
}

/// Builds the .glb bytes for `dancers` (name, motion); all must have the
/// same number of frames.
pub fn to_bytes(dancers: &[(&str, &Motion)], fps: f32) -> Result<Vec<u8>> {
    let Some((_, first)) = dancers.first() else {
        bail!("glb export: no dancers given")
    };
    let frames = first.frames;
    if let Some((n, m)) = dancers.iter().find(|(_, m)| m.frames != frames) {
        bail!(
            "glb export: dancer {n} has {} frames, expected {frames} like the first",
            m.frames
        );
    }
    if fps.is_nan() || fps <= 0.0 {
        bail!("glb export: fps must be positive, got {fps}");
    }
    let mut bin = Vec::new();
    let mut views: Vec<Value> = Vec::new();
    let mut accessors: Vec<Value> = Vec::new();
    let mut nodes: Vec<Value> = Vec::new();
    let mut samplers: Vec<Value> = Vec::new();
    let mut channels: Vec<Value> = Vec::new();
    let mut meshes: Vec<Value> = Vec::new();
    let mut skins: Vec<Value> = Vec::new();
    let mut materials: Vec<Value> = Vec::new();

    // Keyframe times (T,), accessor 0 with the min/max the spec requires.
    let times: Vec<f32> = (0..frames).map(|t| t as f32 / fps).collect();
    views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": 4 * frames}));
    push_f32s(&mut bin, times.iter().copied());
    accessors.push(
        json!({"bufferView": 0, "componentType": FLOAT, "count": frames, "type": "SCALAR",
        "min": [times[0]], "max": [times[frames - 1]]}),
    );

    let mut scene_nodes = Vec::new();
    for (d, (name, m)) in dancers.iter().enumerate() {
        let base = d * NODES_PER_DANCER;
        scene_nodes.push(base);
        nodes.push(json!({"name": name, "children": [base + 1]}));
        let quats = quaternions(m);
        for j in 0..JOINTS {
            let mut node = json!({"name": format!("{name}_{}", JOINT_NAMES[j])});
            let kids: Vec<usize> = children(j).map(|c| base + 1 + c).collect();
            if !kids.is_empty() {
                node["children"] = json!(kids);
            }
            let tr = if j == 0 {
                [m.roots[0], m.roots[1], m.roots[2]]
            } else {
                m.skeleton.offsets[j]
            };
            node["translation"] = json!(tr);
            node["rotation"] = json!(quats[j * frames]);
            nodes.push(node);
        }
        // Root translation (T, 3).
        let view = views.len();
        views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": 12 * frames}));
        push_f32s(&mut bin, m.roots.iter().copied());
        let acc = accessors.len();
        accessors.push(
            json!({"bufferView": view, "componentType": FLOAT, "count": frames, "type": "VEC3"}),
        );
        samplers.push(json!({"input": 0, "output": acc, "interpolation": "LINEAR"}));
        channels.push(json!({"sampler": samplers.len() - 1, "target": {"node": base + 1, "path": "translation"}}));
        // Rotations (55, T, 4) in one view, one accessor per joint.
        let view = views.len();
        views.push(
            json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": 16 * frames * JOINTS}),
        );
        push_f32s(&mut bin, quats.iter().flatten().copied());
        for j in 0..JOINTS {
            let acc = accessors.len();
            accessors.push(
                json!({"bufferView": view, "byteOffset": 16 * frames * j, "componentType": FLOAT,
                "count": frames, "type": "VEC4"}),
            );
            samplers.push(json!({"input": 0, "output": acc, "interpolation": "LINEAR"}));
            channels.push(json!({"sampler": samplers.len() - 1, "target": {"node": base + 1 + j, "path": "rotation"}}));
        }
        // The mannequin: mesh, skin (bind pose = rest pose) and material.
        let mesh = super::mannequin::mesh(&m.skeleton);
        let n = mesh.positions.len();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in &mesh.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let v = push_view(
            &mut views,
            &mut bin,
            &f32_bytes(mesh.positions.iter().flatten()),
            Some(ARRAY_BUFFER),
        );
        let pos_acc = accessors.len();
        accessors.push(json!({"bufferView": v, "componentType": FLOAT, "count": n, "type": "VEC3", "min": lo, "max": hi}));
        let v = push_view(
            &mut views,
            &mut bin,
            &f32_bytes(mesh.normals.iter().flatten()),
            Some(ARRAY_BUFFER),
        );
        accessors
            .push(json!({"bufferView": v, "componentType": FLOAT, "count": n, "type": "VEC3"}));
        let joints: Vec<u8> = mesh.joints.iter().flat_map(|&j| [j, 0, 0, 0]).collect();
        let v = push_view(&mut views, &mut bin, &joints, Some(ARRAY_BUFFER));
        accessors.push(
            json!({"bufferView": v, "componentType": UNSIGNED_BYTE, "count": n, "type": "VEC4"}),
        );
        let weights: Vec<u8> = (0..n).flat_map(|_| [255u8, 0, 0, 0]).collect();
        let v = push_view(&mut views, &mut bin, &weights, Some(ARRAY_BUFFER));
        accessors.push(json!({"bufferView": v, "componentType": UNSIGNED_BYTE, "normalized": true, "count": n, "type": "VEC4"}));
        let idx: Vec<u8> = mesh.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let v = push_view(&mut views, &mut bin, &idx, Some(ELEMENT_ARRAY_BUFFER));
        let idx_acc = accessors.len();
        accessors.push(json!({"bufferView": v, "componentType": UNSIGNED_SHORT, "count": mesh.indices.len(), "type": "SCALAR"}));
        let rest = m.skeleton.rest_positions();
        let ibm: Vec<f32> = rest
            .iter()
            .flat_map(|p| {
                [
                    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -p[0], -p[1],
                    -p[2], 1.0,
                ]
            })
            .collect();
        let v = push_view(&mut views, &mut bin, &f32_bytes(ibm.iter()), None);
        let ibm_acc = accessors.len();
        accessors.push(
            json!({"bufferView": v, "componentType": FLOAT, "count": JOINTS, "type": "MAT4"}),
        );
        materials.push(
            json!({"name": format!("{name}_material"), "pbrMetallicRoughness": {
            "baseColorFactor": colour(name), "metallicFactor": 0.0, "roughnessFactor": 0.7}}),
        );
        meshes.push(json!({"name": format!("{name}_mannequin"), "primitives": [{
            "attributes": {"POSITION": pos_acc, "NORMAL": pos_acc + 1, "JOINTS_0": pos_acc + 2, "WEIGHTS_0": pos_acc + 3},
            "indices": idx_acc, "material": materials.len() - 1, "mode": 4}]}));
        skins.push(json!({"name": format!("{name}_skin"), "inverseBindMatrices": ibm_acc, "skeleton": base + 1,
            "joints": (base + 1..base + 1 + JOINTS).collect::<Vec<_>>()}));
        nodes.push(json!({"name": format!("{name}_mesh"), "mesh": meshes.len() - 1, "skin": skins.len() - 1}));
        scene_nodes.push(base + NODES_PER_DANCER - 1);
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "duolando export::glb"},
        "scene": 0,
        "scenes": [{"name": "duet", "nodes": scene_nodes}],
        "nodes": nodes,
        "meshes": meshes,
        "skins": skins,
        "materials": materials,
        "animations": [{"name": "dance", "samplers": samplers, "channels": channels}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
        "extras": {"fps": fps, "units": "metres", "up": "+y", "skeleton": "SMPL-X 55 joints"},
    });
    let mut json_bytes = serde_json::to_vec(&doc)?;
    while json_bytes.len() % 4 != 0 {
        json_bytes.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let total32 = u32::try_from(total).context("glb export: file larger than 4 GiB")?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&GLB_MAGIC.to_le_bytes());
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    out.extend_from_slice(&bin);
    Ok(out)
}

/// Writes `dancers` to a .glb file.
pub fn write(path: &Path, dancers: &[(&str, &Motion)], fps: f32) -> Result<()> {
    let bytes =
        to_bytes(dancers, fps).with_context(|| format!("cannot export {}", path.display()))?;
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// The two chunks of a .glb file, checked: (JSON document, BIN payload).
pub fn parse(bytes: &[u8], what: &str) -> Result<(Value, Vec<u8>)> {
    let word = |o: usize| -> Result<u32> {
        let b = bytes
            .get(o..o + 4)
            .with_context(|| format!("{what}: truncated glb at byte {o}"))?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    if word(0)? != GLB_MAGIC || word(4)? != 2 {
        bail!("{what}: not a glTF 2.0 binary (bad magic or version)");
    }
    if word(8)? as usize != bytes.len() {
        bail!(
            "{what}: header length {} but the file has {} bytes",
            word(8)?,
            bytes.len()
        );
    }
    let json_len = word(12)? as usize;
    if word(16)? != CHUNK_JSON || json_len % 4 != 0 {
        bail!("{what}: first chunk must be JSON with a length multiple of 4");
    }
    let json_end = 20usize
        .checked_add(json_len)
        .filter(|&e| e <= bytes.len())
        .with_context(|| format!("{what}: JSON chunk overruns the file"))?;
    let doc: Value = serde_json::from_slice(&bytes[20..json_end])
        .with_context(|| format!("{what}: JSON chunk is not valid JSON"))?;
    let bin_len = word(json_end)? as usize;
    if word(json_end + 4)? != CHUNK_BIN || bin_len % 4 != 0 {
        bail!("{what}: second chunk must be BIN with a length multiple of 4");
    }
    let bin_end = (json_end + 8)
        .checked_add(bin_len)
        .filter(|&e| e == bytes.len())
        .with_context(|| format!("{what}: BIN chunk length does not match the file"))?;
    Ok((doc, bytes[json_end + 8..bin_end].to_vec()))
}

/// The float data of accessor `i` (FLOAT components, tightly packed):
/// (values, count, components). Every index and range is checked.
fn read_accessor(
    doc: &Value,
    bin: &[u8],
    i: usize,
    what: &str,
) -> Result<(Vec<f32>, usize, usize)> {
    let a = doc["accessors"]
        .get(i)
        .with_context(|| format!("{what}: no accessor {i}"))?;
    let comps = match a["type"].as_str() {
        Some("SCALAR") => 1,
        Some("VEC3") => 3,
        Some("VEC4") => 4,
        t => bail!("{what}: accessor {i} has type {t:?}; expected SCALAR, VEC3 or VEC4"),
    };
    if a["componentType"].as_u64() != Some(FLOAT as u64) {
        bail!("{what}: accessor {i} is not FLOAT");
    }
    let count = a["count"]
        .as_u64()
        .with_context(|| format!("{what}: accessor {i} has no count"))? as usize;
    let vi = a["bufferView"]
        .as_u64()
        .with_context(|| format!("{what}: accessor {i} has no bufferView"))? as usize;
    let v = doc["bufferViews"]
        .get(vi)
        .with_context(|| format!("{what}: no bufferView {vi}"))?;
    let start = (v["byteOffset"].as_u64().unwrap_or(0) as usize)
        .checked_add(a["byteOffset"].as_u64().unwrap_or(0) as usize);
    let len = count.checked_mul(4 * comps);
    let end = start.zip(len).and_then(|(s, l)| s.checked_add(l));
    let (Some(start), Some(end)) = (start, end) else {
        bail!("{what}: accessor {i} range overflows")
    };
    let view_end = (v["byteOffset"].as_u64().unwrap_or(0) as usize)
        .saturating_add(v["byteLength"].as_u64().unwrap_or(0) as usize);
    if end > view_end || end > bin.len() {
        bail!("{what}: accessor {i} reads past its bufferView or the BIN chunk");
    }
    let vals = bin[start..end]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok((vals, count, comps))
}

/// World joint positions (T, 165) of dancer `name` in a parsed .glb as this
/// module writes it, by FK over its animation: joint nodes `<name>_<joint>`
/// with their rest translations, the per-joint rotation channels and the
/// pelvis translation channel, sampled at the keyframes (no interpolation).
/// Fails, naming what is missing, on a file of another layout.
pub fn dancer_positions(doc: &Value, bin: &[u8], name: &str, what: &str) -> Result<Vec<f32>> {
    use crate::skeleton::math::{add, mat_mul, mat_vec};
    use crate::skeleton::{mat_from_quat, parent, POS_DIM};
    let nodes = doc["nodes"]
        .as_array()
        .with_context(|| format!("{what}: no nodes"))?;
    let mut index = [0usize; JOINTS];
    let mut rest = [[0.0f32; 3]; JOINTS];
    for j in 0..JOINTS {
        let node_name = format!("{name}_{}", JOINT_NAMES[j]);
        index[j] = nodes
            .iter()
            .position(|n| n["name"].as_str() == Some(&node_name))
            .with_context(|| format!("{what}: no node {node_name}"))?;
        let t = nodes[index[j]]["translation"]
            .as_array()
            .filter(|t| t.len() == 3)
            .with_context(|| format!("{what}: node {node_name} has no translation"))?;
        for k in 0..3 {
            rest[j][k] = t[k]
                .as_f64()
                .with_context(|| format!("{what}: node {node_name}: bad translation"))?
                as f32;
        }
    }
    let anim = doc["animations"]
        .get(0)
        .with_context(|| format!("{what}: no animation"))?;
    let channels = anim["channels"]
        .as_array()
        .with_context(|| format!("{what}: animation without channels"))?;
    let mut rot: Vec<Option<Vec<f32>>> = vec![None; JOINTS];
    let mut root: Option<Vec<f32>> = None;
    let mut frames: Option<usize> = None;
    for ch in channels {
        let Some(node) = ch["target"]["node"].as_u64() else {
            continue;
        };
        let Some(j) = index.iter().position(|&n| n as u64 == node) else {
            continue;
        };
        let s = ch["sampler"]
            .as_u64()
            .and_then(|s| anim["samplers"].get(s as usize))
            .with_context(|| format!("{what}: channel without a sampler"))?;
        let out = s["output"]
            .as_u64()
            .with_context(|| format!("{what}: sampler without output"))? as usize;
        let (data, count, comps) = read_accessor(doc, bin, out, what)?;
        if *frames.get_or_insert(count) != count {
            bail!("{what}: {name}: channels with different keyframe counts");
        }
        match (ch["target"]["path"].as_str(), comps) {
            (Some("rotation"), 4) => rot[j] = Some(data),
            (Some("translation"), 3) if j == 0 => root = Some(data),
            (p, c) => bail!(
                "{what}: unexpected channel {p:?} with {c} components on {name}_{}",
                JOINT_NAMES[j]
            ),
        }
    }
    let frames = frames.with_context(|| format!("{what}: {name} is not animated"))?;
    let root = root.with_context(|| format!("{what}: {name}_pelvis has no translation channel"))?;
    let mut out = Vec::with_capacity(frames * POS_DIM);
    for t in 0..frames {
        let mut world = [[[0.0f32; 3]; 3]; JOINTS];
        let mut pos = [[0.0f32; 3]; JOINTS];
        for j in 0..JOINTS {
            let r = match &rot[j] {
                Some(q) => mat_from_quat([q[4 * t], q[4 * t + 1], q[4 * t + 2], q[4 * t + 3]]),
                None => crate::skeleton::math::IDENTITY,
            };
            match parent(j) {
                None => {
                    pos[j] = [root[3 * t], root[3 * t + 1], root[3 * t + 2]];
                    world[j] = r;
                }
                Some(p) => {
                    pos[j] = add(pos[p], mat_vec(&world[p], rest[j]));
                    world[j] = mat_mul(&world[p], &r);
                }
            }
        }
        out.extend(pos.iter().flatten());
    }
    Ok(out)
}
