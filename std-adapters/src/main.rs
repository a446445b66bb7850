//! The `duolando` binary: a thin shell over [`duolando::cli`].

fn main() {
    if let Err(err) = duolando::cli::run() {
        eprintln!("error: {err:#}");
        std::process::exit(1);
    }
}
