//! audio (being written)
