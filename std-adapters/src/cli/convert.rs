//! `duolando convert`: original checkpoints -> `.duo` (see `crate::convert`).

use std::path::PathBuf;

use anyhow::{bail, Context};

use crate::duo_writer::StoreAs;

/// Flags of `duolando convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The authors' YAML: Duolando's follower GPT config (e.g.
    /// configs/follower_gpt_beta0.9_final.yaml) or Bailando's
    /// (configs/actor_critic.yaml); the family is recognised from it.
    #[arg(long)]
    pub config: PathBuf,
    /// The GPT state_dict as safetensors (Duolando GPT2nt, Bailando
    /// CrossCondGPT2AC whose critic is skipped); `module.` prefix optional.
    #[arg(long)]
    pub gpt: PathBuf,
    /// The motion VQ-VAE state_dict as safetensors (Duolando SepVQVAEXM,
    /// Bailando SepVQVAER).
    #[arg(long)]
    pub vqvae: PathBuf,
    /// Duolando only: the relative-translation VQVAE state_dict as safetensors.
    #[arg(long)]
    pub transl: Option<PathBuf>,
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
    let text = std::fs::read_to_string(&args.config).with_context(|| format!("cannot read {}", args.config.display()))?;
    if crate::convert::is_bailando(&text) {
        if let Some(t) = &args.transl {
            bail!("{} is a Bailando config, which has no translation VQ-VAE: drop --transl {}", args.config.display(), t.display());
        }
        let cfg = crate::convert::parse_bailando_config(&args.config, &text)?;
        let read = |p: &std::path::Path| std::fs::read(p).with_context(|| format!("cannot read {}", p.display()));
        let (g, v) = (read(&args.gpt)?, read(&args.vqvae)?);
        let (bytes, r) = crate::convert::bailando::convert_bailando(&cfg, (&args.gpt, &g), (&args.vqvae, &v), store_as, &args.out)?;
        crate::convert::write_atomically(&args.out, &bytes)?;
        println!(
            "wrote {} (Bailando, {} tensors, {} bytes; skipped {} training-only critic tensors, {} attention masks checked)",
            args.out.display(),
            r.report.written,
            r.report.bytes,
            r.critic_skipped,
            r.report.masks_checked
        );
        return Ok(());
    }
    let transl = args.transl.as_ref().with_context(|| format!("{} is a Duolando config: --transl (the relative-translation VQ-VAE) is required", args.config.display()))?;
    let report = crate::convert::convert_files(&args.config, &args.gpt, &args.vqvae, transl, store_as, &args.out)?;
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
