//! music (being written)
