//! duolando-runtime: the small std layer between `duolando-core` (no_std,
//! no alloc) and its hosts. Both the C library (`duolando-ffi`) and the std
//! crate (`duolando`: CLI, converter, audio, export) build on it, so that a
//! game that links the C library carries this and core only.
//!
//! - [`model_file`]: `.duo` files mapped read-only and validated;
//! - [`simd`]: run-time ISA detection (selected automatically the first
//!   time a model is opened: see [`simd::ensure_init`]);
//! - [`workers`]: the GEMM thread pool;
//! - [`engine_errors`]: engine errors in words;
//! - [`skeleton`]: rotation helpers (matrices, quaternions).
// Unsafe code is denied except at the allowed sites, each with a SAFETY
// comment: the read-only file map, the ISA switch and the GEMM thread pool
// (tests/unsafe_audit.rs).
#![deny(unsafe_code)]

pub mod engine_errors;
pub mod model_file;
pub mod simd;
pub mod skeleton;
pub mod workers;
