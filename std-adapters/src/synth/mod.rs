//! synth (being written)
