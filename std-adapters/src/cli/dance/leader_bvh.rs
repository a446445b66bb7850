//! A leader from a BVH file: any frame rate (resampled to the model's 30
//! fps) and the skeletons of docs/LEADER_INPUT.md (SMPL-X joint names as
//! `duolando` writes them, and Mixamo's), mapped onto the 55 SMPL-X joint
//! positions the model reads.

use std::path::Path;

use anyhow::{bail, Context, Result};
use duolando_core::duolando::config::POSE_DIM;

use super::inputs::{check_finite, Leader, FPS, FRAME_TIME_TOLERANCE};
use crate::export::bvh::{self, BvhClip};
use crate::skeleton::{JOINTS, JOINT_NAMES};

/// Frame times accepted (seconds): 1000 fps down to 1 fps.
const FRAME_TIME_RANGE: (f64, f64) = (0.001, 1.0);
/// The most frames a resampled clip may have (one hour at 30 fps).
const MAX_FRAMES: usize = 30 * 3600;

/// Where one SMPL-X joint comes from in a rig.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    /// The rig's joint of this name.
    Joint(&'static str),
    /// A joint the rig lacks, placed at another SMPL-X joint (by index):
    /// Mixamo has no jaw or eyes (placed at the head) and rigs exported
    /// without fingers have none (placed at the wrist, so the model sees
    /// a closed hand).
    At(usize),
}

/// A skeleton we can read: its name and, per SMPL-X joint, the rig joint.
struct Rig {
    name: &'static str,
    /// Names the rig must have (the body); the rest may fall back.
    required: &'static [&'static str],
    map: fn(usize) -> (&'static str, Option<usize>),
}

/// Mixamo's names for the SMPL-X joints (after any `mixamorig:`-style
/// prefix), and where a missing one is placed. Left and right are the
/// character's own in both conventions.
fn mixamo(j: usize) -> (&'static str, Option<usize>) {
    const HEAD: usize = 15;
    const L_WRIST: usize = 20;
    const R_WRIST: usize = 21;
    const LEFT: [&str; 15] = [
        "LeftHandIndex1", "LeftHandIndex2", "LeftHandIndex3", "LeftHandMiddle1", "LeftHandMiddle2",
        "LeftHandMiddle3", "LeftHandPinky1", "LeftHandPinky2", "LeftHandPinky3", "LeftHandRing1", "LeftHandRing2",
        "LeftHandRing3", "LeftHandThumb1", "LeftHandThumb2", "LeftHandThumb3",
    ];
    const RIGHT: [&str; 15] = [
        "RightHandIndex1", "RightHandIndex2", "RightHandIndex3", "RightHandMiddle1", "RightHandMiddle2",
        "RightHandMiddle3", "RightHandPinky1", "RightHandPinky2", "RightHandPinky3", "RightHandRing1",
        "RightHandRing2", "RightHandRing3", "RightHandThumb1", "RightHandThumb2", "RightHandThumb3",
    ];
    match j {
        0..=21 => (MIXAMO_BODY[j], None),
        22..=24 => ("", Some(HEAD)), // jaw, eyes: Mixamo has none
        25..=39 => (LEFT[j - 25], Some(L_WRIST)),
        _ => (RIGHT[j - 40], Some(R_WRIST)),
    }
}

/// Mixamo's names of SMPL-X joints 0..=21 (the body), in SMPL-X order: all
/// required of a Mixamo rig.
pub const MIXAMO_BODY: [&str; 22] = [
    "Hips", "LeftUpLeg", "RightUpLeg", "Spine", "LeftLeg", "RightLeg", "Spine1", "LeftFoot", "RightFoot", "Spine2",
    "LeftToeBase", "RightToeBase", "Neck", "LeftShoulder", "RightShoulder", "Head", "LeftArm", "RightArm",
    "LeftForeArm", "RightForeArm", "LeftHand", "RightHand",
];

fn smplx(j: usize) -> (&'static str, Option<usize>) {
    (JOINT_NAMES[j], None)
}

const RIGS: [Rig; 2] = [
    Rig { name: "SMPL-X", required: &JOINT_NAMES, map: smplx },
    Rig { name: "Mixamo", required: &MIXAMO_BODY, map: mixamo },
];

/// A joint name without a namespace prefix (`mixamorig:Hips` -> `Hips`,
/// `mixamorig1:Hips` -> `Hips`), compared without case.
pub fn bare(name: &str) -> &str {
    name.rsplit(':').next().unwrap_or(name)
}

/// The rig `clip` matches (every required name present), with the source of
/// each SMPL-X joint, or why none matches.
fn match_rig(clip: &BvhClip, what: &str) -> Result<(&'static str, Vec<(Source, Option<usize>)>)> {
    let find = |name: &str| clip.joints.iter().position(|j| bare(&j.name).eq_ignore_ascii_case(name));
    let mut reasons = Vec::new();
    for rig in &RIGS {
        let missing: Vec<&str> = rig.required.iter().copied().filter(|n| find(n).is_none()).collect();
        if !missing.is_empty() {
            reasons.push(format!(
                "as {}: {} of its {} joints missing (first: {})",
                rig.name,
                missing.len(),
                rig.required.len(),
                missing.iter().take(4).copied().collect::<Vec<_>>().join(", ")
            ));
            continue;
        }
        let sources = (0..JOINTS)
            .map(|j| {
                let (name, fallback) = (rig.map)(j);
                match (find(name).filter(|_| !name.is_empty()), fallback) {
                    (Some(i), _) => (Source::Joint(name), Some(i)),
                    (None, Some(at)) => (Source::At(at), None),
                    (None, None) => unreachable!("a required joint was checked above"),
                }
            })
            .collect();
        return Ok((rig.name, sources));
    }
    bail!(
        "{what}: the skeleton is neither SMPL-X nor Mixamo ({}); see docs/LEADER_INPUT.md for the joint names read",
        reasons.join("; ")
    )
}

/// The clip's 55 SMPL-X joint positions per frame, (frames, 165), in the
/// file's units.
fn smplx_positions(clip: &BvhClip, sources: &[(Source, Option<usize>)]) -> Vec<f32> {
    let mut pos3d = vec![0.0f32; clip.frames * POSE_DIM];
    for (t, row) in pos3d.chunks_exact_mut(POSE_DIM).enumerate() {
        let world = clip.positions(t);
        for (j, (_, index)) in sources.iter().enumerate() {
            if let Some(i) = index {
                row[j * 3..j * 3 + 3].copy_from_slice(&world[*i]);
            }
        }
        // Fallbacks refer to joints with a lower index that came from the rig.
        for (j, (src, _)) in sources.iter().enumerate() {
            if let Source::At(at) = *src {
                let p = [row[at * 3], row[at * 3 + 1], row[at * 3 + 2]];
                row[j * 3..j * 3 + 3].copy_from_slice(&p);
            }
        }
    }
    pos3d
}

/// `rows` (frames, width) sampled every `frame_time` seconds, linearly
/// resampled to 30 fps over the same span: frame k at k/30 s.
pub fn resample_to_30fps(rows: &[f32], width: usize, frame_time: f64) -> Vec<f32> {
    let frames = rows.len() / width;
    if frames == 0 {
        return Vec::new();
    }
    let span = (frames - 1) as f64 * frame_time;
    let out_frames = (span * FPS + 1e-6).floor() as usize + 1;
    let mut out = vec![0.0f32; out_frames * width];
    for (k, o) in out.chunks_exact_mut(width).enumerate() {
        let t = k as f64 / FPS / frame_time; // in source frames
        let i = (t.floor() as usize).min(frames - 1);
        let w = (t - i as f64) as f32;
        let a = &rows[i * width..(i + 1) * width];
        let b = &rows[(i + 1).min(frames - 1) * width..((i + 1).min(frames - 1) + 1) * width];
        for ((o, &a), &b) in o.iter_mut().zip(a).zip(b) {
            *o = a + (b - a) * w;
        }
    }
    out
}

/// Reads a BVH leader: SMPL-X or Mixamo joint names, any frame rate from 1
/// to 1000 fps (resampled to 30), centimetres or metres (taken as
/// centimetres when the first frame is taller than 5 units).
pub fn load(path: &Path) -> Result<Leader> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let what = path.display().to_string();
    let clip = bvh::parse(&text, &what)?;
    let ft = clip.frame_time as f64;
    if !(ft.is_finite() && ft >= FRAME_TIME_RANGE.0 && ft <= FRAME_TIME_RANGE.1) {
        bail!(
            "{what}: Frame Time {} s; expected {} to {} s (1000 to 1 fps); the clip is resampled to 30 fps",
            clip.frame_time,
            FRAME_TIME_RANGE.0,
            FRAME_TIME_RANGE.1
        );
    }
    if clip.frames == 0 {
        bail!("{what}: the BVH has 0 frames");
    }
    let resampled_frames = ((clip.frames - 1) as f64 * ft * FPS).floor() as usize + 1;
    if resampled_frames > MAX_FRAMES {
        bail!("{what}: {resampled_frames} frames at 30 fps; at most {MAX_FRAMES} (one hour) are read");
    }
    let (rig, sources) = match_rig(&clip, &what)?;
    let mut pos3d = smplx_positions(&clip, &sources);
    let native = (ft * FPS - 1.0).abs() <= FRAME_TIME_TOLERANCE;
    if !native {
        pos3d = resample_to_30fps(&pos3d, POSE_DIM, ft);
    }
    let frames = pos3d.len() / POSE_DIM;
    let ys = pos3d.chunks_exact(3).take(JOINTS).map(|p| p[1]);
    let height = ys.clone().fold(f32::MIN, f32::max) - ys.fold(f32::MAX, f32::min);
    let cm = height > 5.0;
    if cm {
        pos3d.iter_mut().for_each(|v| *v /= 100.0);
    }
    check_finite(path, &pos3d, POSE_DIM, "leader positions")?;
    let placed = sources.iter().filter(|(s, _)| matches!(s, Source::At(_))).count();
    let mut source = format!("bvh, {rig}, {}", if cm { "centimetres" } else { "metres" });
    if !native {
        source += &format!(", {:.2} fps resampled to 30 ({} -> {frames} frames)", 1.0 / ft, clip.frames);
    }
    if placed > 0 {
        source += &format!(", {placed} joints placed (docs/LEADER_INPUT.md)");
    }
    Ok(Leader { pos3d, frames, source })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Mixamo-named rig without fingers: every joint with zero rotation,
    /// so world positions are the summed offsets plus the root position.
    fn mixamo_bvh(frame_time: f32, roots: &[[f32; 3]], prefix: &str) -> String {
        // (name, parent name, offset) in cm; parents come first.
        let joints: [(&str, &str, [f32; 3]); 22] = [
            ("Hips", "", [0.0, 0.0, 0.0]),
            ("Spine", "Hips", [0.0, 10.0, 0.0]),
            ("Spine1", "Spine", [0.0, 12.0, 0.0]),
            ("Spine2", "Spine1", [0.0, 12.0, 0.0]),
            ("Neck", "Spine2", [0.0, 15.0, 0.0]),
            ("Head", "Neck", [0.0, 10.0, 0.0]),
            ("LeftShoulder", "Spine2", [6.0, 12.0, 0.0]),
            ("LeftArm", "LeftShoulder", [12.0, 0.0, 0.0]),
            ("LeftForeArm", "LeftArm", [28.0, 0.0, 0.0]),
            ("LeftHand", "LeftForeArm", [25.0, 0.0, 0.0]),
            ("RightShoulder", "Spine2", [-6.0, 12.0, 0.0]),
            ("RightArm", "RightShoulder", [-12.0, 0.0, 0.0]),
            ("RightForeArm", "RightArm", [-28.0, 0.0, 0.0]),
            ("RightHand", "RightForeArm", [-25.0, 0.0, 0.0]),
            ("LeftUpLeg", "Hips", [9.0, -5.0, 0.0]),
            ("LeftLeg", "LeftUpLeg", [0.0, -42.0, 0.0]),
            ("LeftFoot", "LeftLeg", [0.0, -40.0, 0.0]),
            ("LeftToeBase", "LeftFoot", [0.0, -6.0, 12.0]),
            ("RightUpLeg", "Hips", [-9.0, -5.0, 0.0]),
            ("RightLeg", "RightUpLeg", [0.0, -42.0, 0.0]),
            ("RightFoot", "RightLeg", [0.0, -40.0, 0.0]),
            ("RightToeBase", "RightFoot", [0.0, -6.0, 12.0]),
        ];
        fn emit(out: &mut String, joints: &[(&str, &str, [f32; 3])], i: usize, depth: usize, prefix: &str) {
            let (name, _, o) = joints[i];
            let pad = "  ".repeat(depth);
            let kw = if depth == 0 { "ROOT" } else { "JOINT" };
            let ch = if depth == 0 { "6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" } else { "3 Zrotation Xrotation Yrotation" };
            out.push_str(&format!("{pad}{kw} {prefix}{name}\n{pad}{{\n{pad}  OFFSET {} {} {}\n{pad}  CHANNELS {ch}\n", o[0], o[1], o[2]));
            let kids: Vec<usize> = (0..joints.len()).filter(|&k| joints[k].1 == name).collect();
            if kids.is_empty() {
                out.push_str(&format!("{pad}  End Site\n{pad}  {{\n{pad}    OFFSET 0 5 0\n{pad}  }}\n"));
            }
            for k in kids {
                emit(out, joints, k, depth + 1, prefix);
            }
            out.push_str(&format!("{pad}}}\n"));
        }
        let mut s = String::from("HIERARCHY\n");
        emit(&mut s, &joints, 0, 0, prefix);
        s.push_str(&format!("MOTION\nFrames: {}\nFrame Time: {frame_time}\n", roots.len()));
        for r in roots {
            s.push_str(&format!("{} {} {} 0 0 0{}\n", r[0], r[1], r[2], " 0 0 0".repeat(joints.len() - 1)));
        }
        s
    }

    fn load_text(text: &str, name: &str) -> Result<Leader> {
        let dir = std::env::temp_dir().join(format!("duolando-leader-bvh-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(format!("{name}.bvh"));
        std::fs::write(&p, text).unwrap();
        let r = load(&p);
        std::fs::remove_dir_all(&dir).ok();
        r
    }

    fn joint(l: &Leader, t: usize, j: usize) -> [f32; 3] {
        let r = &l.pos3d[t * POSE_DIM + j * 3..t * POSE_DIM + j * 3 + 3];
        [r[0], r[1], r[2]]
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
    }

    #[test]
    fn mixamo_at_60_fps_maps_and_resamples() {
        // 7 frames at 60 fps (0.1 s): the root moves 6 cm per frame in x.
        let roots: Vec<[f32; 3]> = (0..7).map(|i| [6.0 * i as f32, 100.0, 0.0]).collect();
        let l = load_text(&mixamo_bvh(1.0 / 60.0, &roots, "mixamorig:"), "m60").unwrap();
        assert_eq!(l.frames, 4, "0.1 s at 30 fps: frames at 0, 1/30, 2/30, 3/30 s");
        assert!(l.source.contains("Mixamo") && l.source.contains("resampled"), "{}", l.source);
        for t in 0..4 {
            // Frame t at 30 fps = source frame 2t: the root at 12 t cm.
            let pelvis = joint(&l, t, 0);
            assert!(close(pelvis, [0.12 * t as f32, 1.0, 0.0]), "frame {t}: pelvis {pelvis:?}");
            // Left elbow (SMPL-X 18) = Mixamo LeftForeArm: hips + spine chain + shoulder + arm.
            let elbow = joint(&l, t, 18);
            assert!(close(elbow, [0.12 * t as f32 + 0.46, 1.0 + 0.46, 0.0]), "frame {t}: elbow {elbow:?}");
            // Right foot (SMPL-X 11) = RightToeBase.
            assert!(close(joint(&l, t, 11), [0.12 * t as f32 - 0.09, 1.0 - 0.93, 0.12]));
            // Missing fingers at the wrists, jaw and eyes at the head.
            for f in 25..40 {
                assert_eq!(joint(&l, t, f), joint(&l, t, 20), "left finger {f}");
            }
            for f in 40..55 {
                assert_eq!(joint(&l, t, f), joint(&l, t, 21), "right finger {f}");
            }
            for f in 22..25 {
                assert_eq!(joint(&l, t, f), joint(&l, t, 15));
            }
        }
    }

    #[test]
    fn a_clip_between_source_frames_is_interpolated() {
        // 24 fps: frame 1 at 30 fps (1/30 s) is source frame 0.8.
        let roots: Vec<[f32; 3]> = (0..3).map(|i| [0.0, 100.0, 10.0 * i as f32]).collect();
        let l = load_text(&mixamo_bvh(1.0 / 24.0, &roots, ""), "m24").unwrap();
        assert_eq!(l.frames, 3, "2/24 s = 0.0833 s: frames at 0, 1/30, 2/30");
        assert!(close(joint(&l, 1, 0), [0.0, 1.0, 0.08]), "{:?}", joint(&l, 1, 0));
        assert!(close(joint(&l, 2, 0), [0.0, 1.0, 0.16]), "{:?}", joint(&l, 2, 0));
    }

    #[test]
    fn resampling_30_fps_is_the_identity_and_keeps_the_span() {
        let rows: Vec<f32> = (0..20).map(|v| v as f32 * 0.5).collect();
        assert_eq!(resample_to_30fps(&rows, 2, 1.0 / 30.0), rows);
        let up = resample_to_30fps(&rows, 2, 1.0 / 15.0); // 10 frames over 0.6 s -> 19
        assert_eq!(up.len() / 2, 19);
        assert_eq!(&up[2..4], &[0.5, 1.0], "halfway between frames 0 and 1");
    }

    #[test]
    fn unknown_skeletons_and_rates_are_named() {
        let roots = [[0.0, 100.0, 0.0]; 2];
        let text = mixamo_bvh(1.0 / 30.0, &roots, "").replace("LeftForeArm", "LeftLowerArm");
        let e = format!("{:#}", load_text(&text, "unk").unwrap_err());
        assert!(e.contains("neither SMPL-X nor Mixamo") && e.contains("LeftForeArm"), "{e}");
        let e = format!("{:#}", load_text(&mixamo_bvh(0.0001, &roots, ""), "fast").unwrap_err());
        assert!(e.contains("Frame Time"), "{e}");
        let slow = load_text(&mixamo_bvh(1.0, &roots, ""), "slow").unwrap();
        assert_eq!(slow.frames, 31, "2 frames 1 s apart: 31 frames at 30 fps");
    }
}
