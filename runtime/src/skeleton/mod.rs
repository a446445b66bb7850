//! The rotation helpers the C library needs (3-vectors, row-major 3x3
//! matrices, quaternions, nearest rotation). The rest of the skeleton
//! (joint tree, rest pose, FK/IK, retargeting) lives in the std crate
//! (`duolando::skeleton`), which re-exports these two modules.

pub mod math;
pub mod rotation;
