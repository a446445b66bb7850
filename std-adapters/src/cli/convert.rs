//! `duolando convert`: original checkpoints -> `.duo` (see `crate::convert`).

use std::path::PathBuf;

use anyhow::{bail, Context};

use crate::duo_writer::StoreAs;

/// Flags of `duolando convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The authors' YAML: Duolando's follower GPT config (e.g.
    /// configs/follower_gpt_beta0.9_final.yaml), Bailando's
    /// (configs/actor_critic.yaml), or Transflower's checkpoint-directory
    /// hparams.yaml; the family is recognised from it.
    #[arg(long)]
    pub config: PathBuf,
    /// Duolando, Bailando: the GPT state_dict as safetensors (Duolando
    /// GPT2nt, Bailando CrossCondGPT2AC whose critic is skipped); `module.`
    /// prefix optional.
    #[arg(long)]
    pub gpt: Option<PathBuf>,
    /// Duolando, Bailando: the motion VQ-VAE state_dict as safetensors
    /// (Duolando SepVQVAEXM, Bailando SepVQVAER).
    #[arg(long)]
    pub vqvae: Option<PathBuf>,
    /// Duolando only: the relative-translation VQVAE state_dict as safetensors.
    #[arg(long)]
    pub transl: Option<PathBuf>,
    /// Transflower only: the Lightning checkpoint's state_dict as
    /// safetensors (tools/transflower_ckpt_to_safetensors.py).
    #[arg(long)]
    pub weights: Option<PathBuf>,
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
    let cfg_path = args.config.display();
    let read = |p: &std::path::Path| std::fs::read(p).with_context(|| format!("cannot read {}", p.display()));
    if crate::convert::transflower::is_transflower(&text) {
        for (flag, given) in [("--gpt", &args.gpt), ("--vqvae", &args.vqvae), ("--transl", &args.transl)] {
            if let Some(p) = given {
                bail!("{cfg_path} is a Transflower hparams.yaml: its weights are one state dict, given with --weights; drop {flag} {}", p.display());
            }
        }
        let weights = args.weights.as_ref().with_context(|| format!("{cfg_path} is a Transflower hparams.yaml: --weights (the checkpoint's state_dict as safetensors, tools/transflower_ckpt_to_safetensors.py) is required"))?;
        let cfg = crate::convert::transflower::parse_transflower_config(&args.config, &text)?;
        let w = read(weights)?;
        let (bytes, r) = crate::convert::transflower::convert_transflower(&cfg, (weights, &w), store_as, &args.out)?;
        crate::convert::write_atomically(&args.out, &bytes)?;
        println!(
            "wrote {} (Transflower, {} tensors, {} bytes; skipped {} unused buffers: {} is_initialized, {} bounds)",
            args.out.display(),
            r.report.written,
            r.report.bytes,
            r.report.skipped,
            r.is_initialized_skipped,
            r.bounds_skipped
        );
        return Ok(());
    }
    if let Some(w) = &args.weights {
        bail!("--weights is for Transflower checkpoints; {cfg_path} is a {} config: give --gpt and --vqvae{} instead of --weights {}", if crate::convert::is_bailando(&text) { "Bailando" } else { "Duolando" }, if crate::convert::is_bailando(&text) { "" } else { " and --transl" }, w.display());
    }
    let family = if crate::convert::is_bailando(&text) { "Bailando" } else { "Duolando" };
    let gpt = args.gpt.as_ref().with_context(|| format!("{cfg_path} is a {family} config: --gpt (the GPT state_dict as safetensors) is required"))?;
    let vqvae = args.vqvae.as_ref().with_context(|| format!("{cfg_path} is a {family} config: --vqvae (the motion VQ-VAE state_dict as safetensors) is required"))?;
    if crate::convert::is_bailando(&text) {
        if let Some(t) = &args.transl {
            bail!("{cfg_path} is a Bailando config, which has no translation VQ-VAE: drop --transl {}", t.display());
        }
        let cfg = crate::convert::parse_bailando_config(&args.config, &text)?;
        let (g, v) = (read(gpt)?, read(vqvae)?);
        let (bytes, r) = crate::convert::bailando::convert_bailando(&cfg, (gpt, &g), (vqvae, &v), store_as, &args.out)?;
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
    let transl = args.transl.as_ref().with_context(|| format!("{cfg_path} is a Duolando config: --transl (the relative-translation VQ-VAE) is required"))?;
    let report = crate::convert::convert_files(&args.config, gpt, vqvae, transl, store_as, &args.out)?;
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
