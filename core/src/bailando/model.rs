//! `Model<'a>`: every weight of Bailando's inference path, borrowed from
//! the model bytes and validated at bind time (names from
//! [`crate::bailando::schema`]). Immutable and `Sync`.

use heapless::Vec;

use crate::bailando::config::{BailandoConfig, N_STREAMS};
use crate::bailando::schema;
use crate::kernels::Matrix;
use crate::limits::MAX_GPT_LAYERS;
use crate::nn::bind::{BindError, Binder, TensorSource};
use crate::nn::names::{name, DecoderKind};
use crate::nn::weights::{BlockW, DecoderW, LayerNormW, Linear, VqW};

/// The actor GPT (`CrossCondGPTBase` + `CrossCondGPTHead`).
#[derive(Clone, Debug)]
pub struct GptW<'a> {
    /// `tok_emb_up`, `tok_emb_down` (vocab, C).
    pub tok_emb: [Matrix<'a>; 2],
    /// `pos_emb` (3 * block_size, C): stream s uses rows s * block_size ..
    pub pos_emb: &'a [f32],
    /// `cond_emb`: Linear(n_music -> C), the music stream's rows.
    pub cond_emb: Linear<'a>,
    pub base: Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>,
    pub head: Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>,
    /// `ln_f`, before the heads.
    pub ln_f: LayerNormW<'a>,
    /// Bias-free `head_up`, `head_down` (vocab, C).
    pub heads: [Matrix<'a>; 2],
}

/// The whole inference path. Thread rule: immutable after [`Model::bind`].
#[derive(Clone, Debug)]
pub struct Model<'a> {
    pub cfg: BailandoConfig,
    pub gpt: GptW<'a>,
    /// `vqvae_up`, `vqvae_down` (position decoders only).
    pub parts: [VqW<'a>; 2],
    /// `vqvae_down.decoders_root`: the root velocity (3 channels per frame).
    pub root: DecoderW<'a>,
}

impl<'a> Model<'a> {
    /// Validates `cfg` and binds every tensor the schema lists from `src`.
    pub fn bind<S: TensorSource<'a>>(
        cfg: &BailandoConfig,
        src: &S,
    ) -> Result<Model<'a>, BindError> {
        cfg.validate().map_err(BindError::Config)?;
        let b = Binder { src };
        let g = &cfg.gpt;
        let c = g.n_embd;
        let blocks = |prefix: &str,
                      n: u32|
         -> Result<Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>, BindError> {
            let mut v = Vec::new();
            for i in 0..n {
                v.push(b.block(&name(format_args!("{prefix}.blocks.{i}"))?, c)?)
                    .map_err(|_| BindError::Capacity)?;
            }
            Ok(v)
        };
        let gpt = GptW {
            tok_emb: [
                b.matrix(schema::tok_emb_name(0)?, &[g.vocab[0], c])?,
                b.matrix(schema::tok_emb_name(1)?, &[g.vocab[1], c])?,
            ],
            pos_emb: b.get(
                name(format_args!("gpt.gpt_base.pos_emb"))?,
                &[1, g.block_size * N_STREAMS as u32, c],
            )?,
            cond_emb: b.linear("gpt.gpt_base.cond_emb", c, g.n_music, true)?,
            base: blocks("gpt.gpt_base", g.n_layer_base)?,
            head: blocks("gpt.gpt_head", g.n_layer_head)?,
            ln_f: b.ln("gpt.gpt_head.ln_f", c)?,
            heads: [
                b.matrix(schema::head_name(0)?, &[g.vocab[0], c])?,
                b.matrix(schema::head_name(1)?, &[g.vocab[1], c])?,
            ],
        };
        let up = b.vq(&schema::vq_prefix(0)?, &cfg.parts[0])?;
        let down = b.vq(&schema::vq_prefix(1)?, &cfg.parts[1])?;
        let root = b.decoder(&schema::vq_prefix(1)?, &cfg.parts[1], DecoderKind::Root)?;
        Ok(Model {
            cfg: *cfg,
            gpt,
            parts: [up, down],
            root,
        })
    }

    /// Binds every weight of a parsed `.duo` file; a file of another
    /// family is refused ([`BindError::Family`]).
    pub fn from_duo(file: &crate::format::DuoFile<'a>) -> Result<Model<'a>, BindError> {
        match file.config() {
            crate::family::FamilyConfig::Bailando(cfg) => Model::bind(cfg, file),
            other => Err(BindError::Family {
                expected: crate::family::Family::Bailando,
                found: other.family(),
            }),
        }
    }

    pub fn config(&self) -> &BailandoConfig {
        &self.cfg
    }
}

const _: () = {
    const fn assert_sync<T: Sync>() {}
    assert_sync::<Model<'static>>();
};
