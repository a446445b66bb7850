//! A synthetic 54-d music feature track laid out like the original
//! extractor's output (30 fps): MFCC 20 | MFCC delta 20 | chroma 12 |
//! onset envelope 1 | beat one-hot 1. See docs/SYNTH.md for the model.

use super::choreography::Plan;
use super::genre::Genre;
use super::rng::Rng;

/// Feature width.
pub const MUSIC_DIM: usize = 54;
const FPS: f32 = 30.0;

/// Chord progressions as (scale degree in semitones, minor?) per bar.
const PROGRESSIONS: [[(usize, bool); 4]; 4] = [
    [(0, false), (7, false), (9, true), (5, false)], // I V vi IV
    [(2, true), (7, false), (0, false), (9, true)],  // ii V I vi
    [(0, false), (5, false), (7, false), (5, false)], // I IV V IV
    [(9, true), (5, false), (0, false), (7, false)], // vi IV I V
];

fn syncopated(g: Genre) -> bool {
    matches!(
        g,
        Genre::ChaCha | Genre::Samba | Genre::Jive | Genre::Quickstep
    )
}

/// The feature track for a planned take: (frames, 54) row-major.
pub fn synthetic_features(plan: &Plan, frames: usize, rng: &mut Rng) -> Vec<f32> {
    let key = rng.below(12);
    let prog = PROGRESSIONS[rng.below(PROGRESSIONS.len())];
    let timbre: Vec<f32> = (0..19)
        .map(|k| rng.normal() * 30.0 / (1.0 + 0.25 * k as f32))
        .collect();
    let drum: Vec<f32> = (0..19).map(|_| rng.normal()).collect();
    let chord_colour: Vec<Vec<f32>> = (0..4)
        .map(|_| (0..19).map(|_| rng.normal() * 4.0).collect())
        .collect();
    let tau = 0.08 + 0.1 * plan.period; // drum decay (s)
    let bar = plan.beats_per_bar;
    let first = plan.beats.first().copied().unwrap_or(0.0);

    // Onset envelope and beat one-hot.
    let mut onset = vec![0.0f32; frames]; // (T,)
    let mut beat_hot = vec![0.0f32; frames]; // (T,)
    for (k, &b) in plan.beats.iter().enumerate() {
        let f = (b * FPS).round() as usize;
        if f < frames {
            beat_hot[f] = 1.0;
        }
        let amp = if k % bar == 0 { 1.0 } else { 0.65 };
        add_pulse(&mut onset, b, amp, tau);
        if syncopated(plan.genre) {
            add_pulse(&mut onset, b + 0.5 * plan.period, 0.3, 0.5 * tau);
        }
    }
    let mut out = vec![0.0f32; frames * MUSIC_DIM]; // (T, 54)
    for t in 0..frames {
        let time = t as f32 / FPS;
        let o = onset[t];
        let bar_idx = (((time - first) / plan.period).floor().max(0.0) as usize) / bar;
        let (degree, minor) = prog[bar_idx % 4];
        let root = (key + degree) % 12;
        let pcs = [
            root,
            (root + if minor { 3 } else { 4 }) % 12,
            (root + 7) % 12,
        ];
        let row = &mut out[t * MUSIC_DIM..(t + 1) * MUSIC_DIM];
        // Chroma (40..52): triad strong, the rest low, normalized to max 1.
        let mut chroma = [0.0f32; 12];
        for (pc, c) in chroma.iter_mut().enumerate() {
            *c = if pcs.contains(&pc) {
                0.8 + 0.2 * rng.unit()
            } else {
                0.05 + 0.2 * rng.unit()
            };
        }
        let mx = chroma.iter().cloned().fold(1e-6, f32::max);
        for (pc, c) in chroma.iter().enumerate() {
            row[40 + pc] = c / mx;
        }
        // MFCC (0..20): loudness in c0, genre timbre + chord colour + drum brightness.
        row[0] = -330.0 + 90.0 * o.min(2.0) + 8.0 * rng.normal();
        for k in 0..19 {
            row[1 + k] = timbre[k]
                + chord_colour[bar_idx % 4][k]
                + 12.0 * o.min(2.0) * drum[k]
                + 1.5 * rng.normal();
        }
        row[52] = 4.0 * o + 0.05 * rng.unit();
        row[53] = beat_hot[t];
    }
    // MFCC delta (20..40): central differences (one-sided at the ends).
    for t in 0..frames {
        let (a, b) = (t.saturating_sub(1), (t + 1).min(frames - 1));
        let denom = (b - a).max(1) as f32;
        for k in 0..20 {
            out[t * MUSIC_DIM + 20 + k] = (out[b * MUSIC_DIM + k] - out[a * MUSIC_DIM + k]) / denom;
        }
    }
    out
}

fn add_pulse(env: &mut [f32], at: f32, amp: f32, tau: f32) {
    // Quantized to the frame grid like the beat one-hot (round to nearest).
    let start = (at * FPS).round().max(0.0) as usize;
    for (t, v) in env.iter_mut().enumerate().skip(start) {
        let dt = (t - start) as f32 / FPS;
        if dt > 6.0 * tau {
            break;
        }
        *v += amp * (-dt / tau).exp();
    }
}
