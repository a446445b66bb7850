//! `Model<'a>`: every weight of the inference path, bound once as borrowed
//! views of the model bytes (mmap, `include_bytes!`, an engine asset) and
//! validated at bind time (names from [`crate::duolando::schema`], shapes, dtypes,
//! alignment). Immutable and `Sync`: many sessions share one model.
//!
//! Dtypes: weight matrices (Linear, Conv1d/ConvTranspose1d, token
//! embeddings, codebooks, heads) bind as [`Matrix`] of any stored type
//! (F32, F16, Q8Block32, Q4Block32 and their x8 groups; one generic kernel
//! path, `kernels::weights`); a ConvTranspose1d weight in either stored
//! order ([`crate::kernels::ConvTWeight`]: PyTorch's, or the GEMM order of blocked files);
//! biases, LayerNorm parameters and `pos_emb` are added to activations
//! as they are and must be F32 (they are <1% of the bytes).
//!
//! Structure mirrors the original modules: [`LatW`] (`MusicTrans`),
//! [`BlockW`] (`MusicBlock` / `Block`), [`GptW`] (`GPT2nt`), [`VqW`]
//! (one part of `SepVQVAEXM`, or the translation `VQVAE`).

use heapless::Vec;

use crate::duolando::config::{LatConfig, ModelConfig, Part};
use crate::duolando::schema;
use crate::kernels::Matrix;
use crate::limits::{MAX_GPT_LAYERS, MAX_LAT_LAYERS};
use crate::nn::bind::{BindError, Binder, TensorSource};
use crate::nn::names::name;
use crate::nn::weights::{BlockW, Linear, VqW};

/// A Look-Ahead Transformer (`MusicTrans`).
#[derive(Clone, Debug)]
pub struct LatW<'a> {
    pub cfg: LatConfig,
    pub cond_emb: Linear<'a>,
    pub blocks: Vec<BlockW<'a>, { MAX_LAT_LAYERS as usize }>,
    /// (C, C * downsample_rate).
    pub downsample: Linear<'a>,
}

/// The follower GPT (`GPT2nt`).
#[derive(Clone, Debug)]
pub struct GptW<'a> {
    pub music: LatW<'a>,
    /// Leader LATs in part order up, down, lhand, rhand.
    pub leaders: [LatW<'a>; 4],
    /// `tok_emb_{up,down,lhand,rhand,transl}` (vocab, C).
    pub tok_emb: [Matrix<'a>; 5],
    /// `gpt_base.pos_emb` (n_streams * block_size, C).
    pub pos_emb: &'a [f32],
    pub base: Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>,
    pub head: Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>,
    /// Bias-free heads `head_{up,down,lhand,rhand,transl}` (vocab, C).
    pub heads: [Matrix<'a>; 5],
}

/// The whole inference path. Thread rule: immutable after [`Model::bind`];
/// `&Model` may be shared by any number of threads (`Model: Sync`).
#[derive(Clone, Debug)]
pub struct Model<'a> {
    pub cfg: ModelConfig,
    pub gpt: GptW<'a>,
    /// Part VQ-VAEs in order up, down, lhand, rhand.
    pub parts: [VqW<'a>; 4],
    pub transl: VqW<'a>,
}

impl<'a> Model<'a> {
    /// Validates `cfg` and binds every tensor the schema lists from `src`.
    pub fn bind<S: TensorSource<'a>>(cfg: &ModelConfig, src: &S) -> Result<Model<'a>, BindError> {
        cfg.validate().map_err(BindError::Config)?;
        let b = Binder { src };
        let gpt = gpt(&b, cfg)?;
        let parts = [
            b.vq(&schema::vq_prefix(Some(Part::Up))?, &cfg.parts[0])?,
            b.vq(&schema::vq_prefix(Some(Part::Down))?, &cfg.parts[1])?,
            b.vq(&schema::vq_prefix(Some(Part::LHand))?, &cfg.parts[2])?,
            b.vq(&schema::vq_prefix(Some(Part::RHand))?, &cfg.parts[3])?,
        ];
        let transl = b.vq(&schema::vq_prefix(None)?, &cfg.transl)?;
        Ok(Model {
            cfg: *cfg,
            gpt,
            parts,
            transl,
        })
    }

    pub fn config(&self) -> &ModelConfig {
        &self.cfg
    }
}

const _: () = {
    const fn assert_sync<T: Sync>() {}
    assert_sync::<Model<'static>>();
};

impl<'a> Model<'a> {
    /// Binds every weight of a parsed `.duo` file (its config was validated
    /// by the decoder and is validated again here).
    /// A file of another family is refused ([`BindError::Family`]).
    pub fn from_duo(file: &crate::format::DuoFile<'a>) -> Result<Model<'a>, BindError> {
        match file.config() {
            crate::family::FamilyConfig::Duolando(cfg) => Model::bind(cfg, file),
            other => Err(BindError::Family {
                expected: crate::family::Family::Duolando,
                found: other.family(),
            }),
        }
    }
}

impl<'a> Model<'a> {
    /// The VQ-VAE of a body part or of the translation.
    pub fn vq(&self, which: crate::limits::VqWhich) -> &VqW<'a> {
        match which {
            crate::limits::VqWhich::Part(p) => &self.parts[p as usize],
            crate::limits::VqWhich::Transl => &self.transl,
        }
    }
}

fn lat<'a, S: TensorSource<'a>>(
    b: &Binder<'_, S>,
    which: Option<Part>,
    lat: &LatConfig,
    c: u32,
) -> Result<LatW<'a>, BindError> {
    let p = schema::lat_prefix(which)?;
    let mut blocks = Vec::new();
    for i in 0..lat.n_layer {
        let b = b.block(&name(format_args!("{p}.blocks.{i}"))?, c)?;
        blocks.push(b).map_err(|_| BindError::Capacity)?;
    }
    Ok(LatW {
        cfg: *lat,
        cond_emb: b.linear(&name(format_args!("{p}.cond_emb"))?, c, lat.n_in, true)?,
        blocks,
        downsample: b.linear(
            &name(format_args!("{p}.downsample"))?,
            c,
            c * lat.downsample_rate,
            true,
        )?,
    })
}

fn gpt<'a, S: TensorSource<'a>>(
    b: &Binder<'_, S>,
    cfg: &ModelConfig,
) -> Result<GptW<'a>, BindError> {
    let g = &cfg.gpt;
    let c = g.n_embd;
    let music = lat(b, None, &g.music, c)?;
    let leaders = [
        lat(b, Some(Part::Up), &g.leader, c)?,
        lat(b, Some(Part::Down), &g.leader, c)?,
        lat(b, Some(Part::LHand), &g.leader, c)?,
        lat(b, Some(Part::RHand), &g.leader, c)?,
    ];
    let mut tok = [None; 5];
    for (s, t) in tok.iter_mut().enumerate() {
        *t = Some(b.matrix(schema::tok_emb_name(s)?, &[g.vocab[s], c])?);
    }
    let pos_emb = b.get(
        name(format_args!("gpt.gpt_base.pos_emb"))?,
        &[1, g.block_size * g.n_streams, c],
    )?;
    let mut base = Vec::new();
    for i in 0..g.n_layer_base {
        let b = b.block(&name(format_args!("gpt.gpt_base.blocks.{i}"))?, c)?;
        base.push(b).map_err(|_| BindError::Capacity)?;
    }
    let mut head = Vec::new();
    for i in 0..g.n_layer_head {
        let b = b.block(&name(format_args!("gpt.gpt_head.blocks.{i}"))?, c)?;
        head.push(b).map_err(|_| BindError::Capacity)?;
    }
    // Quirk: head_lhand has vocab_up rows, head_rhand vocab_down rows.
    let head_rows = [g.vocab[0], g.vocab[1], g.vocab[0], g.vocab[1], g.vocab[4]];
    let mut heads = [None; 5];
    for (s, h) in heads.iter_mut().enumerate() {
        *h = Some(b.matrix(schema::head_name(s)?, &[head_rows[s], c])?);
    }
    let unwrap5 = |a: [Option<Matrix<'a>>; 5]| -> Result<[Matrix<'a>; 5], BindError> {
        let mut out = [a[0].ok_or(BindError::Capacity)?; 5];
        for (o, m) in out.iter_mut().zip(a) {
            *o = m.ok_or(BindError::Capacity)?;
        }
        Ok(out)
    };
    Ok(GptW {
        music,
        leaders,
        tok_emb: unwrap5(tok)?,
        pos_emb,
        base,
        head,
        heads: unwrap5(heads)?,
    })
}
