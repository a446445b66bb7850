//! duolando: the std side of the Duolando engine — model files, the
//! converter from the original checkpoints, audio features, motion I/O and
//! export, the viewer, and the `duolando` CLI.
// Unsafe code is denied except at four allowed sites, each with a SAFETY
// comment: the two read-only file maps, the ISA switch and the GEMM thread
// pool (tests/unsafe_audit.rs).
#![deny(unsafe_code)]

// The small std layer shared with the C library (duolando-runtime),
// re-exported under its old paths.
pub use duolando_runtime::{engine_errors, model_file, simd, workers};

pub mod agreement;
pub mod audio;
pub mod cli;
pub mod convert;
pub mod duo_writer;
pub mod eval;
pub mod export;
pub mod kernel_bench;
pub mod live;
pub mod music;
pub mod npy;
pub mod skeleton;
pub mod streaming;
pub mod synth;
pub mod transflower_motion;
pub mod viewer;
