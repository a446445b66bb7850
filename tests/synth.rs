//! Skeleton maths and procedural duet synthesis: FK/IK round trips,
//! rotation conversions, nearest-rotation properties, synth determinism
//! and plausibility.

#[path = "synth/dataset.rs"]
mod dataset;
#[path = "synth/plausibility.rs"]
mod plausibility;
#[path = "synth/skeleton.rs"]
mod skeleton;
