//! Speed of the offline music features on a 3-minute signal (clicks at
//! 118 BPM + a chord progression + light noise, like
//! `tools/music_goldens.py --speed`). Prints the wall time per run.
//!
//! `cargo bench -p duolando --bench music_speed`

use std::time::Instant;

use duolando::music::{Extractor, SAMPLE_RATE};

fn signal(seconds: usize) -> Vec<f32> {
    let sr = SAMPLE_RATE as f64;
    let n = seconds * SAMPLE_RATE as usize;
    let chords = [
        [261.63, 329.63, 392.00],
        [196.00, 246.94, 293.66],
        [220.00, 261.63, 329.63],
        [174.61, 220.00, 261.63],
    ];
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut y = vec![0.0f32; n];
    for (i, v) in y.iter_mut().enumerate() {
        let t = i as f64 / sr;
        let c = &chords[(t / 1.5) as usize % 4];
        let mut s: f64 = c
            .iter()
            .map(|f| 0.15 * (2.0 * std::f64::consts::PI * f * t).sin())
            .sum();
        let beat = 60.0 / 118.0;
        let since = (t - 0.25).rem_euclid(beat);
        if since < 0.02 && t >= 0.25 {
            s += 0.8 * (2.0 * std::f64::consts::PI * 1500.0 * since).sin() * (-since * 200.0).exp();
        }
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        s += 0.05 * ((state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * 1.7;
        *v = s as f32;
    }
    y
}

fn main() {
    let y = signal(180);
    let ex = Extractor::new();
    ex.features(&y[..5 * SAMPLE_RATE as usize])
        .expect("warm-up");
    let mut best = f64::INFINITY;
    for run in 0..3 {
        let t0 = Instant::now();
        let f = ex.features(&y).expect("features");
        let dt = t0.elapsed().as_secs_f64();
        best = best.min(dt);
        println!(
            "run {run}: 180 s signal -> ({}, 54) in {dt:.3} s (tempo {:.1})",
            f.frames, f.tempo_bpm
        );
    }
    println!(
        "duolando music features: best {best:.3} s for 180 s of audio ({:.0}x real time)",
        180.0 / best
    );
}
