//! The `duolando` binary: a thin shell over [`duolando::cli`].
#![forbid(unsafe_code)]

fn main() {
    if let Err(err) = duolando::cli::run() {
        eprintln!("error: {}", duolando::cli::error_chain(&err));
        std::process::exit(1);
    }
}
