//! Shared generators of arbitrary-but-structured inputs for the robustness
//! work of issue #6 (docs/ROBUSTNESS.md):
//!
//! - [`bytes`]: byte-level mutations aimed at a region (prefix, header, data);
//! - [`duo`]: `.duo` inputs, raw or as semantic mutations of a valid file
//!   (config varints, tensor-table entries), and the invariant check
//!   [`duo::check_duo`];
//! - [`convert`]: converter inputs (YAML text + three safetensors) as
//!   mutations of the tiny2 sources, and [`convert::check_convert`];
//! - [`session`]: session configurations and push/pull/reset/force
//!   sequences with hostile floats, and [`session::run_ops`], which checks
//!   the session contract against a shadow session;
//! - [`fixture`]: the tiny2 fixture model, clip and converter sources,
//!   loaded once.
//!
//! The same generators drive the cargo-fuzz targets (`fuzz/`), the property
//! tests of this crate and the soak binary (`src/bin/soak.rs`).
#![forbid(unsafe_code)]

pub mod bytes;
pub mod convert;
pub mod duo;
pub mod fixture;
pub mod floats;
pub mod session;
