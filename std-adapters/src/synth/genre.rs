//! Dance genres and their figure tables.
//!
//! A figure is a short list of leader steps in the couple frame (see
//! [`Step`]); the follower mirrors each step with the other foot. Tempos
//! stay inside DD100's 72-163 BPM.

use std::f32::consts::PI;

/// The leader's moving foot (the follower moves the other one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Foot {
    Left,
    Right,
}

/// What a step does with the moving foot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepKind {
    /// A weight transfer: the foot lands at its new home and the couple
    /// frame moves by the step's displacement.
    Step,
    /// The foot touches out along the displacement and returns; no travel.
    Tap,
    /// The foot kicks forward and up and returns; no travel.
    Kick,
}

/// How the couple holds each other during a figure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hold {
    /// Closed ballroom hold: leader's left hand joined with follower's
    /// right, leader's right hand on the follower's back, follower's left
    /// hand on the leader's right upper arm.
    Closed,
    /// Open hold: only leader-left / follower-right joined; the free arms
    /// gesture (leader) and answer (follower, style chosen at random).
    Open,
    /// Joined hands raised above the couple; the follower may spin under
    /// them (her choice, hidden).
    Underarm,
}

/// One leader step. `side` (+ = leader's left) and `fwd` (+ = leader's
/// forward) are the couple-frame travel in metres; `turn` is the couple's
/// turn in radians (+ = towards the leader's left).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    pub beats: f32,
    pub foot: Foot,
    pub side: f32,
    pub fwd: f32,
    pub turn: f32,
    pub kind: StepKind,
}

/// A named figure.
#[derive(Clone, Copy, Debug)]
pub struct Figure {
    pub name: &'static str,
    pub hold: Hold,
    pub steps: &'static [Step],
}

impl Figure {
    /// Total length in beats.
    pub fn beats(&self) -> f32 {
        self.steps.iter().map(|s| s.beats).sum()
    }
}

const L: Foot = Foot::Left;
const R: Foot = Foot::Right;
const D: f32 = PI / 180.0;

const fn st(beats: f32, foot: Foot, side: f32, fwd: f32, turn_deg: f32) -> Step {
    Step {
        beats,
        foot,
        side,
        fwd,
        turn: turn_deg * D,
        kind: StepKind::Step,
    }
}
const fn tap(beats: f32, foot: Foot, side: f32, fwd: f32) -> Step {
    Step {
        beats,
        foot,
        side,
        fwd,
        turn: 0.0,
        kind: StepKind::Tap,
    }
}
const fn kick(beats: f32, foot: Foot) -> Step {
    Step {
        beats,
        foot,
        side: 0.0,
        fwd: 0.3,
        turn: 0.0,
        kind: StepKind::Kick,
    }
}
const fn fig(name: &'static str, hold: Hold, steps: &'static [Step]) -> Figure {
    Figure { name, hold, steps }
}

const WALTZ: &[Figure] = &[
    fig(
        "box_forward",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, 0.28, 0.0),
            st(1.0, R, -0.22, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "box_back",
        Hold::Closed,
        &[
            st(1.0, R, 0.0, -0.28, 0.0),
            st(1.0, L, 0.22, 0.0, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "natural_turn",
        Hold::Closed,
        &[
            st(1.0, R, 0.0, 0.28, -45.0),
            st(1.0, L, 0.2, 0.0, -45.0),
            st(1.0, R, 0.0, 0.0, -10.0),
        ],
    ),
    fig(
        "reverse_turn",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, 0.28, 45.0),
            st(1.0, R, -0.2, 0.0, 45.0),
            st(1.0, L, 0.0, 0.0, 10.0),
        ],
    ),
    fig(
        "hesitation",
        Hold::Closed,
        &[st(1.0, L, 0.0, 0.25, 0.0), tap(2.0, R, 0.0, 0.15)],
    ),
    fig(
        "promenade",
        Hold::Open,
        &[
            st(1.0, L, 0.24, 0.0, 0.0),
            st(1.0, R, 0.2, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "underarm_turn",
        Hold::Underarm,
        &[
            st(1.0, L, 0.0, 0.18, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(1.0, R, 0.0, -0.18, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
];

const TANGO: &[Figure] = &[
    fig(
        "walks",
        Hold::Closed,
        &[st(2.0, L, 0.0, 0.34, 0.0), st(2.0, R, 0.0, 0.34, 0.0)],
    ),
    fig(
        "progressive_link",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, 0.3, 0.0),
            st(1.0, R, -0.08, 0.1, 0.0),
            st(2.0, L, 0.0, 0.0, 25.0),
        ],
    ),
    fig(
        "rock_turn",
        Hold::Closed,
        &[
            st(1.0, R, 0.0, 0.25, -30.0),
            st(1.0, L, 0.0, -0.18, -30.0),
            st(2.0, R, 0.0, 0.0, -30.0),
        ],
    ),
    fig(
        "corte",
        Hold::Closed,
        &[st(2.0, R, 0.0, -0.3, 0.0), st(2.0, L, 0.0, 0.3, 0.0)],
    ),
    fig(
        "open_promenade",
        Hold::Open,
        &[
            st(2.0, L, 0.3, 0.0, 0.0),
            st(1.0, R, 0.25, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "tap_and_close",
        Hold::Closed,
        &[tap(2.0, L, 0.25, 0.0), st(2.0, L, 0.0, 0.0, 0.0)],
    ),
];

const FOXTROT: &[Figure] = &[
    fig(
        "feather",
        Hold::Closed,
        &[
            st(2.0, R, 0.0, 0.35, 0.0),
            st(1.0, L, 0.0, 0.3, 0.0),
            st(1.0, R, 0.0, 0.3, 0.0),
        ],
    ),
    fig(
        "three_step",
        Hold::Closed,
        &[
            st(2.0, L, 0.0, 0.33, 0.0),
            st(1.0, R, 0.0, 0.3, 0.0),
            st(1.0, L, 0.0, 0.3, 0.0),
        ],
    ),
    fig(
        "reverse_turn",
        Hold::Closed,
        &[
            st(2.0, L, 0.0, 0.3, 40.0),
            st(1.0, R, -0.2, 0.0, 40.0),
            st(1.0, L, 0.0, -0.2, 20.0),
        ],
    ),
    fig(
        "natural_weave",
        Hold::Open,
        &[
            st(2.0, R, 0.0, 0.3, -30.0),
            st(1.0, L, 0.2, 0.0, -30.0),
            st(1.0, R, 0.0, -0.25, 0.0),
        ],
    ),
    fig(
        "underarm_turn",
        Hold::Underarm,
        &[
            st(2.0, L, 0.0, 0.2, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(2.0, R, 0.0, -0.2, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
];

const QUICKSTEP: &[Figure] = &[
    fig(
        "quarter_turn",
        Hold::Closed,
        &[
            st(2.0, R, 0.0, 0.32, -45.0),
            st(1.0, L, 0.2, 0.0, -45.0),
            st(1.0, R, 0.08, 0.0, 0.0),
            st(2.0, L, 0.16, 0.0, 0.0),
            st(2.0, R, 0.0, -0.25, 0.0),
        ],
    ),
    fig(
        "chasse",
        Hold::Closed,
        &[
            st(1.0, L, 0.2, 0.0, 0.0),
            st(1.0, R, 0.08, 0.0, 0.0),
            st(2.0, L, 0.2, 0.0, 0.0),
        ],
    ),
    fig(
        "lock_step",
        Hold::Closed,
        &[
            st(2.0, L, 0.0, 0.3, 0.0),
            st(1.0, R, 0.05, 0.2, 0.0),
            st(1.0, L, 0.0, 0.2, 0.0),
            st(2.0, R, 0.0, 0.3, 0.0),
            st(2.0, L, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "hop_kicks",
        Hold::Open,
        &[
            kick(1.0, L),
            st(1.0, L, 0.0, 0.0, 0.0),
            kick(1.0, R),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
];

const RUMBA: &[Figure] = &[
    fig(
        "basic",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, 0.18, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(2.0, L, 0.14, -0.1, 0.0),
            st(1.0, R, 0.0, -0.18, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(2.0, R, -0.14, 0.1, 0.0),
        ],
    ),
    fig(
        "new_york",
        Hold::Open,
        &[
            st(1.0, L, 0.2, 0.0, 20.0),
            st(1.0, R, 0.0, 0.0, -20.0),
            st(2.0, L, -0.2, 0.0, 0.0),
        ],
    ),
    fig(
        "alemana",
        Hold::Underarm,
        &[
            st(1.0, L, 0.0, 0.15, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(2.0, L, 0.0, 0.0, 0.0),
            st(1.0, R, 0.0, -0.15, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(2.0, R, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "side_steps",
        Hold::Closed,
        &[
            st(1.0, L, 0.2, 0.0, 0.0),
            st(1.0, R, 0.1, 0.0, 0.0),
            st(2.0, L, 0.2, 0.0, 0.0),
        ],
    ),
];

const CHACHA: &[Figure] = &[
    fig(
        "basic",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, 0.2, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(0.5, L, 0.12, -0.1, 0.0),
            st(0.5, R, 0.06, 0.0, 0.0),
            st(1.0, L, 0.12, 0.0, 0.0),
            st(1.0, R, 0.0, -0.2, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(0.5, R, -0.12, 0.1, 0.0),
            st(0.5, L, -0.06, 0.0, 0.0),
            st(1.0, R, -0.12, 0.0, 0.0),
        ],
    ),
    fig(
        "hand_to_hand",
        Hold::Open,
        &[
            st(1.0, L, 0.0, -0.2, 30.0),
            st(1.0, R, 0.0, 0.0, -30.0),
            st(0.5, L, 0.12, 0.0, 0.0),
            st(0.5, R, 0.06, 0.0, 0.0),
            st(1.0, L, 0.12, 0.0, 0.0),
        ],
    ),
    fig(
        "spot_turn",
        Hold::Underarm,
        &[
            st(1.0, L, 0.0, 0.15, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(0.5, L, 0.0, -0.15, 0.0),
            st(0.5, R, 0.0, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
];

const SAMBA: &[Figure] = &[
    fig(
        "basic_bounce",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, 0.2, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(1.0, R, 0.0, -0.2, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "whisks",
        Hold::Closed,
        &[
            st(1.0, L, 0.18, 0.0, 0.0),
            tap(1.0, R, 0.0, -0.12),
            st(1.0, R, -0.18, 0.0, 0.0),
            tap(1.0, L, 0.0, -0.12),
        ],
    ),
    fig(
        "botafogo",
        Hold::Open,
        &[
            st(1.0, L, 0.15, 0.15, 25.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(1.0, R, -0.15, 0.15, -25.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "samba_roll",
        Hold::Underarm,
        &[
            st(1.0, L, 0.0, 0.12, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(1.0, L, 0.0, -0.12, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
];

const JIVE: &[Figure] = &[
    fig(
        "fallaway_rock",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, -0.2, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(0.5, L, 0.12, 0.0, 0.0),
            st(0.5, R, 0.05, 0.0, 0.0),
            st(1.0, L, 0.12, 0.0, 0.0),
            st(0.5, R, -0.12, 0.0, 0.0),
            st(0.5, L, -0.05, 0.0, 0.0),
            st(1.0, R, -0.12, 0.0, 0.0),
        ],
    ),
    fig(
        "kicks",
        Hold::Open,
        &[
            kick(1.0, L),
            st(1.0, L, 0.0, 0.0, 0.0),
            kick(1.0, R),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "change_of_places",
        Hold::Underarm,
        &[
            st(1.0, L, 0.0, -0.15, 0.0),
            st(1.0, R, 0.0, 0.0, 0.0),
            st(0.5, L, 0.0, 0.0, 45.0),
            st(0.5, R, 0.0, 0.0, 45.0),
            st(1.0, L, 0.0, 0.0, 0.0),
            st(0.5, R, 0.0, 0.0, 45.0),
            st(0.5, L, 0.0, 0.0, 45.0),
            st(1.0, R, 0.0, 0.0, 0.0),
        ],
    ),
    fig(
        "link",
        Hold::Closed,
        &[
            st(1.0, L, 0.0, -0.2, 0.0),
            st(1.0, R, 0.0, 0.2, 0.0),
            st(0.5, L, 0.0, 0.0, 0.0),
            st(0.5, R, 0.0, 0.0, 0.0),
            st(1.0, L, 0.0, 0.0, 0.0),
        ],
    ),
];

/// Per-genre movement style.
#[derive(Clone, Copy, Debug)]
pub struct Style {
    /// Rise and fall of the pelvis over a bar (m).
    pub rise: f32,
    /// Per-beat bounce depth of the pelvis (m).
    pub bounce: f32,
    /// Hip roll amplitude (radians) over two beats.
    pub hip_roll: f32,
    /// Knee softness: how far below standing the pelvis rides (m).
    pub crouch: f32,
    /// Swing phase as a fraction of the step (the rest is stance).
    pub swing: f32,
}

/// The genres, named like DD100's take prefixes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Genre {
    Waltz,
    Tango,
    Foxtrot,
    Quickstep,
    Rumba,
    ChaCha,
    Samba,
    Jive,
}

impl Genre {
    /// Every genre.
    pub const ALL: [Genre; 8] = [
        Genre::Waltz,
        Genre::Tango,
        Genre::Foxtrot,
        Genre::Quickstep,
        Genre::Rumba,
        Genre::ChaCha,
        Genre::Samba,
        Genre::Jive,
    ];

    /// The name used in take file names.
    pub fn name(self) -> &'static str {
        match self {
            Genre::Waltz => "Waltz",
            Genre::Tango => "Tango",
            Genre::Foxtrot => "Foxtrot",
            Genre::Quickstep => "Quickstep",
            Genre::Rumba => "Rumba",
            Genre::ChaCha => "ChaCha",
            Genre::Samba => "Samba",
            Genre::Jive => "Jive",
        }
    }

    /// Tempo range in BPM (all within 72-163).
    pub fn bpm_range(self) -> (f32, f32) {
        match self {
            Genre::Waltz => (78.0, 96.0),
            Genre::Tango => (112.0, 132.0),
            Genre::Foxtrot => (104.0, 120.0),
            Genre::Quickstep => (140.0, 163.0),
            Genre::Rumba => (72.0, 104.0),
            Genre::ChaCha => (112.0, 128.0),
            Genre::Samba => (96.0, 108.0),
            Genre::Jive => (136.0, 163.0),
        }
    }

    /// Beats per bar.
    pub fn beats_per_bar(self) -> usize {
        match self {
            Genre::Waltz => 3,
            Genre::Samba => 2,
            _ => 4,
        }
    }

    /// The figure table.
    pub fn figures(self) -> &'static [Figure] {
        match self {
            Genre::Waltz => WALTZ,
            Genre::Tango => TANGO,
            Genre::Foxtrot => FOXTROT,
            Genre::Quickstep => QUICKSTEP,
            Genre::Rumba => RUMBA,
            Genre::ChaCha => CHACHA,
            Genre::Samba => SAMBA,
            Genre::Jive => JIVE,
        }
    }

    /// Movement style.
    pub fn style(self) -> Style {
        let s = |rise, bounce, hip_roll, crouch, swing| Style {
            rise,
            bounce,
            hip_roll,
            crouch,
            swing,
        };
        match self {
            Genre::Waltz => s(0.05, 0.0, 0.02, 0.03, 0.6),
            Genre::Tango => s(0.0, 0.0, 0.02, 0.06, 0.45),
            Genre::Foxtrot => s(0.035, 0.0, 0.02, 0.04, 0.6),
            Genre::Quickstep => s(0.02, 0.015, 0.02, 0.04, 0.55),
            Genre::Rumba => s(0.0, 0.0, 0.09, 0.03, 0.5),
            Genre::ChaCha => s(0.0, 0.008, 0.08, 0.03, 0.5),
            Genre::Samba => s(0.0, 0.03, 0.05, 0.05, 0.5),
            Genre::Jive => s(0.0, 0.025, 0.04, 0.05, 0.5),
        }
    }
}
