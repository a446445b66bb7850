//! Generates one take: plan -> per-frame targets -> IK -> FK, for both
//! dancers, plus the music feature track.

use super::choreography::{ease, PlacedFigure, Plan, Response};
use super::feet::{plan_feet, FootPlace, FootTrack};
use super::genre::{Genre, Hold};
use super::hands::{blend, upper_body, Frame, UpperBody};
use super::music_features::synthetic_features;
use super::pose::{solve, Targets};
use super::rng::Rng;
use crate::skeleton::math::{add, flatten, scale, sub, Vec3};
use crate::skeleton::{Skeleton, POS_DIM, ROT_DIM};

/// Frames per second of every synthesized array.
pub const FPS: f32 = 30.0;

/// One dancer's motion in the dataset's terms.
#[derive(Clone, Debug)]
pub struct DancerTrack {
    pub skeleton: Skeleton,
    pub roots: Vec<f32>,          // (T, 3) pelvis world position
    pub rotmats: Vec<f32>,        // (T, 495) local rotations, row-major 3x3 per joint
    pub positions: Vec<f32>,      // (T, 165) world joint positions (FK of the above)
    pub contacts: Vec<[bool; 2]>, // (T, 2) left/right foot planted
}

impl DancerTrack {
    /// The dataset's `rotmat` row layout: (T, 3 + 495), root translation first.
    pub fn rotmat_with_root(&self) -> Vec<f32> {
        let frames = self.contacts.len();
        let mut out = Vec::with_capacity(frames * (3 + ROT_DIM)); // (T, 498)
        for t in 0..frames {
            out.extend_from_slice(&self.roots[3 * t..3 * t + 3]);
            out.extend_from_slice(&self.rotmats[ROT_DIM * t..ROT_DIM * (t + 1)]);
        }
        out
    }
}

/// A figure as it happened in a take (for takes.json and tests).
#[derive(Clone, Debug)]
pub struct FigureLog {
    pub name: &'static str,
    pub hold: Hold,
    pub start_frame: usize,
    pub end_frame: usize,
    pub response: Response,
}

/// One synthesized duet take.
#[derive(Clone, Debug)]
pub struct Take {
    pub genre: Genre,
    pub bpm: f32,
    pub frames: usize,
    /// Beat times in seconds.
    pub beats: Vec<f32>,
    pub beats_per_bar: usize,
    pub leader: DancerTrack,
    pub follower: DancerTrack,
    pub music: Vec<f32>, // (T, 54)
    pub figures: Vec<FigureLog>,
}

/// Settings of one take.
#[derive(Clone, Copy, Debug)]
pub struct TakeSpec {
    pub genre: Genre,
    pub seconds: f32,
    /// Tempo; drawn from the genre's range when `None`.
    pub bpm: Option<f32>,
    /// Beat grid (seconds): when set, the tempo is moved to the nearest one
    /// whose beat lasts a whole number of these and every beat falls on a
    /// multiple of it (`duolando synth --beat-grid-frames`).
    pub beat_grid: Option<f32>,
    /// Seeds the leader's choreography, tempo, body sizes and music.
    pub choreo_seed: u64,
    /// Seeds the follower's hidden responses.
    pub take_seed: u64,
}

fn hold_targets(fig: Option<&PlacedFigure>) -> (Hold, Response) {
    match fig {
        Some(f) => (f.figure.hold, f.response),
        None => (
            Hold::Closed,
            Response {
                spin: 0,
                arm_style: 0,
                swap_accent: false,
            },
        ),
    }
}

/// How long a change of hold takes (s).
const HOLD_BLEND: f32 = 0.4;

/// Generates one take deterministically from its spec.
pub fn generate(spec: &TakeSpec) -> Take {
    let mut choreo = Rng::new(spec.choreo_seed, 1);
    let mut take_rng = Rng::new(spec.take_seed, 2);
    let plan = Plan::new(
        spec.genre,
        spec.bpm,
        spec.beat_grid,
        spec.seconds,
        &mut choreo,
        &mut take_rng,
    );
    let scales = [choreo.range(0.98, 1.06), choreo.range(0.9, 0.97)];
    let skels = scales.map(Skeleton::adult);
    let feet: [[FootTrack; 2]; 2] = [
        plan_feet(&plan, false, scales[0]),
        plan_feet(&plan, true, scales[1]),
    ];
    let frames = (spec.seconds * FPS).round() as usize;
    let style = spec.genre.style();
    let first_beat = plan.beats.first().copied().unwrap_or(0.0);
    let mut tracks = skels.map(|skeleton| DancerTrack {
        skeleton,
        roots: Vec::with_capacity(frames * 3),
        rotmats: Vec::with_capacity(frames * ROT_DIM),
        positions: Vec::with_capacity(frames * POS_DIM),
        contacts: Vec::with_capacity(frames),
    });
    for f in 0..frames {
        let time = f as f32 / FPS;
        let couple = plan.couple_at(time);
        let beat = (time - first_beat) / plan.period;
        let bar = beat / plan.beats_per_bar as f32;
        let mut pelvis = [[0.0f32; 3]; 2];
        let mut heading = [0.0f32; 2];
        let mut placed: [[(FootPlace, bool, f32); 2]; 2] =
            [[(feet[0][0].initial, true, 0.0); 2]; 2];
        for d in 0..2 {
            let body = couple.body(d == 1);
            let s = scales[d];
            placed[d] = [feet[d][0].at(time), feet[d][1].at(time)];
            // Weight shift towards the stance foot while the other swings.
            let mut p = body.pos;
            for k in 0..2 {
                let (_, planted, arc) = placed[d][k];
                if !planted {
                    let stance = placed[d][1 - k].0.ankle;
                    let toward = sub([stance[0], 0.0, stance[2]], [p[0], 0.0, p[2]]);
                    p = add(p, scale(toward, 0.2 * arc));
                }
            }
            let rise = -0.5 * style.rise * (std::f32::consts::TAU * bar).cos();
            let bounce = -style.bounce * (0.5 + 0.5 * (std::f32::consts::TAU * beat).cos());
            p[1] = skels[d].standing_pelvis_height() - style.crouch * s + (rise + bounce) * s;
            pelvis[d] = p;
            heading[d] = body.heading;
        }
        let frame = Frame {
            couple,
            pelvis,
            heading,
            scale: scales,
            beat,
        };
        let upper = current_upper(&plan, time, &frame);
        let roll = style.hip_roll * (std::f32::consts::PI * beat).sin();
        for d in 0..2 {
            let t = Targets {
                pelvis: pelvis[d],
                heading: heading[d],
                roll,
                pitch: 0.0,
                lean: upper.lean[d],
                twist: -0.5 * roll,
                head_yaw: upper.head_yaw[d],
                head_pitch: upper.head_pitch[d],
                feet: [placed[d][0].0, placed[d][1].0],
                hands: upper.hands[d],
                curl: upper.curl[d],
                collar: upper.collar[d],
            };
            let (local, pose) = solve(&skels[d], &t);
            let tr = &mut tracks[d];
            tr.roots.extend_from_slice(&pose.positions[0]);
            for m in local.iter() {
                tr.rotmats.extend_from_slice(&flatten(m));
            }
            tr.positions.extend(pose.positions.iter().flatten());
            tr.contacts.push([placed[d][0].1, placed[d][1].1]);
        }
    }
    let mut music_rng = Rng::new(spec.choreo_seed, 3);
    let music = synthetic_features(&plan, frames, &mut music_rng);
    let figures = plan
        .figures
        .iter()
        .map(|p| FigureLog {
            name: p.figure.name,
            hold: p.figure.hold,
            start_frame: (p.t0 * FPS).round() as usize,
            end_frame: ((p.t1 * FPS).round() as usize).min(frames),
            response: p.response,
        })
        .collect();
    let [leader, follower] = tracks;
    Take {
        genre: spec.genre,
        bpm: plan.bpm,
        frames,
        beats: plan.beats.clone(),
        beats_per_bar: plan.beats_per_bar,
        leader,
        follower,
        music,
        figures,
    }
}

/// Upper-body targets at `time`, blending from the previous hold over
/// [`HOLD_BLEND`] seconds after a figure starts.
fn current_upper(plan: &Plan, time: f32, frame: &Frame) -> UpperBody {
    match plan.figure_at(time) {
        None => {
            let (h, r) = hold_targets(None);
            upper_body(h, r, frame)
        }
        Some((i, since)) => {
            let (h, r) = hold_targets(Some(&plan.figures[i]));
            let cur = upper_body(h, r, frame);
            let s = ease(since / HOLD_BLEND);
            if s >= 1.0 {
                return cur;
            }
            let (ph, pr) = hold_targets(i.checked_sub(1).map(|k| &plan.figures[k]));
            blend(&upper_body(ph, pr, frame), &cur, s)
        }
    }
}

/// Horizontal distance between two points (x, z).
pub fn floor_distance(a: Vec3, b: Vec3) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
