//! `duolando convert`: original checkpoints -> `.duo` (see `crate::convert`).

use std::path::PathBuf;

use crate::duo_writer::StoreAs;

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
    /// Linear weights, embeddings, heads and the VQ decoders' convs as
    /// Q8Block32 (f16 scales); encoders, codebooks and transposed convs f16,
    /// vectors f32 (docs/FORMAT.md §6).
    Int8,
    /// The same tensors as int8 in 4 bits (Q4Block32: f16 scale per block
    /// of 32, 18 bytes per block).
    Q4,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let store_as = match args.dtype {
        WeightType::F32 => StoreAs::F32,
        WeightType::F16 => StoreAs::F16,
        WeightType::Int8 => StoreAs::Q8Block32,
        WeightType::Q4 => StoreAs::Q4Block32,
    };
    let report = crate::convert::convert_files(&args.config, &args.gpt, &args.vqvae, &args.transl, store_as, &args.out)?;
    println!(
        "wrote {} ({} tensors, {} bytes; skipped {} unused source tensors, {} attention masks checked)",
        args.out.display(),
        report.written,
        report.bytes,
        report.skipped,
        report.masks_checked
    );
    Ok(())
}
