//! The `duolando` command line: one file per subcommand under `cli/`.
//!
//! Adding a subcommand `foo` is two lines in the [`commands!`] list below
//! (a doc line and `Foo => foo,`) plus the file `cli/foo.rs`, which must
//! provide:
//!
//! ```ignore
//! #[derive(clap::Args, Debug)]
//! pub struct Args { /* flags */ }
//! pub fn run(args: Args) -> anyhow::Result<()>;
//! ```
//!
//! Errors bubble up as `anyhow::Error`; `main` prints the whole chain and
//! exits with status 1.

use clap::{Parser, Subcommand};

pub mod bench_tract;
pub mod budget;
pub mod generate_solo;
pub mod generate_transflower;
pub mod generate_transflower_motion;

/// Declares the subcommand modules, the [`Command`] enum and its dispatcher
/// from one list, so that a new subcommand cannot be half-registered.
macro_rules! commands {
    ($( $(#[$doc:meta])* $variant:ident => $module:ident ),* $(,)?) => {
        $( pub mod $module; )*

        /// Every `duolando` subcommand.
        #[derive(Subcommand, Debug)]
        pub enum Command {
            $( $(#[$doc])* $variant($module::Args), )*
        }

        impl Command {
            /// Runs the chosen subcommand.
            pub fn run(self) -> anyhow::Result<()> {
                match self {
                    $( Command::$variant(args) => $module::run(args), )*
                }
            }
        }
    };
}

commands! {
    /// Convert the original PyTorch checkpoints (as safetensors) and YAML to a `.duo` model.
    Convert => convert,
    /// Generate the follower for a leader clip and music (npy in, npy out).
    Generate => generate,
    /// Write a procedural duet dataset in the original DD100 layout.
    Synth => synth,
    /// Music features of an audio file (WAV/MP3/OGG/FLAC) as .npy: Duolando's (T, 54), Bailando's (T, 438) with --for bailando, Transflower's (T, 85) with --for transflower [--scaler].
    Features => features,
    /// Speed of the engine on a full-size model built from seeded random weights (f32/f16/int8).
    Bench => bench,
    /// Dance with a leader to music, or solo to music alone: a browser viewer, glTF, BVH and npy (defaults to the bundled demos: a duet, then a solo dancer).
    Dance => dance,
    /// Show a `.duo` model's config, sizes, dtypes, scratch memory and latency.
    Inspect => inspect,
    /// Agreement of streaming (S) with exact (R) mode, or of two models (e.g. int8 vs f32): tokens and joints.
    Compare => compare,
    /// Stream a leader clip through a session at 30 fps and watch the follower live in the browser (127.0.0.1).
    Live => live,
    /// The papers' motion metrics (FID_k/g/cd, Div, BAS, BED, foot skating) of generated vs real motion folders.
    Eval => eval,
}

/// `duolando <command> [flags]`.
#[derive(Parser, Debug)]
#[command(
    name = "duolando",
    version,
    about = "Real-time Duolando dance accompaniment"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Prints the kernels that run the model (`kernels: Avx512Vnni+AMX`) to
/// stderr. Commands that run a model call it after opening it: opening
/// selected the fastest kernels this CPU supports (`simd::ensure_init`),
/// or those `DUOLANDO_ISA` caps it to.
pub(crate) fn print_kernels() {
    eprintln!("kernels: {}", crate::simd::describe());
}

/// An error and its causes on one line, `a: b: c`, each cause once: a
/// cause whose text its parent's message already includes (errors that
/// print their source, as `io::Error` wrappers often do) is not repeated.
pub fn error_chain(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// Parses `std::env::args` and runs the chosen subcommand.
pub fn run() -> anyhow::Result<()> {
    Cli::parse().command.run()
}
