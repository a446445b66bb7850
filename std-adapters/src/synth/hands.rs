//! Hand targets for each hold: joined hands, the leader's hand on the
//! follower's back, her hand on his arm, and free-arm gestures.

use super::choreography::{Couple, Response};
use super::genre::Hold;
use crate::skeleton::math::{add, lerp, mat_vec, rot_y, scale, Vec3};
use std::f32::consts::PI;

/// Upper-body targets of both dancers for one frame (`[leader, follower]`,
/// each `[left, right]`).
#[derive(Clone, Copy, Debug)]
pub struct UpperBody {
    pub hands: [[Vec3; 2]; 2],
    pub curl: [[f32; 2]; 2],
    pub collar: [[f32; 2]; 2],
    pub head_yaw: [f32; 2],
    pub head_pitch: [f32; 2],
    pub lean: [f32; 2],
}

/// Where the joined hands (leader left, follower right) meet, and half
/// the gap kept between the two wrists.
const GRIP_GAP: f32 = 0.03;

/// A point in a dancer's frame: `pelvis + Ry(heading) * (x, y, z) * scale`.
fn at(pelvis: Vec3, heading: f32, s: f32, local: Vec3) -> Vec3 {
    add(pelvis, mat_vec(&rot_y(heading), scale(local, s)))
}

/// Inputs shared by every hold.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub couple: Couple,
    /// Pelvis positions and headings of [leader, follower].
    pub pelvis: [Vec3; 2],
    pub heading: [f32; 2],
    pub scale: [f32; 2],
    /// Beats since the first beat (continuous).
    pub beat: f32,
}

/// Upper-body targets for a hold and the follower's response.
pub fn upper_body(hold: Hold, resp: Response, f: &Frame) -> UpperBody {
    let [pl, pf] = f.pelvis;
    let [hl, hf] = f.heading;
    let [sl, sf] = f.scale;
    let c = [f.couple.center[0], 0.0, f.couple.center[1]];
    let fwd = mat_vec(&rot_y(f.couple.heading), [0.0, 0.0, 1.0]);
    let shoulder_y = 0.5 * (pl[1] + 0.45 * sl + pf[1] + 0.45 * sf);
    let wave = (PI * f.beat * 0.5).sin();
    let joined = |lateral: f32, height: f32| {
        let mut j = add(c, mat_vec(&rot_y(f.couple.heading), [lateral, 0.0, 0.0]));
        j[1] = height;
        (add(j, scale(fwd, -GRIP_GAP)), add(j, scale(fwd, GRIP_GAP)))
    };
    // The follower's free (left) arm: mirror of the leader's gesture, or her own style.
    let free_follower = |style: u8| match style {
        0 => at(pf, hf, sf, [0.57, 0.5 + 0.12 * wave, 0.1]),
        1 => at(pf, hf, sf, [0.35, 0.9, 0.05]),
        _ => at(pf, hf, sf, [0.2, 0.05, -0.04]),
    };
    match hold {
        Hold::Closed => {
            let (ll, fr) = joined(0.3 * sl, shoulder_y - 0.04);
            UpperBody {
                hands: [
                    [ll, at(pf, hf, sf, [0.1, 0.33, -0.1])],
                    [at(pl, hl, sl, [-0.2, 0.42, 0.06]), fr],
                ],
                curl: [[0.9, 0.25], [0.5, 0.9]],
                collar: [[0.05, 0.0], [0.08, 0.05]],
                head_yaw: [0.2, 0.5],
                head_pitch: [0.0, -0.15],
                lean: [-0.03, -0.12],
            }
        }
        Hold::Open => {
            let (ll, fr) = joined(0.42 * sl, shoulder_y - 0.15);
            UpperBody {
                hands: [
                    [ll, at(pl, hl, sl, [-0.57, 0.5 + 0.12 * wave, 0.1])],
                    [free_follower(resp.arm_style), fr],
                ],
                curl: [
                    [0.9, 0.1],
                    [0.1 + 0.3 * (resp.arm_style == 2) as u8 as f32, 0.9],
                ],
                collar: [[0.0, 0.05], [0.05, 0.0]],
                head_yaw: [0.3, -0.3],
                head_pitch: [0.0, 0.0],
                lean: [0.0, -0.03],
            }
        }
        Hold::Underarm => {
            let mut j = add(c, mat_vec(&rot_y(f.couple.heading), [0.05 * sl, 0.0, 0.0]));
            j[1] = pf[1] + 0.95 * sf;
            let (ll, fr) = (add(j, scale(fwd, -GRIP_GAP)), add(j, scale(fwd, GRIP_GAP)));
            UpperBody {
                hands: [
                    [ll, at(pl, hl, sl, [-0.4, 0.3, 0.15])],
                    [free_follower(resp.arm_style), fr],
                ],
                curl: [[0.9, 0.2], [0.2, 0.9]],
                collar: [[0.1, 0.0], [0.0, 0.1]],
                head_yaw: [0.0, 0.0],
                head_pitch: [-0.1, 0.0],
                lean: [0.0, 0.0],
            }
        }
    }
}

/// Blends two upper-body targets (`s` = 0 gives `a`).
pub fn blend(a: &UpperBody, b: &UpperBody, s: f32) -> UpperBody {
    let mix = |x: f32, y: f32| x + (y - x) * s;
    let mut out = *b;
    for d in 0..2 {
        for k in 0..2 {
            out.hands[d][k] = lerp(a.hands[d][k], b.hands[d][k], s);
            out.curl[d][k] = mix(a.curl[d][k], b.curl[d][k]);
            out.collar[d][k] = mix(a.collar[d][k], b.collar[d][k]);
        }
        out.head_yaw[d] = mix(a.head_yaw[d], b.head_yaw[d]);
        out.head_pitch[d] = mix(a.head_pitch[d], b.head_pitch[d]);
        out.lean[d] = mix(a.lean[d], b.lean[d]);
    }
    out
}
