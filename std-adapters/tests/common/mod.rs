//! Helpers shared by the CLI test crates (each says `mod common;`).
#![allow(dead_code)] // each test crate uses its own subset

use std::process::{Command, Output};

/// `duolando bench ARGS` with the detected ISA (`DUOLANDO_ISA` removed).
pub fn bench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_duolando"))
        .arg("bench")
        .args(args)
        .env_remove("DUOLANDO_ISA")
        .output()
        .unwrap()
}
