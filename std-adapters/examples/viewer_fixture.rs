//! Writes a viewer page from small synthetic motion: two SMPL-X stick figures
//! (the leader walks a wide circle, the follower walks a small circle the other
//! way and spins every four beats), 120 bpm beats, made-up follower tokens and a
//! click track on the beats (music.wav). Used by tests/browser/run.sh.
//!
//!     cargo run -p duolando --example viewer_fixture -- OUT_DIR [--frames N] [--no-audio]

use std::f32::consts::{PI, TAU};
use std::path::PathBuf;

use duolando::viewer::{write_index_html, ViewerData, JOINTS, ROW, SMPLX_PARENTS, TOKEN_STREAMS};

const FPS: f32 = 30.0;
/// Frames between beats (120 bpm at 30 fps).
const BEAT_PERIOD: usize = 15;
const SAMPLE_RATE: u32 = 22_050;

/// Approximate SMPL-X rest joints (metres, y-up, facing +z, left = +x, feet on y = 0).
fn rest_pose() -> [[f32; 3]; JOINTS] {
    let mut p = [[0.0f32; 3]; JOINTS];
    let body: [[f32; 3]; 25] = [
        [0.0, 0.95, 0.0],     // 0 pelvis
        [0.06, 0.86, 0.0],    // 1 left hip
        [-0.06, 0.86, 0.0],   // 2 right hip
        [0.0, 1.06, -0.01],   // 3 spine1
        [0.10, 0.49, 0.01],   // 4 left knee
        [-0.10, 0.49, 0.01],  // 5 right knee
        [0.0, 1.19, 0.0],     // 6 spine2
        [0.09, 0.08, -0.03],  // 7 left ankle
        [-0.09, 0.08, -0.03], // 8 right ankle
        [0.0, 1.25, 0.02],    // 9 spine3
        [0.11, 0.02, 0.10],   // 10 left foot
        [-0.11, 0.02, 0.10],  // 11 right foot
        [0.0, 1.47, -0.01],   // 12 neck
        [0.08, 1.39, 0.0],    // 13 left collar
        [-0.08, 1.39, 0.0],   // 14 right collar
        [0.0, 1.60, 0.03],    // 15 head
        [0.18, 1.41, -0.01],  // 16 left shoulder
        [-0.18, 1.41, -0.01], // 17 right shoulder
        [0.23, 1.15, -0.03],  // 18 left elbow
        [-0.23, 1.15, -0.03], // 19 right elbow
        [0.25, 0.91, 0.01],   // 20 left wrist
        [-0.25, 0.91, 0.01],  // 21 right wrist
        [0.0, 1.56, 0.07],    // 22 jaw
        [0.03, 1.65, 0.08],   // 23 left eye
        [-0.03, 1.65, 0.08],  // 24 right eye
    ];
    p[..25].copy_from_slice(&body);
    // Fingers hang down from the wrist: index, middle, pinky, ring, thumb; 3 joints each.
    let bases: [[f32; 3]; 5] = [
        [0.01, -0.09, 0.03],
        [0.0, -0.095, 0.01],
        [0.0, -0.08, -0.03],
        [0.0, -0.09, -0.01],
        [0.01, -0.03, 0.045],
    ];
    for (side, wrist, first) in [(1.0f32, 20usize, 25usize), (-1.0, 21, 40)] {
        for (f, b) in bases.iter().enumerate() {
            for k in 0..3 {
                let j = first + 3 * f + k;
                let step = if f == 4 {
                    [0.0, -0.022, 0.018]
                } else {
                    [0.0, -0.03, 0.0]
                };
                p[j] = [
                    p[wrist][0] + side * b[0],
                    p[wrist][1] + b[1] + step[1] * k as f32,
                    p[wrist][2] + b[2] + step[2] * k as f32,
                ];
            }
        }
    }
    p
}

type M3 = [f32; 9];
const I3: M3 = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
fn rot_x(a: f32) -> M3 {
    let (s, c) = a.sin_cos();
    [1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c]
}
fn rot_y(a: f32) -> M3 {
    let (s, c) = a.sin_cos();
    [c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c]
}
fn mul(a: &M3, b: &M3) -> M3 {
    let mut o = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            o[3 * r + c] = (0..3).map(|k| a[3 * r + k] * b[3 * k + c]).sum();
        }
    }
    o
}
fn apply(m: &M3, v: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|r| m[3 * r] * v[0] + m[3 * r + 1] * v[1] + m[3 * r + 2] * v[2])
}

/// Forward kinematics of one walking frame into `out` (165 floats).
/// `root`: pelvis xz; `heading`: yaw (0 faces +z); `phase`: gait phase in radians.
fn pose(rest: &[[f32; 3]; JOINTS], root: [f32; 2], heading: f32, phase: f32, out: &mut [f32]) {
    let mut local = [I3; JOINTS];
    let s = phase.sin();
    local[0] = rot_y(heading);
    local[1] = rot_x(-0.45 * s); // hips swing (negative x-rotation = forward)
    local[2] = rot_x(0.45 * s);
    local[4] = rot_x(0.75 * (-phase.cos()).max(0.0)); // knees bend on the back swing
    local[5] = rot_x(0.75 * phase.cos().max(0.0));
    local[3] = rot_y(0.12 * s); // spine counter-twist
    local[16] = rot_x(0.4 * s); // arms swing against the legs
    local[17] = rot_x(-0.4 * s);
    local[18] = rot_x(-0.35);
    local[19] = rot_x(-0.35);
    for (j, l) in local.iter_mut().enumerate().skip(25) {
        if (j - 25) % 3 != 0 {
            *l = rot_x(-0.25 - 0.15 * s); // fingers curl a little
        }
    }
    let mut global = [I3; JOINTS];
    let mut pos = [[0.0f32; 3]; JOINTS];
    let bob = 0.03 * (2.0 * phase).cos();
    pos[0] = [root[0], rest[0][1] - 0.03 + bob, root[1]];
    global[0] = local[0];
    for j in 1..JOINTS {
        let p = SMPLX_PARENTS[j] as usize; // parents precede children
        let off = [0, 1, 2].map(|c| rest[j][c] - rest[p][c]);
        let d = apply(&global[p], off);
        pos[j] = [0, 1, 2].map(|c| pos[p][c] + d[c]);
        global[j] = mul(&global[p], &local[j]);
    }
    for (j, v) in pos.iter().enumerate() {
        out[3 * j..3 * j + 3].copy_from_slice(v);
    }
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// 16-bit mono PCM WAV with a short 880 Hz click on every beat.
fn click_track(frames: usize) -> Vec<u8> {
    let n = (frames as f32 / FPS * SAMPLE_RATE as f32) as usize;
    let beat_samples = (BEAT_PERIOD as f32 / FPS * SAMPLE_RATE as f32) as usize;
    let mut wav = Vec::with_capacity(44 + 2 * n);
    let data_len = (2 * n) as u32;
    wav.extend_from_slice(b"RIFF");
    wav.extend_from_slice(&(36 + data_len).to_le_bytes());
    wav.extend_from_slice(b"WAVEfmt ");
    wav.extend_from_slice(&16u32.to_le_bytes());
    wav.extend_from_slice(&1u16.to_le_bytes()); // PCM
    wav.extend_from_slice(&1u16.to_le_bytes()); // mono
    wav.extend_from_slice(&SAMPLE_RATE.to_le_bytes());
    wav.extend_from_slice(&(SAMPLE_RATE * 2).to_le_bytes());
    wav.extend_from_slice(&2u16.to_le_bytes());
    wav.extend_from_slice(&16u16.to_le_bytes());
    wav.extend_from_slice(b"data");
    wav.extend_from_slice(&data_len.to_le_bytes());
    for i in 0..n {
        let t = (i % beat_samples) as f32 / SAMPLE_RATE as f32;
        let v = (TAU * 880.0 * t).sin() * (-t * 60.0).exp() * 0.5;
        wav.extend_from_slice(&((v * 32767.0) as i16).to_le_bytes());
    }
    wav
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut dir = None;
    let mut frames = 300usize;
    let mut audio = true;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--frames" => {
                let v = args.next().ok_or("--frames needs a value")?;
                frames = v.parse().map_err(|_| format!("--frames: not a positive integer: {v:?}"))?;
                if frames < 8 {
                    return Err("--frames must be at least 8".into());
                }
            }
            "--no-audio" => audio = false,
            _ if dir.is_none() && !a.starts_with("--") => dir = Some(PathBuf::from(a)),
            _ => return Err(format!("unexpected argument {a:?}\nusage: viewer_fixture OUT_DIR [--frames N] [--no-audio]").into()),
        }
    }
    let dir = dir.ok_or("usage: viewer_fixture OUT_DIR [--frames N] [--no-audio]")?;

    let rest = rest_pose();
    let mut leader = vec![0.0f32; frames * ROW];
    let mut follower = vec![0.0f32; frames * ROW];
    let lap = 8.0; // seconds per lap of the leader
    for f in 0..frames {
        let t = f as f32 / FPS;
        // Leader: counter-clockwise (seen from above) on a 1.1 m circle, facing along the path.
        let th = TAU * t / lap;
        let r = 1.1;
        let heading = (-th.sin()).atan2(-th.cos()); // along d/dt of (r cos th, -r sin th)
        pose(
            &rest,
            [r * th.cos(), -r * th.sin()],
            heading,
            TAU * t,
            &mut leader[f * ROW..(f + 1) * ROW],
        );
        // Follower: the other way round a 0.5 m circle, with a full spin on every fourth beat.
        let thf = -TAU * t / lap * 1.3 + PI / 2.0;
        let rf = 0.5;
        let spin_period = 4.0 * BEAT_PERIOD as f32 / FPS;
        let spin =
            TAU * ((t / spin_period).floor() + smoothstep((t % spin_period) / (0.6 * spin_period)));
        let headf = thf + spin; // thf decreases: the path tangent is (sin thf, cos thf)
        pose(
            &rest,
            [rf * thf.cos(), -rf * thf.sin()],
            headf,
            TAU * t * 1.1 + 1.0,
            &mut follower[f * ROW..(f + 1) * ROW],
        );
    }
    let beats: Vec<f32> = (0..frames)
        .map(|f| if f % BEAT_PERIOD == 0 { 1.0 } else { 0.0 })
        .collect();
    let rows = frames / 4;
    let tokens: Vec<u32> = (0..rows * TOKEN_STREAMS)
        .map(|i| {
            let (k, s) = ((i / TOKEN_STREAMS) as u32, (i % TOKEN_STREAMS) as u32);
            (s * 97 + (k / 3) * 31 + k % 3) % 512
        })
        .collect();

    std::fs::create_dir_all(&dir)?;
    let audio_file = if audio {
        std::fs::write(dir.join("music.wav"), click_track(frames))?;
        Some("music.wav")
    } else {
        None
    };
    let page = write_index_html(
        &dir,
        &ViewerData {
            title: "duolando viewer fixture: synthetic leader and follower",
            fps: FPS,
            leader_pos3d: Some(&leader),
            follower_pos3d: &follower,
            beats: Some(&beats),
            tokens: Some(&tokens),
            audio_file,
            see_also: None,
        },
    )?;
    println!("{}", page.display());
    Ok(())
}
