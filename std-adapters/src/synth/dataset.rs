//! dataset (next)
