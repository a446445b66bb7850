//! `duolando convert`: original checkpoints -> `.duo` (see `crate::convert`).

use std::path::PathBuf;

/// Flags of `duolando convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The follower GPT YAML (e.g. configs/follower_gpt_beta0.9_final.yaml).
    #[arg(long)]
    pub config: PathBuf,
    /// GPT2nt state_dict as safetensors (`module.` prefix optional).
    #[arg(long)]
    pub gpt: PathBuf,
    /// Motion SepVQVAEXM state_dict as safetensors.
    #[arg(long)]
    pub vqvae: PathBuf,
    /// Relative-translation VQVAE state_dict as safetensors.
    #[arg(long)]
    pub transl: PathBuf,
    /// Weight type stored in the `.duo`.
    #[arg(long, value_enum, default_value_t = WeightType::F32)]
    pub dtype: WeightType,
    /// Output `.duo` path.
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
}

/// Weight types the converter can write.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightType {
    F32,
    F16,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::bail!(
        "convert: not wired yet (args: {:?}); the converter lands shortly",
        args
    )
}
