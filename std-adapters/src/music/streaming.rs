//! Streaming music features (being written).
pub struct Streaming;
