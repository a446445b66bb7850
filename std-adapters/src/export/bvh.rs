//! BVH export (one file per dancer) and a small BVH reader.
//!
//! The hierarchy is the SMPL-X joint tree (depth first, children in index
//! order), OFFSETs are the rig's rest offsets in the chosen [`Units`]
//! (centimetres by default), the root has
//! `Xposition Yposition Zposition Zrotation Xrotation Yrotation` and every
//! other joint `Zrotation Xrotation Yrotation`, meaning the local rotation
//! `R = Rz(z) Rx(x) Ry(y)` in degrees. Joints without children end with an
//! `End Site` half as long as their own bone. Y up, facing +z.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};

use super::Motion;
use crate::skeleton::math::{
    add, mat_mul, mat_vec, rot_x, rot_y, rot_z, scale, unflatten, Mat3, Vec3, IDENTITY,
};
use crate::skeleton::rotation::euler_zxy_from_mat;
use crate::skeleton::{children, JOINTS, JOINT_NAMES, ROT_DIM};

/// Length unit of the BVH file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Units {
    Metres,
    Centimetres,
}

impl Units {
    /// Multiplier from metres.
    pub fn per_metre(self) -> f32 {
        match self {
            Units::Metres => 1.0,
            Units::Centimetres => 100.0,
        }
    }
}

/// Joints in BVH (depth-first) order.
pub fn depth_first_order() -> Vec<usize> {
    fn visit(j: usize, out: &mut Vec<usize>) {
        out.push(j);
        for c in children(j) {
            visit(c, out);
        }
    }
    let mut out = Vec::with_capacity(JOINTS);
    visit(0, &mut out);
    out
}

fn hierarchy(m: &Motion, k: f32, j: usize, depth: usize, s: &mut String) {
    let pad = "  ".repeat(depth);
    let o = if j == 0 {
        [0.0; 3]
    } else {
        scale(m.skeleton.offsets[j], k)
    };
    let _ = writeln!(
        s,
        "{pad}{} {}",
        if j == 0 { "ROOT" } else { "JOINT" },
        JOINT_NAMES[j]
    );
    let _ = writeln!(s, "{pad}{{");
    let _ = writeln!(s, "{pad}  OFFSET {:.6} {:.6} {:.6}", o[0], o[1], o[2]);
    if j == 0 {
        let _ = writeln!(
            s,
            "{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        );
    } else {
        let _ = writeln!(s, "{pad}  CHANNELS 3 Zrotation Xrotation Yrotation");
    }
    let mut any = false;
    for c in children(j) {
        any = true;
        hierarchy(m, k, c, depth + 1, s);
    }
    if !any {
        let e = scale(o, 0.5);
        let _ = writeln!(
            s,
            "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {:.6} {:.6} {:.6}\n{pad}  }}",
            e[0], e[1], e[2]
        );
    }
    let _ = writeln!(s, "{pad}}}");
}

/// The BVH text of a motion.
pub fn to_string(m: &Motion, fps: f32, units: Units) -> String {
    let k = units.per_metre();
    let mut s = String::from("HIERARCHY\n");
    hierarchy(m, k, 0, 0, &mut s);
    let _ = write!(
        s,
        "MOTION\nFrames: {}\nFrame Time: {:.7}\n",
        m.frames,
        1.0 / fps
    );
    let order = depth_first_order();
    let mut prev = vec![[0.0f32; 3]; JOINTS];
    for t in 0..m.frames {
        let r = &m.roots[3 * t..3 * t + 3];
        let _ = write!(s, "{:.6} {:.6} {:.6}", r[0] * k, r[1] * k, r[2] * k);
        for &j in &order {
            let rot = unflatten(&m.rotmats[t * ROT_DIM + 9 * j..t * ROT_DIM + 9 * j + 9]);
            let mut e = euler_zxy_from_mat(&rot).map(f32::to_degrees);
            // Keep each angle within 180 degrees of the previous frame's.
            for (a, p) in e.iter_mut().zip(prev[j].iter()) {
                if t > 0 {
                    *a += 360.0 * ((p - *a) / 360.0).round();
                }
            }
            prev[j] = e;
            let _ = write!(s, " {:.5} {:.5} {:.5}", e[0], e[1], e[2]);
        }
        s.push('\n');
    }
    s
}

/// Writes a motion as BVH.
pub fn write(path: &Path, m: &Motion, fps: f32, units: Units) -> Result<()> {
    std::fs::write(path, to_string(m, fps, units))
        .with_context(|| format!("cannot write {}", path.display()))
}

/// One channel of a BVH joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

/// A joint read from a BVH file.
#[derive(Clone, Debug)]
pub struct BvhJoint {
    pub name: String,
    pub parent: Option<usize>,
    pub offset: Vec3,
    /// The OFFSET as written, parsed to f64 (`offset` is it parsed to f32).
    pub offset_f64: [f64; 3],
    pub channels: Vec<Channel>,
}

/// A parsed BVH clip (End Sites are dropped).
#[derive(Clone, Debug)]
pub struct BvhClip {
    pub joints: Vec<BvhJoint>,
    pub frame_time: f32,
    pub frames: usize,
    pub values: Vec<f32>, // (frames, channels total), file order
}

/// Parses BVH text. `what` names the source in errors.
pub fn parse(text: &str, what: &str) -> Result<BvhClip> {
    let mut tok = text.split_whitespace().peekable();
    let mut next = |expect: &str| -> Result<String> {
        tok.next()
            .map(str::to_string)
            .with_context(|| format!("{what}: unexpected end of file, expected {expect}"))
    };
    if next("HIERARCHY")? != "HIERARCHY" {
        bail!("{what}: expected HIERARCHY at the start");
    }
    let mut joints: Vec<BvhJoint> = Vec::new();
    let mut stack: Vec<Option<usize>> = Vec::new(); // open braces: Some(joint) or None (End Site)
    let mut pending: Option<(String, bool)> = None;
    loop {
        let t = next("a hierarchy keyword")?;
        match t.as_str() {
            "ROOT" | "JOINT" => pending = Some((next("a joint name")?, false)),
            "End" => {
                next("Site")?;
                pending = Some((String::new(), true));
            }
            "{" => {
                let (name, end) = pending
                    .take()
                    .with_context(|| format!("{what}: '{{' without a joint"))?;
                if end {
                    stack.push(None);
                } else {
                    let parent = stack.iter().rev().find_map(|s| *s);
                    if parent.is_none() && !joints.is_empty() {
                        bail!("{what}: more than one ROOT");
                    }
                    joints.push(BvhJoint {
                        name,
                        parent,
                        offset: [0.0; 3],
                        offset_f64: [0.0; 3],
                        channels: Vec::new(),
                    });
                    stack.push(Some(joints.len() - 1));
                }
            }
            "}" => {
                stack
                    .pop()
                    .with_context(|| format!("{what}: unbalanced '}}'"))?;
            }
            "OFFSET" => {
                let mut o = [0.0f32; 3];
                let mut o64 = [0.0f64; 3];
                for (v, v64) in o.iter_mut().zip(o64.iter_mut()) {
                    let text = next("an OFFSET value")?;
                    *v = text
                        .parse()
                        .with_context(|| format!("{what}: bad OFFSET value"))?;
                    *v64 = text
                        .parse()
                        .with_context(|| format!("{what}: bad OFFSET value"))?;
                }
                if let Some(Some(j)) = stack.last() {
                    joints[*j].offset = o;
                    joints[*j].offset_f64 = o64;
                }
            }
            "CHANNELS" => {
                let n: usize = next("a channel count")?
                    .parse()
                    .with_context(|| format!("{what}: bad CHANNELS count"))?;
                if n > 6 {
                    bail!("{what}: at most 6 channels per joint, got {n}");
                }
                let j = stack
                    .last()
                    .copied()
                    .flatten()
                    .with_context(|| format!("{what}: CHANNELS outside a joint"))?;
                for _ in 0..n {
                    let c = match next("a channel name")?.as_str() {
                        "Xposition" => Channel::Xposition,
                        "Yposition" => Channel::Yposition,
                        "Zposition" => Channel::Zposition,
                        "Xrotation" => Channel::Xrotation,
                        "Yrotation" => Channel::Yrotation,
                        "Zrotation" => Channel::Zrotation,
                        other => bail!("{what}: unknown channel {other}"),
                    };
                    joints[j].channels.push(c);
                }
            }
            "MOTION" => break,
            other => bail!("{what}: unexpected token {other} in HIERARCHY"),
        }
    }
    if !stack.is_empty() || joints.is_empty() {
        bail!("{what}: unbalanced or empty HIERARCHY");
    }
    if next("Frames:")? != "Frames:" {
        bail!("{what}: expected 'Frames:' after MOTION");
    }
    let frames: usize = next("a frame count")?
        .parse()
        .with_context(|| format!("{what}: bad frame count"))?;
    if next("Frame")? != "Frame" || next("Time:")? != "Time:" {
        bail!("{what}: expected 'Frame Time:'");
    }
    let frame_time: f32 = next("a frame time")?
        .parse()
        .with_context(|| format!("{what}: bad frame time"))?;
    let width: usize = joints.iter().map(|j| j.channels.len()).sum();
    let want = frames
        .checked_mul(width)
        .with_context(|| format!("{what}: frame count too large"))?;
    let mut values = Vec::with_capacity(want.min(1 << 26));
    for tkn in tok {
        values.push(
            tkn.parse::<f32>()
                .with_context(|| format!("{what}: bad motion value {tkn}"))?,
        );
    }
    if values.len() != want {
        bail!(
            "{what}: expected {frames} frames x {width} channels = {want} values, found {}",
            values.len()
        );
    }
    Ok(BvhClip {
        joints,
        frame_time,
        frames,
        values,
    })
}

impl BvhClip {
    /// World joint positions of frame `t` (file units), by FK with each
    /// joint's channels applied in file order.
    pub fn positions(&self, t: usize) -> Vec<Vec3> {
        let width: usize = self.joints.iter().map(|j| j.channels.len()).sum();
        let row = &self.values[t * width..(t + 1) * width];
        let mut world: Vec<Mat3> = Vec::with_capacity(self.joints.len());
        let mut pos: Vec<Vec3> = Vec::with_capacity(self.joints.len());
        let mut k = 0;
        for j in &self.joints {
            let mut trans = j.offset;
            let mut rot = IDENTITY;
            for c in &j.channels {
                let v = row[k];
                k += 1;
                match c {
                    Channel::Xposition => trans[0] = v,
                    Channel::Yposition => trans[1] = v,
                    Channel::Zposition => trans[2] = v,
                    Channel::Xrotation => rot = mat_mul(&rot, &rot_x(v.to_radians())),
                    Channel::Yrotation => rot = mat_mul(&rot, &rot_y(v.to_radians())),
                    Channel::Zrotation => rot = mat_mul(&rot, &rot_z(v.to_radians())),
                }
            }
            match j.parent {
                None => {
                    pos.push(trans);
                    world.push(rot);
                }
                Some(p) => {
                    pos.push(add(pos[p], mat_vec(&world[p], trans)));
                    world.push(mat_mul(&world[p], &rot));
                }
            }
        }
        pos
    }
}
