//! The original follower-GPT YAML -> [`ModelConfig`].
//!
//! Keys read (all under the structure of configs/follower_gpt_beta0.9_final.yaml):
//! - `structure.{up_half,down_half,lhand,rhand}`: SepVQVAEXM parts
//!   (`pos_channel`, `rot_channel`, `width`, `depth`, `m_conv`,
//!   `dilation_growth_rate`, `levels`, `downs_t`, `strides_t`, `emb_width`,
//!   `l_bins`, `hvqvae_multipliers`, `dilation_cycle`,
//!   `vqvae_reverse_decoder_dilation`);
//! - `structure_transl_vqvae`: the translation VQVAE (`input_dim` channels);
//! - `structure_generate`: GPT2nt (`n_embd`, `block_size`, `look_forward`,
//!   `vocab_size_*`, `base`, `head`, `music_trans`, `leader_*_trans`);
//! - `music_motion_rate`.
//!
//! Values the engine has a single field for but the YAML repeats (per-module
//! `n_embd`, `block_size`, `look_forward`, the four leader LATs) must agree;
//! a disagreement is an error naming both keys.

use std::path::{Path, PathBuf};

use duolando_core::bailando::config::{
    BailandoConfig, GptConfig as BGptConfig, DOWN_JOINTS, UP_JOINTS,
};
use duolando_core::duolando::config::{GptConfig, LatConfig, ModelConfig};
use duolando_core::nn::vq_config::VqConfig;

use super::error::ConvertError;
use super::yaml::Yaml;

/// Reads and maps the follower-GPT YAML at `path`.
pub fn load_config(path: &Path) -> Result<ModelConfig, ConvertError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConvertError::Io {
        path: path.into(),
        source,
    })?;
    parse_config(path, &text)
}

/// Maps YAML `text`; `path` only labels errors.
pub fn parse_config(path: &Path, text: &str) -> Result<ModelConfig, ConvertError> {
    let root = Yaml::parse(text).map_err(|source| ConvertError::Yaml {
        path: path.into(),
        source,
    })?;
    let cfg = Keys {
        path: path.to_path_buf(),
    }
    .model(&root)?;
    cfg.validate().map_err(|error| ConvertError::Config {
        path: path.into(),
        error,
        detail: format!("{error:?}"),
    })?;
    Ok(cfg)
}

/// Which family a YAML describes: Bailando's `actor_critic*.yaml` names
/// `SepVQVAER` and `CrossCondGPT2AC`; everything else is read as Duolando's.
pub fn is_bailando(text: &str) -> bool {
    match Yaml::parse(text) {
        Ok(root) => {
            let name = |k: &str| root.get(k).and_then(|s| s.get("name")).cloned();
            name("structure") == Some(Yaml::Str("SepVQVAER".into()))
                || name("structure_generate") == Some(Yaml::Str("CrossCondGPT2AC".into()))
        }
        Err(_) => false,
    }
}

/// Maps Bailando's YAML (`configs/actor_critic.yaml` structure: `structure`
/// = SepVQVAER up_half/down_half, `structure_generate` = CrossCondGPT2AC
/// base/head; `critic_net` is training-only and not read); `path` only
/// labels errors.
pub fn parse_bailando_config(path: &Path, text: &str) -> Result<BailandoConfig, ConvertError> {
    let root = Yaml::parse(text).map_err(|source| ConvertError::Yaml {
        path: path.into(),
        source,
    })?;
    let keys = Keys {
        path: path.to_path_buf(),
    };
    let cfg = keys.bailando(&root)?;
    cfg.validate().map_err(|error| ConvertError::Config {
        path: path.into(),
        error,
        detail: format!("{error:?}"),
    })?;
    Ok(cfg)
}

/// Typed lookups that name the dotted key path in errors.
struct Keys {
    path: PathBuf,
}

impl Keys {
    fn err(&self, key: &str, problem: impl Into<String>) -> ConvertError {
        ConvertError::ConfigKey {
            path: self.path.clone(),
            key: key.to_string(),
            problem: problem.into(),
        }
    }

    fn node<'y>(&self, y: &'y Yaml, key: &str) -> Result<&'y Yaml, ConvertError> {
        let mut cur = y;
        for part in key.split('.') {
            cur = cur.get(part).ok_or_else(|| self.err(key, "missing"))?;
        }
        Ok(cur)
    }

    fn uint(&self, y: &Yaml, key: &str) -> Result<u32, ConvertError> {
        match self.node(y, key)? {
            Yaml::Int(i) => u32::try_from(*i)
                .map_err(|_| self.err(key, format!("{i} is not in 0..=4294967295"))),
            other => Err(self.err(key, format!("expected an integer, found {}", other.kind()))),
        }
    }

    fn float(&self, y: &Yaml, key: &str) -> Result<f64, ConvertError> {
        match self.node(y, key)? {
            Yaml::Int(i) => Ok(*i as f64),
            Yaml::Float(f) => Ok(*f),
            other => Err(self.err(key, format!("expected a number, found {}", other.kind()))),
        }
    }

    /// A one-element integer list (`downs_t: [2,]`), as the single-level
    /// original uses.
    fn single(&self, y: &Yaml, key: &str) -> Result<u32, ConvertError> {
        match self.node(y, key)? {
            Yaml::Seq(items) if items.len() == 1 => match &items[0] {
                Yaml::Int(i) => {
                    u32::try_from(*i).map_err(|_| self.err(key, format!("{i} is out of range")))
                }
                other => Err(self.err(
                    key,
                    format!("expected an integer item, found {}", other.kind()),
                )),
            },
            Yaml::Seq(items) => Err(self.err(
                key,
                format!("expected one entry (levels = 1), found {}", items.len()),
            )),
            other => Err(self.err(key, format!("expected a list, found {}", other.kind()))),
        }
    }

    /// `a` and `b` must hold the same integer.
    fn same(&self, y: &Yaml, a: &str, b: &str) -> Result<u32, ConvertError> {
        let (va, vb) = (self.uint(y, a)?, self.uint(y, b)?);
        if va != vb {
            return Err(self.err(
                b,
                format!("is {vb} but `{a}` is {va}; the engine has one value for both"),
            ));
        }
        Ok(va)
    }

    /// Like [`Keys::same`] but `b` may be absent.
    fn same_if_present(&self, y: &Yaml, a: &str, b: &str) -> Result<(), ConvertError> {
        if self.node(y, b).is_ok() {
            self.same(y, a, b)?;
        }
        Ok(())
    }

    fn model(&self, root: &Yaml) -> Result<ModelConfig, ConvertError> {
        let parts = [
            self.vq_keys(
                root,
                "structure.up_half",
                "pos_channel",
                Some("rot_channel"),
            )?,
            self.vq_keys(
                root,
                "structure.down_half",
                "pos_channel",
                Some("rot_channel"),
            )?,
            self.vq_keys(root, "structure.lhand", "pos_channel", Some("rot_channel"))?,
            self.vq_keys(root, "structure.rhand", "pos_channel", Some("rot_channel"))?,
        ];
        let transl = self.vq_keys(root, "structure_transl_vqvae", "input_dim", None)?;
        let gpt = self.gpt(root)?;
        let music_motion_rate = self.uint(root, "music_motion_rate")?;
        Ok(ModelConfig {
            gpt,
            parts,
            transl,
            music_motion_rate,
        })
    }

    /// One VQ-VAE section at `sec` (a dotted path) whose channel counts
    /// are the keys `in_key` and `rot_key`.
    fn vq_keys(
        &self,
        root: &Yaml,
        sec: &str,
        in_key: &str,
        rot_key: Option<&str>,
    ) -> Result<VqConfig, ConvertError> {
        let k = |name: &str| format!("{sec}.{name}");
        let in_channels = self.uint(root, &k(in_key))?;
        let rot_channels = match rot_key {
            Some(r) => self.uint(root, &k(r))?,
            None => 0,
        };
        self.vq(root, sec, in_channels, rot_channels)
    }

    /// One VQ-VAE section at `sec` (a dotted path) with the given channels.
    fn vq(
        &self,
        root: &Yaml,
        sec: &str,
        in_channels: u32,
        rot_channels: u32,
    ) -> Result<VqConfig, ConvertError> {
        let k = |name: &str| format!("{sec}.{name}");
        let levels = self.uint(root, &k("levels"))?;
        if levels != 1 {
            return Err(self.err(
                &k("levels"),
                format!("only 1 level is supported (the published models), found {levels}"),
            ));
        }
        let mult = match self.node(root, &k("hvqvae_multipliers")) {
            Ok(_) => self.single(root, &k("hvqvae_multipliers"))?,
            Err(_) => 1,
        };
        if let Ok(v) = self.node(root, &k("dilation_cycle")) {
            if *v != Yaml::Null {
                return Err(self.err(
                    &k("dilation_cycle"),
                    "must be absent or null (dilation cycles are not supported)",
                ));
            }
        }
        if let Ok(v) = self.node(root, &k("vqvae_reverse_decoder_dilation")) {
            if *v != Yaml::Bool(true) {
                return Err(self.err(
                    &k("vqvae_reverse_decoder_dilation"),
                    "must be true (the engine's decoders reverse the dilations)",
                ));
            }
        }
        let width = self.uint(root, &k("width"))?;
        let depth = self.uint(root, &k("depth"))?;
        let scaled = |key: &str, v: u32| {
            v.checked_mul(mult).ok_or_else(|| {
                self.err(
                    &k(key),
                    format!("{v} x hvqvae_multipliers {mult} overflows"),
                )
            })
        };
        let (m_conv_num, m_conv_den) = ratio(self.float(root, &k("m_conv"))?).ok_or_else(|| {
            self.err(
                &k("m_conv"),
                "must be a positive ratio with denominator <= 64 (e.g. 1.0, 0.5, 0.75)",
            )
        })?;
        Ok(VqConfig {
            in_channels,
            rot_channels,
            width: scaled("width", width)?,
            depth: scaled("depth", depth)?,
            dilation_growth_rate: self.uint(root, &k("dilation_growth_rate"))?,
            down_t: self.single(root, &k("downs_t"))?,
            stride_t: self.single(root, &k("strides_t"))?,
            emb_width: self.uint(root, &k("emb_width"))?,
            l_bins: self.uint(root, &k("l_bins"))?,
            m_conv_num,
            m_conv_den,
        })
    }

    fn bailando(&self, root: &Yaml) -> Result<BailandoConfig, ConvertError> {
        let part = |sec: &str, joints: usize| -> Result<VqConfig, ConvertError> {
            let jc = self.uint(root, &format!("{sec}.joint_channel"))?;
            if jc != 3 {
                return Err(self.err(
                    &format!("{sec}.joint_channel"),
                    format!("must be 3 (joint positions), found {jc}"),
                ));
            }
            self.vq(root, sec, (joints * 3) as u32, 0)
        };
        let parts = [
            part("structure.up_half", UP_JOINTS.len())?,
            part("structure.down_half", DOWN_JOINTS.len())?,
        ];
        let g = |name: &str| format!("structure_generate.{name}");
        let n_embd = self.same(root, &g("base.n_embd"), &g("head.n_embd"))?;
        self.same(root, &g("base.n_embd"), &g("base.n_music_emb"))?;
        let block_size = self.same(root, &g("block_size"), &g("base.block_size"))?;
        self.same(root, &g("block_size"), &g("head.block_size"))?;
        let n_head = self.same(root, &g("base.n_head"), &g("head.n_head"))?;
        let vocab = [
            self.same(root, &g("base.vocab_size_up"), &g("head.vocab_size_up"))?,
            self.same(root, &g("base.vocab_size_down"), &g("head.vocab_size_down"))?,
        ];
        let gpt = BGptConfig {
            n_embd,
            n_head,
            n_layer_base: self.uint(root, &g("base.n_layer"))?,
            n_layer_head: self.uint(root, &g("head.n_layer"))?,
            block_size,
            vocab,
            n_music: self.uint(root, &g("base.n_music"))?,
        };
        Ok(BailandoConfig { gpt, parts })
    }

    fn lat(&self, root: &Yaml, sec: &str) -> Result<LatConfig, ConvertError> {
        let g = "structure_generate";
        let k = |name: &str| format!("{g}.{sec}.{name}");
        self.same(root, &format!("{g}.n_embd"), &k("n_embd"))?;
        self.same(root, &format!("{g}.block_size"), &k("block_size"))?;
        self.same(root, &format!("{g}.look_forward"), &k("look_forward"))?;
        Ok(LatConfig {
            n_in: self.uint(root, &k("n_music"))?,
            n_layer: self.uint(root, &k("n_layer"))?,
            n_head: self.uint(root, &k("n_head"))?,
            downsample_rate: self.uint(root, &k("downsample_rate"))?,
        })
    }

    fn gpt(&self, root: &Yaml) -> Result<GptConfig, ConvertError> {
        let g = |name: &str| format!("structure_generate.{name}");
        for sec in ["base", "head"] {
            self.same(root, &g("n_embd"), &g(&format!("{sec}.n_embd")))?;
            self.same(root, &g("block_size"), &g(&format!("{sec}.block_size")))?;
            self.same(root, &g("look_forward"), &g(&format!("{sec}.look_forward")))?;
        }
        let n_head = self.same(root, &g("base.n_head"), &g("head.n_head"))?;
        // GPTHead sizes head_up/head_lhand by head.vocab_size_up and
        // head_down/head_rhand by head.vocab_size_down (the original's quirk).
        for (top, head) in [
            ("vocab_size_up", "head.vocab_size_up"),
            ("vocab_size_down", "head.vocab_size_down"),
            ("vocab_size_transl", "head.vocab_size_transl"),
        ] {
            self.same_if_present(root, &g(top), &g(head))?;
        }
        let music = self.lat(root, "music_trans")?;
        let leader = self.lat(root, "leader_up_trans")?;
        for part in ["down", "lhand", "rhand"] {
            let sec = format!("leader_{part}_trans");
            let other = self.lat(root, &sec)?;
            if other != leader {
                return Err(self.err(
                    &g(&sec),
                    format!("differs from `leader_up_trans` ({other:?} vs {leader:?}); the engine shares one leader-LAT config"),
                ));
            }
        }
        Ok(GptConfig {
            n_embd: self.uint(root, &g("n_embd"))?,
            n_head,
            n_layer_base: self.uint(root, &g("base.n_layer"))?,
            n_layer_head: self.uint(root, &g("head.n_layer"))?,
            block_size: self.uint(root, &g("block_size"))?,
            look_forward: self.uint(root, &g("look_forward"))?,
            vocab: [
                self.uint(root, &g("vocab_size_up"))?,
                self.uint(root, &g("vocab_size_down"))?,
                self.uint(root, &g("vocab_size_lhand"))?,
                self.uint(root, &g("vocab_size_rhand"))?,
                self.uint(root, &g("vocab_size_transl"))?,
            ],
            music,
            leader,
            n_streams: 10,
            final_ln: false,
        })
    }
}

/// `m` as num/den with den <= 64, when exact to 1e-9 (`m_conv: 1.0` -> 1/1).
fn ratio(m: f64) -> Option<(u32, u32)> {
    if !(m.is_finite() && m > 0.0 && m < 1e6) {
        return None;
    }
    (1u32..=64).find_map(|den| {
        let num = (m * den as f64).round();
        ((num / den as f64 - m).abs() < 1e-9 && num >= 1.0).then_some((num as u32, den))
    })
}

#[cfg(test)]
mod tests {
    use super::ratio;

    #[test]
    fn ratios() {
        assert_eq!(ratio(1.0), Some((1, 1)));
        assert_eq!(ratio(0.5), Some((1, 2)));
        assert_eq!(ratio(0.75), Some((3, 4)));
        assert_eq!(ratio(0.0), None);
        assert_eq!(ratio(f64::NAN), None);
        assert_eq!(ratio(0.123456789), None);
    }
}
