//! Foot placement: each foot is planted (fixed position and yaw) except
//! during the swing of a step, when it travels on a lifted arc.

use super::choreography::{dancer_foot, ease, Plan};
use super::genre::StepKind;
use crate::skeleton::math::{add, lerp, mat_vec, rot_y, Vec3};

/// A foot's ankle position and yaw (the foot is kept flat).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootPlace {
    pub ankle: Vec3,
    pub yaw: f32,
}

/// One swing phase of a foot.
#[derive(Clone, Copy, Debug)]
pub struct Swing {
    pub lift: f32,
    pub land: f32,
    pub from: FootPlace,
    pub to: FootPlace,
    /// Taps and kicks go out to this point and come back.
    pub apex: Option<Vec3>,
}

/// Stance and swing schedule of one foot.
#[derive(Clone, Debug)]
pub struct FootTrack {
    pub initial: FootPlace,
    pub swings: Vec<Swing>,
}

/// Lateral foot spacing and ankle height of the adult rig (scaled).
const HALF_STANCE: f32 = 0.09;
const ANKLE_HEIGHT: f32 = 0.07;
const TOE_OUT: f32 = 0.08;
const LIFT: f32 = 0.05;

/// The home place of `foot` (0 left, 1 right) for a dancer at time `t`.
fn home(plan: &Plan, follower: bool, foot: usize, t: f32, scale: f32) -> FootPlace {
    let body = plan.couple_at(t).body(follower);
    let side = if foot == 0 { 1.0 } else { -1.0 };
    let off = mat_vec(&rot_y(body.heading), [side * HALF_STANCE * scale, 0.0, 0.0]);
    let mut ankle = add(body.pos, off);
    ankle[1] = ANKLE_HEIGHT * scale;
    FootPlace {
        ankle,
        yaw: body.heading + side * TOE_OUT,
    }
}

/// Plans both feet of a dancer (`scale` is the rig scale).
pub fn plan_feet(plan: &Plan, follower: bool, scale: f32) -> [FootTrack; 2] {
    let mut tracks = [0, 1].map(|f| FootTrack {
        initial: home(plan, follower, f, 0.0, scale),
        swings: Vec::new(),
    });
    let swing_frac = plan.genre.style().swing;
    for ts in &plan.steps {
        let foot = dancer_foot(ts.step.foot, follower);
        let track = &mut tracks[foot];
        let from = track.swings.last().map(|s| s.to).unwrap_or(track.initial);
        let mut kind = ts.step.kind;
        if follower && plan.figures[ts.figure].response.swap_accent {
            kind = match kind {
                StepKind::Tap => StepKind::Kick,
                StepKind::Kick => StepKind::Tap,
                k => k,
            };
        }
        let lift = ts.t0;
        let swing = match kind {
            StepKind::Step => {
                let land = ts.t0 + (swing_frac * ts.dur).max(0.1f32.min(ts.dur));
                let to = home(plan, follower, foot, ts.t0 + ts.dur, scale);
                Swing {
                    lift,
                    land,
                    from,
                    to,
                    apex: None,
                }
            }
            StepKind::Tap => {
                let heading = plan.couple_at(ts.t0).heading;
                let d = mat_vec(&rot_y(heading), [ts.step.side, 0.0, ts.step.fwd]);
                let apex = add(from.ankle, [d[0] * scale, 0.01, d[2] * scale]);
                Swing {
                    lift,
                    land: ts.t0 + 0.9 * ts.dur,
                    from,
                    to: from,
                    apex: Some(apex),
                }
            }
            StepKind::Kick => {
                let body = plan.couple_at(ts.t0).body(follower);
                let side = if foot == 0 { 1.0 } else { -1.0 };
                let d = mat_vec(&rot_y(body.heading), [side * 0.25, 0.2, 0.12]);
                Swing {
                    lift,
                    land: ts.t0 + 0.9 * ts.dur,
                    from,
                    to: from,
                    apex: Some(add(from.ankle, scale3(d, scale))),
                }
            }
        };
        track.swings.push(swing);
    }
    tracks
}

fn scale3(v: Vec3, s: f32) -> Vec3 {
    [v[0] * s, v[1] * s, v[2] * s]
}

impl FootTrack {
    /// The foot's place at `t` and whether it is in contact (planted).
    pub fn at(&self, t: f32) -> (FootPlace, bool, f32) {
        let n = self.swings.partition_point(|s| s.lift <= t);
        let Some(i) = n.checked_sub(1) else {
            return (self.initial, true, 0.0);
        };
        let s = &self.swings[i];
        if t >= s.land {
            return (s.to, true, 0.0);
        }
        let u = ((t - s.lift) / (s.land - s.lift)).clamp(0.0, 1.0);
        let arc = (std::f32::consts::PI * u).sin();
        let yaw = s.from.yaw + (s.to.yaw - s.from.yaw) * ease(u);
        let ankle = match s.apex {
            None => {
                let mut p = lerp(s.from.ankle, s.to.ankle, ease(u));
                p[1] += LIFT * arc;
                p
            }
            Some(apex) if u < 0.5 => lerp(s.from.ankle, apex, ease(2.0 * u)),
            Some(apex) => lerp(apex, s.to.ankle, ease(2.0 * u - 1.0)),
        };
        (FootPlace { ankle, yaw }, false, arc)
    }
}
