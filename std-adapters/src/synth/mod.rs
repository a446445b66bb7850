//! Procedural duet synthesis: a leader dancing beat-timed ballroom-like
//! figures and a follower answering as a partner, written in the original
//! DD100 dataset layout. See docs/SYNTH.md.
//!
//! - [`generate_take`] / [`demo_take`]: one take in memory.
//! - [`dataset::write_dataset`]: `duolando synth --minutes M --seed S --out DIR`.

pub mod choreography;
pub mod dataset;
pub mod feet;
pub mod genre;
pub mod hands;
pub mod music_features;
pub mod pose;
pub mod rng;
pub mod take;

pub use genre::Genre;
pub use music_features::MUSIC_DIM;
pub use take::{generate as generate_take, DancerTrack, FigureLog, Take, TakeSpec, FPS};

/// A short deterministic take for demos and tests: `seconds` long, genre
/// picked from `seed`.
pub fn demo_take(seed: u64, seconds: f32) -> Take {
    let genre = Genre::ALL[(seed % Genre::ALL.len() as u64) as usize];
    generate_take(&TakeSpec {
        genre,
        seconds,
        bpm: None,
        beat_grid: None,
        choreo_seed: seed,
        take_seed: seed ^ 0x5eed,
    })
}
