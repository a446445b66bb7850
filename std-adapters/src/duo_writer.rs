//! duo_writer (being written)
