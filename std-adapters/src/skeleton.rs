//! skeleton (being written)
