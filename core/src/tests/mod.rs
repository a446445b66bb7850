//! Unit tests of the core (kernels against naive references, motion
//! normalisation round trips, schema and config validation, arena
//! accounting). Integration tests against ONNX/tract live in `tests/`.

mod arena;
mod engine;
pub(crate) mod kernels;
mod motion_sampler;
mod rings;
mod schema_config;
mod simd;
