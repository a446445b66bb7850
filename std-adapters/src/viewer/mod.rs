//! viewer (being written)
