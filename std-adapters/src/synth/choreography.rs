//! The choreography of one take: a beat grid, the leader's figure
//! sequence placed on bars, the follower's hidden choices, the couple
//! frame over time, and each foot's stance/swing schedule.

use super::genre::{Figure, Foot, Genre, Hold, Step, StepKind};
use super::rng::Rng;
use crate::skeleton::math::{add, mat_vec, rot_y, Vec3};
use std::f32::consts::TAU;

/// The follower's hidden response to one figure (not visible in the
/// leader's motion or the music).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Response {
    /// Underarm figures: 0 no spin, +1 spins to her left, -1 to her right.
    pub spin: i8,
    /// Open figures: free-arm answer 0 mirror, 1 high flourish, 2 low.
    pub arm_style: u8,
    /// Taps and kicks: true answers with the other kind (tap <-> kick).
    pub swap_accent: bool,
}

/// One figure placed in time.
#[derive(Clone, Debug)]
pub struct PlacedFigure {
    pub figure: Figure,
    pub t0: f32,
    pub t1: f32,
    /// Pelvis-to-pelvis distance the couple settles to during the figure.
    pub distance: f32,
    pub response: Response,
}

/// One leader step placed in time.
#[derive(Clone, Copy, Debug)]
pub struct TimedStep {
    pub t0: f32,
    pub dur: f32,
    pub step: Step,
    pub figure: usize,
}

/// The couple frame: centre on the floor (x, z), heading (the leader faces
/// `rot_y(heading) * +z`), pelvis distance, and the follower's extra spin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Couple {
    pub center: [f32; 2],
    pub heading: f32,
    pub distance: f32,
    pub spin: f32,
}

/// A dancer's body frame on the floor.
#[derive(Clone, Copy, Debug)]
pub struct Body {
    pub pos: Vec3, // (x, 0, z)
    pub heading: f32,
}

impl Couple {
    /// The leader's (`follower = false`) or follower's body frame.
    pub fn body(&self, follower: bool) -> Body {
        let half = mat_vec(&rot_y(self.heading), [0.0, 0.0, 0.5 * self.distance]);
        let c = [self.center[0], 0.0, self.center[1]];
        if follower {
            Body {
                pos: add(c, half),
                heading: self.heading + std::f32::consts::PI + self.spin,
            }
        } else {
            Body {
                pos: [c[0] - half[0], 0.0, c[2] - half[2]],
                heading: self.heading,
            }
        }
    }
}

/// The whole plan of a take.
#[derive(Clone, Debug)]
pub struct Plan {
    pub genre: Genre,
    pub bpm: f32,
    /// Seconds per beat.
    pub period: f32,
    /// Beat times in seconds (covering the take).
    pub beats: Vec<f32>,
    pub beats_per_bar: usize,
    pub figures: Vec<PlacedFigure>,
    pub steps: Vec<TimedStep>,
    /// Couple frame at the start of each step, plus one after the last.
    pub keys: Vec<Couple>,
}

/// Smoothstep easing on [0, 1].
pub fn ease(s: f32) -> f32 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// The tempo range of every take (beats per minute).
pub const MIN_BPM: f32 = 72.0;
pub const MAX_BPM: f32 = 163.0;

/// `bpm` moved to the nearest tempo in [`MIN_BPM`, `MAX_BPM`] whose beat
/// lasts a whole number of `grid` seconds, and `first_beat` to the nearest
/// positive multiple of `grid`: every beat then falls on the grid (for
/// Bailando's 8-frame tokens at 60 fps, a grid of 2/15 s gives 150, 112.5,
/// 90 or 75 BPM). A grid too coarse for the range leaves the tempo as it is.
pub fn snap_to_grid(bpm: f32, first_beat: f32, grid: f32) -> (f32, f32) {
    if !(grid.is_finite() && grid > 0.0) {
        return (bpm, first_beat);
    }
    let lo = (60.0 / MAX_BPM / grid).ceil().max(1.0);
    let hi = (60.0 / MIN_BPM / grid).floor();
    if lo > hi {
        return (bpm, first_beat);
    }
    let n = (60.0 / bpm / grid).round().clamp(lo, hi);
    let first = ((first_beat / grid).round().max(1.0) * grid).min(n * grid);
    (60.0 / (n * grid), first)
}

impl Plan {
    /// Plans a take of `seconds` for `genre` (tempo drawn in the genre's
    /// range unless `bpm` is given; on `grid` when given, see
    /// [`snap_to_grid`]). `choreo` draws the figure sequence; `take` draws
    /// the follower's hidden responses, so two takes of one choreography
    /// share the leader's figures but not her answers.
    pub fn new(
        genre: Genre,
        bpm: Option<f32>,
        grid: Option<f32>,
        seconds: f32,
        choreo: &mut Rng,
        take: &mut Rng,
    ) -> Plan {
        let (lo, hi) = genre.bpm_range();
        let bpm = bpm
            .unwrap_or_else(|| choreo.range(lo, hi))
            .clamp(MIN_BPM, MAX_BPM);
        let first_beat = choreo.range(0.05, 60.0 / bpm);
        let (bpm, first_beat) = match grid {
            Some(q) => snap_to_grid(bpm, first_beat, q),
            None => (bpm, first_beat),
        };
        let period = 60.0 / bpm;
        let n_beats = ((seconds - first_beat) / period).ceil().max(1.0) as usize + 1;
        let beats: Vec<f32> = (0..n_beats)
            .map(|k| first_beat + k as f32 * period)
            .collect();
        let bar = genre.beats_per_bar();
        let table = genre.figures();
        let mut figures = Vec::new();
        let mut steps = Vec::new();
        // One bar of standing in hold, then figures on bar lines.
        let mut beat = bar as f32;
        let end_beat = (seconds - first_beat) / period;
        let mut prev = usize::MAX;
        loop {
            let mut pick = choreo.below(table.len());
            if pick == prev {
                pick = (pick + 1 + choreo.below(table.len() - 1)) % table.len();
            }
            prev = pick;
            let figure = table[pick];
            let len = figure.beats();
            if beat + len > end_beat - 0.5 {
                break;
            }
            let t0 = first_beat + beat * period;
            let distance = choreo.range(0.34, 0.52);
            let response = Response {
                spin: if figure.hold == Hold::Underarm {
                    [0i8, 1, -1][take.below(3)]
                } else {
                    0
                },
                arm_style: if figure.hold == Hold::Open {
                    take.below(3) as u8
                } else {
                    0
                },
                swap_accent: take.chance(0.5),
            };
            let mut b = beat;
            for s in figure.steps {
                steps.push(TimedStep {
                    t0: first_beat + b * period,
                    dur: s.beats * period,
                    step: *s,
                    figure: figures.len(),
                });
                b += s.beats;
            }
            figures.push(PlacedFigure {
                figure,
                t0,
                t1: first_beat + b * period,
                distance,
                response,
            });
            // Next figure on the next bar line (pauses fill the bar).
            beat = ((b / bar as f32).ceil() * bar as f32).max(b);
        }
        let keys = Self::keyframes(
            &steps,
            &figures,
            choreo.range(0.0, TAU),
            choreo.range(0.38, 0.48),
        );
        Plan {
            genre,
            bpm,
            period,
            beats,
            beats_per_bar: bar,
            figures,
            steps,
            keys,
        }
    }

    fn keyframes(
        steps: &[TimedStep],
        figures: &[PlacedFigure],
        heading: f32,
        distance: f32,
    ) -> Vec<Couple> {
        let mut cur = Couple {
            center: [0.0, 0.0],
            heading,
            distance,
            spin: 0.0,
        };
        let mut keys = vec![cur];
        for (i, ts) in steps.iter().enumerate() {
            let s = ts.step;
            if s.kind == StepKind::Step {
                let d = mat_vec(&rot_y(cur.heading), [s.side, 0.0, s.fwd]);
                cur.center = [cur.center[0] + d[0], cur.center[1] + d[2]];
                cur.heading += s.turn;
                let fig = &figures[ts.figure];
                let first_weight_step = steps[..i]
                    .iter()
                    .rev()
                    .take_while(|p| p.figure == ts.figure)
                    .all(|p| p.step.kind != StepKind::Step);
                if first_weight_step {
                    cur.distance = fig.distance;
                }
                if fig.response.spin != 0 {
                    let n = fig
                        .figure
                        .steps
                        .iter()
                        .filter(|p| p.kind == StepKind::Step)
                        .count()
                        .max(1);
                    cur.spin += fig.response.spin as f32 * TAU / n as f32;
                }
            }
            keys.push(cur);
        }
        // Spins are whole turns: wrap so headings stay small.
        keys
    }

    /// Index of the step active at `t` (or the last one started before).
    fn step_at(&self, t: f32) -> Option<usize> {
        let n = self.steps.partition_point(|s| s.t0 <= t);
        n.checked_sub(1)
    }

    /// The couple frame at time `t` (smooth within steps, still between).
    pub fn couple_at(&self, t: f32) -> Couple {
        let Some(i) = self.step_at(t) else {
            return self.keys[0];
        };
        let ts = &self.steps[i];
        let (a, b) = (self.keys[i], self.keys[i + 1]);
        let s = ease((t - ts.t0) / ts.dur);
        let mix = |x: f32, y: f32| x + (y - x) * s;
        Couple {
            center: [mix(a.center[0], b.center[0]), mix(a.center[1], b.center[1])],
            heading: mix(a.heading, b.heading),
            distance: mix(a.distance, b.distance),
            spin: mix(a.spin, b.spin),
        }
    }

    /// The figure active at `t` and the time since it started.
    pub fn figure_at(&self, t: f32) -> Option<(usize, f32)> {
        let n = self.figures.partition_point(|f| f.t0 <= t);
        n.checked_sub(1).map(|i| (i, t - self.figures[i].t0))
    }
}

/// Which physical foot of a dancer moves for a leader step.
pub fn dancer_foot(leader_foot: Foot, follower: bool) -> usize {
    match (leader_foot, follower) {
        (Foot::Left, false) | (Foot::Right, true) => 0,
        _ => 1,
    }
}

#[cfg(test)]
mod grid_tests {
    use super::snap_to_grid;

    #[test]
    fn tempi_and_first_beats_land_on_the_grid() {
        let q = 2.0 / 15.0;
        let bpm = |b: f32| snap_to_grid(b, 0.3, q).0;
        for (drawn, on_grid) in [
            (120.0, 112.5),
            (160.0, 150.0),
            (72.0, 75.0),
            (92.0, 90.0),
            (100.0, 90.0),
        ] {
            assert!(
                (bpm(drawn) - on_grid).abs() < 1e-3,
                "{drawn} -> {}",
                bpm(drawn)
            );
        }
        // First beat: the nearest positive multiple, at most one beat in.
        assert!((snap_to_grid(120.0, 0.3, q).1 - 2.0 * q).abs() < 1e-6);
        assert!((snap_to_grid(120.0, 0.01, q).1 - q).abs() < 1e-6);
        // A grid coarser than any beat in range leaves the tempo alone.
        assert_eq!(snap_to_grid(120.0, 0.3, 2.0), (120.0, 0.3));
        assert_eq!(snap_to_grid(120.0, 0.3, f32::NAN), (120.0, 0.3));
    }
}
