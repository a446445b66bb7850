//! `Model<'a>`: every weight of Transflower's inference path, borrowed
//! from the model bytes and checked at bind time (names from
//! [`crate::transflower::schema`]). Immutable and `Sync`.
//!
//! Besides shapes and dtypes, bind checks the values the flow divides by
//! or inverts ([`ValueProblem`]): the 1x1 convs' `p` must be a
//! permutation and `sign_s` +-1 (so `U` is invertible), norm scales and
//! `weight_v` non-zero, running variances non-negative.

use heapless::Vec;

use crate::kernels::Matrix;
use crate::nn::bind::{BindError, Binder, TensorSource};
use crate::nn::encoder_layer::{bind_encoder_layer, EncoderLayerW};
use crate::nn::names::{name, SchemaError, TensorName};
use crate::nn::weights::Linear;
use crate::transflower::config::{
    ConfigError, NormLayer, TransflowerConfig, INPUT_LAYERS, MAX_COUPLING_LAYERS, MAX_FLOW_STEPS,
    MAX_INPUTS, MAX_LAYERS,
};
use crate::transflower::schema;

/// The authors' `BasicTransformerModel` (models/transformer.py), up to `N`
/// layers: [embedding] -> `encoder1` -> [+ pe] -> post-LN layers [with the
/// `pos_emb` score bias] -> `decoder`.
#[derive(Clone, Debug)]
pub struct TransformerW<'a, const N: usize> {
    /// `encoder` (tokens, din): a discrete input's embedding table.
    pub embedding: Option<Matrix<'a>>,
    /// `encoder1` (d, din).
    pub encoder1: Linear<'a>,
    /// `pos_encoder.pe` (rows, 1, d) viewed (rows, d): added after `encoder1`.
    pub pe: Option<&'a [f32]>,
    /// `pos_emb` (L, L): added to every head's scores in every layer.
    pub bias: Option<&'a [f32]>,
    pub layers: Vec<EncoderLayerW<'a>, N>,
    /// `decoder` (dout, d).
    pub decoder: Linear<'a>,
    pub din: usize,
    pub d: usize,
    pub dout: usize,
    pub n_head: usize,
}

/// An input transformer (`net_input_<mod>`, 2 layers).
pub type InputNetW<'a> = TransformerW<'a, { INPUT_LAYERS as usize }>;
/// The cross-modal transformer (`net_output_<out>`).
pub type CrossModalW<'a> = TransformerW<'a, { MAX_LAYERS as usize }>;
/// A coupling's transformer (`nn.transformer`).
pub type CouplingNetW<'a> = TransformerW<'a, { MAX_COUPLING_LAYERS as usize }>;

/// The norm module of a flow step, per channel (C) each.
#[derive(Clone, Copy, Debug)]
pub enum NormW<'a> {
    None,
    /// The authors' `BatchNorm` in eval: `gamma`, `beta`, `running_mean`, `running_var`.
    BatchNorm {
        gamma: &'a [f32],
        beta: &'a [f32],
        mean: &'a [f32],
        var: &'a [f32],
    },
    /// `ActNorm`: `mean`, `inv_std`.
    ActNorm {
        mean: &'a [f32],
        inv_std: &'a [f32],
    },
}

/// `InvertibleConv1x1` in LU form: W = p (L U), L = l * strict_lower + I,
/// U = u * strict_upper + diag(sign_s * exp(log_s)).
#[derive(Clone, Copy, Debug)]
pub struct InvConvW<'a> {
    /// (C, C) each, row-major; only the strict triangles of `l` / `u` are read.
    pub l: &'a [f32],
    pub u: &'a [f32],
    pub p: &'a [f32],
    /// (C) each.
    pub log_s: &'a [f32],
    pub sign_s: &'a [f32],
}

/// An affine coupling (`Coupling` with a `TransformerNN`).
#[derive(Clone, Debug)]
pub struct CouplingW<'a> {
    /// `input_encoder` (D, C - cc): only without channel concatenation.
    pub input_encoder: Option<Linear<'a>>,
    /// `nn.rescale` (weight norm): `weight_g`, `weight_v` (cc).
    pub weight_g: &'a [f32],
    pub weight_v: &'a [f32],
    pub net: CouplingNetW<'a>,
}

/// One flow step `[norm, 1x1 conv, coupling]` (applied in reverse order).
#[derive(Clone, Debug)]
pub struct FlowStepW<'a> {
    pub norm: NormW<'a>,
    pub conv: InvConvW<'a>,
    pub coupling: CouplingW<'a>,
}

/// A weight value the flow cannot use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueProblem {
    /// A flow parameter is NaN or infinite.
    NonFinite,
    /// `p` is not a permutation matrix (0/1, one 1 per row and column).
    NotPermutation,
    /// `sign_s` holds a value other than +-1.
    SignNotUnit,
    /// A divisor is zero (`gamma`, `inv_std`, `weight_v`).
    Zero,
    /// `running_var` < 0 (its square root is taken).
    NegativeVariance,
}

/// Why a model could not be bound.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelError {
    Config(ConfigError),
    Bind(BindError),
    Value {
        name: TensorName,
        problem: ValueProblem,
    },
}

impl From<BindError> for ModelError {
    fn from(e: BindError) -> Self {
        ModelError::Bind(e)
    }
}

impl From<SchemaError> for ModelError {
    fn from(e: SchemaError) -> Self {
        ModelError::Bind(BindError::Name(e))
    }
}

/// The whole inference path. Thread rule: immutable after [`Model::bind`].
#[derive(Clone, Debug)]
pub struct Model<'a> {
    pub cfg: TransflowerConfig,
    /// One per input, in order.
    pub inputs: Vec<InputNetW<'a>, MAX_INPUTS>,
    pub cross_modal: CrossModalW<'a>,
    /// Flow steps 0..S (the reverse pass runs them from S - 1 down).
    pub flow: Vec<FlowStepW<'a>, { MAX_FLOW_STEPS as usize }>,
}

struct Bind<'b, 's, S> {
    b: &'b Binder<'s, S>,
}

impl<'a, S: TensorSource<'a>> Bind<'_, '_, S> {
    #[allow(clippy::too_many_arguments)]
    fn transformer<const N: usize>(
        &self,
        p: &str,
        din: u32,
        d: u32,
        dout: u32,
        layers: u32,
        n_head: u32,
        pe: Option<u32>,
        bias: Option<u32>,
    ) -> Result<TransformerW<'a, N>, ModelError> {
        let b = self.b;
        let mut ls = Vec::new();
        for i in 0..layers {
            let l = bind_encoder_layer(
                b,
                &name(format_args!("{p}.transformer_encoder.layers.{i}"))?,
                d,
                d,
            )?;
            ls.push(l).map_err(|_| BindError::Capacity)?;
        }
        Ok(TransformerW {
            embedding: None,
            encoder1: b.linear(&name(format_args!("{p}.encoder1"))?, d, din, true)?,
            pe: match pe {
                Some(rows) => {
                    Some(b.get(name(format_args!("{p}.pos_encoder.pe"))?, &[rows, 1, d])?)
                }
                None => None,
            },
            bias: match bias {
                Some(l) => Some(b.get(name(format_args!("{p}.pos_emb"))?, &[l, l])?),
                None => None,
            },
            layers: ls,
            decoder: b.linear(&name(format_args!("{p}.decoder"))?, dout, d, true)?,
            din: din as usize,
            d: d as usize,
            dout: dout as usize,
            n_head: n_head as usize,
        })
    }

    /// An f32 flow vector `<m>.<n>`, finite.
    fn vector(&self, m: &str, n: &str, dims: &[u32]) -> Result<&'a [f32], ModelError> {
        let nm = name(format_args!("{m}.{n}"))?;
        let v = self.b.get(nm.clone(), dims)?;
        if v.iter().any(|x| !x.is_finite()) {
            return Err(ModelError::Value {
                name: nm,
                problem: ValueProblem::NonFinite,
            });
        }
        Ok(v)
    }
}

fn refuse(m: &str, n: &str, problem: ValueProblem) -> ModelError {
    match name(format_args!("{m}.{n}")) {
        Ok(name) => ModelError::Value { name, problem },
        Err(e) => e.into(),
    }
}

/// Whether `p` (c, c) is a permutation matrix.
fn is_permutation(p: &[f32], c: usize) -> bool {
    let rows_ok = p.chunks_exact(c).all(|r| {
        r.iter().all(|&v| v == 0.0 || v == 1.0) && r.iter().filter(|&&v| v == 1.0).count() == 1
    });
    let cols_ok = (0..c).all(|j| (0..c).filter(|&i| p[i * c + j] == 1.0).count() == 1);
    rows_ok && cols_ok
}

impl<'a> Model<'a> {
    /// Validates `cfg` and binds every tensor the schema lists from `src`.
    pub fn bind<S: TensorSource<'a>>(
        cfg: &TransflowerConfig,
        src: &S,
    ) -> Result<Model<'a>, ModelError> {
        cfg.validate().map_err(ModelError::Config)?;
        let binder = Binder { src };
        let b = Bind { b: &binder };
        let d = cfg.dhid;
        let mut inputs = Vec::new();
        for (i, inp) in cfg.inputs().iter().enumerate() {
            let p = schema::input_prefix(cfg, i)?;
            let bias = cfg.input_has_bias(i).then_some(inp.length);
            let mut t: InputNetW<'a> =
                b.transformer(&p, inp.dim, d, d, INPUT_LAYERS, cfg.nhead, None, bias)?;
            if inp.is_discrete() {
                t.embedding = Some(binder.matrix(
                    name(format_args!("{p}.encoder.weight"))?,
                    &[inp.tokens, inp.dim],
                )?);
            }
            inputs.push(t).map_err(|_| BindError::Capacity)?;
        }
        let pe = cfg.pos_emb_output.then_some(cfg.latent_rows() as u32);
        let cross_modal = b.transformer(
            &schema::cross_modal_prefix(cfg)?,
            d,
            d,
            d,
            cfg.nlayers,
            cfg.nhead,
            pe,
            None,
        )?;
        let c = cfg.channels() as u32;
        let cc = cfg.change_channels() as u32;
        let f = &cfg.flow;
        let cv = [1, c, 1, 1];
        let mut flow = Vec::new();
        for j in 0..f.steps {
            let (norm_k, conv_k, coupling_k) = schema::step_modules(cfg, j);
            let norm = match (f.norm, norm_k) {
                (NormLayer::BatchNorm, Some(k)) => {
                    let m = schema::flow_module(cfg, k)?;
                    let (gamma, var) = (
                        b.vector(&m, "gamma", &cv)?,
                        b.vector(&m, "running_var", &cv)?,
                    );
                    if gamma.contains(&0.0) {
                        return Err(refuse(&m, "gamma", ValueProblem::Zero));
                    }
                    if var.iter().any(|&v| v < 0.0) {
                        return Err(refuse(&m, "running_var", ValueProblem::NegativeVariance));
                    }
                    NormW::BatchNorm {
                        gamma,
                        beta: b.vector(&m, "beta", &cv)?,
                        mean: b.vector(&m, "running_mean", &cv)?,
                        var,
                    }
                }
                (NormLayer::ActNorm, Some(k)) => {
                    let m = schema::flow_module(cfg, k)?;
                    let inv_std = b.vector(&m, "inv_std", &cv)?;
                    if inv_std.contains(&0.0) {
                        return Err(refuse(&m, "inv_std", ValueProblem::Zero));
                    }
                    NormW::ActNorm {
                        mean: b.vector(&m, "mean", &cv)?,
                        inv_std,
                    }
                }
                _ => NormW::None,
            };
            let m = schema::flow_module(cfg, conv_k)?;
            let conv = InvConvW {
                l: b.vector(&m, "l", &[c, c])?,
                u: b.vector(&m, "u", &[c, c])?,
                p: b.vector(&m, "p", &[c, c])?,
                log_s: b.vector(&m, "log_s", &[c])?,
                sign_s: b.vector(&m, "sign_s", &[c])?,
            };
            if !is_permutation(conv.p, c as usize) {
                return Err(refuse(&m, "p", ValueProblem::NotPermutation));
            }
            if conv.sign_s.iter().any(|&s| s != 1.0 && s != -1.0) {
                return Err(refuse(&m, "sign_s", ValueProblem::SignNotUnit));
            }
            let m = schema::flow_module(cfg, coupling_k)?;
            let input_encoder = if f.concat_dims {
                None
            } else {
                Some(binder.linear(&name(format_args!("{m}.input_encoder"))?, d, c - cc, true)?)
            };
            let (weight_g, weight_v) = (
                b.vector(&m, "nn.rescale.weight_g", &[cc, 1, 1])?,
                b.vector(&m, "nn.rescale.weight_v", &[cc, 1, 1])?,
            );
            if weight_v.contains(&0.0) {
                return Err(refuse(&m, "nn.rescale.weight_v", ValueProblem::Zero));
            }
            let pe = f.pos_emb.then_some(cfg.coupling_rows() as u32);
            let net = b.transformer(
                &name(format_args!("{m}.nn.transformer"))?,
                cfg.coupling_in() as u32,
                f.dhid,
                2 * cc,
                f.layers,
                f.heads,
                pe,
                None,
            )?;
            flow.push(FlowStepW {
                norm,
                conv,
                coupling: CouplingW {
                    input_encoder,
                    weight_g,
                    weight_v,
                    net,
                },
            })
            .map_err(|_| BindError::Capacity)?;
        }
        Ok(Model {
            cfg: *cfg,
            inputs,
            cross_modal,
            flow,
        })
    }

    /// Binds every weight of a parsed `.duo` file (family Transflower); a
    /// file of another family is refused with [`BindError::Family`].
    pub fn from_duo(file: &crate::format::DuoFile<'a>) -> Result<Model<'a>, ModelError> {
        match file.config() {
            crate::family::FamilyConfig::Transflower(cfg) => Model::bind(cfg, file),
            other => Err(ModelError::Bind(BindError::Family {
                expected: crate::family::Family::Transflower,
                found: other.family(),
            })),
        }
    }

    pub fn config(&self) -> &TransflowerConfig {
        &self.cfg
    }
}

const _: () = {
    const fn assert_sync<T: Sync>() {}
    assert_sync::<Model<'static>>();
};
