//! R mode: the authors' generation loop (models/util/generation.py
//! `autoregressive_generation_multimodal`, batch 1, `model.eval()`),
//! with the base samples given ([`Replay`]) or drawn ([`Seeded`]). Facts
//! and the numbered algorithm: tools/reference/transflower/README.md.
//!
//! ```text
//! windows at start: input i = rows [0, L_i)          (input_time_offsets 0)
//! N = rows(last input) - max_i L_i + 1 steps
//! step t:  latent = concat_rows(input_net_i(window_i))       (sum L, D)
//!          cond   = cross_modal(latent)[0 .. cond_len]       (cond_len, D)
//!          x      = flow_reverse(z_t, cond)                  (C, H)
//!          out[t] = x[:, 0]                                  (C): frame at song row L_out + t
//!          output window = concat_rows(window[1..], out[t]);
//!          other continuous windows = rows [t + 1, t + 1 + L_i); a label never moves
//! ```
//!
//! Nothing is reused across steps (no causal mask, no positions: every
//! row sees every row); only the flow's reverse 1x1 weights are computed
//! once per call (the authors cache them on the first reverse pass).
//!
//! Refused (named errors, nothing written): a motion seed (the output
//! modality's rows) shorter than its window ([`Error::TooShort`],
//! `SeedFrames`); a last input shorter than the longest window (zero
//! steps: the authors return nothing, "Sequence too short!"), or another
//! continuous input shorter than its last window (`TooShort`, `Features`);
//! a label outside the vocabulary ([`Error::Token`]); ragged or non-finite
//! rows; a wrong output length.

use crate::arena::{Arena, ArenaError, Carve, Planner};
use crate::error::{check_len, Buffer, Error};
use crate::input;
use crate::transflower::base::BaseSample;
pub use crate::transflower::base::{Replay, Seeded};
use crate::transflower::config::{TransflowerConfig, MAX_INPUTS};
use crate::transflower::cross_modal::condition;
use crate::transflower::encoders::{encode_inputs, Window};
use crate::transflower::flow::inv_conv::{inverse_weight, InverseScratch};
use crate::transflower::flow::{self, FlowScratch};
use crate::transflower::model::Model;
use crate::transflower::probe::{self, Probe};
use crate::transflower::transformer::TransformerScratch;

/// One input's whole sequence, in `input_modalities` order.
#[derive(Clone, Copy, Debug)]
pub enum Input<'x> {
    /// A continuous input's rows (T_i, d_i) row-major.
    Rows(&'x [f32]),
    /// A discrete input's label (`single`).
    Label(u32),
}

/// The buffer named in errors about input `i`: the output modality's rows
/// are the motion seed (`SeedFrames`), a label `Tokens`, any other
/// continuous input (the audio features) `Features`.
pub fn buffer_of(cfg: &TransflowerConfig, i: usize) -> Buffer {
    if i == cfg.output as usize {
        Buffer::SeedFrames
    } else if cfg.inputs[i].is_discrete() {
        Buffer::Tokens
    } else {
        Buffer::Features
    }
}

/// Checks the inputs and returns N, the number of generated frames.
pub fn steps(cfg: &TransflowerConfig, inputs: &[Input<'_>]) -> Result<usize, Error> {
    let n_in = cfg.inputs().len();
    check_len(Buffer::Features, inputs.len(), n_in)?;
    let mut rows = [0usize; MAX_INPUTS];
    for (i, (c, inp)) in cfg.inputs().iter().zip(inputs).enumerate() {
        let buffer = buffer_of(cfg, i);
        match (*inp, c.is_discrete()) {
            (Input::Label(v), true) => {
                if v >= c.tokens {
                    return Err(Error::Token {
                        stream: i as u8,
                        token: v,
                        vocab: c.tokens,
                    });
                }
                rows[i] = 1;
            }
            (Input::Rows(x), false) => {
                let d = c.dim as usize;
                if x.is_empty() || !x.len().is_multiple_of(d) {
                    return Err(Error::Ragged {
                        buffer,
                        len: x.len(),
                        row: d,
                    });
                }
                input::check(buffer, x)?;
                rows[i] = x.len() / d;
            }
            // A label for a continuous input, or rows for a discrete one.
            (Input::Label(_), false) => {
                return Err(Error::Ragged {
                    buffer,
                    len: 1,
                    row: c.dim as usize,
                })
            }
            (Input::Rows(x), true) => {
                return Err(Error::Length {
                    buffer,
                    len: x.len(),
                    expected: 1,
                })
            }
        }
    }
    let m = cfg.output as usize;
    let lm = cfg.inputs[m].length as usize;
    if rows[m] < lm {
        return Err(Error::TooShort {
            buffer: Buffer::SeedFrames,
            frames: rows[m],
            min: lm,
        });
    }
    let last = n_in - 1;
    let max_l = cfg.max_window();
    if rows[last] < max_l {
        return Err(Error::TooShort {
            buffer: buffer_of(cfg, last),
            frames: rows[last],
            min: max_l,
        });
    }
    let n = rows[last] - max_l + 1;
    for (i, c) in cfg.inputs().iter().enumerate() {
        let need = c.length as usize + n - 1;
        if i != m && !c.is_discrete() && rows[i] < need {
            return Err(Error::TooShort {
                buffer: Features,
                frames: rows[i],
                min: need,
            });
        }
    }
    Ok(n)
}

use Buffer::Features;

/// Working memory of one step ([`step`]).
pub struct StepScratch<'s> {
    /// Shared by every transformer (inputs, cross-modal, couplings).
    pub(crate) net: TransformerScratch<'s>,
    /// (max discrete input dim): an embedding row.
    pub(crate) emb: &'s mut [f32],
    /// (sum L, D): the input encoders' outputs.
    pub(crate) latent: &'s mut [f32],
    /// (cond_len, D).
    pub(crate) cond: &'s mut [f32],
    /// (C, H): the base sample, then the flow's sample.
    pub(crate) x: &'s mut [f32],
    pub(crate) flow: FlowScratch<'s>,
}

impl<'s> StepScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &TransflowerConfig) -> Result<Self, ArenaError> {
        Self::carve_net(a, cfg, cfg.latent_rows(), true)
    }

    /// A step's scratch whose nets compute at most `rows` rows at a time
    /// (at least a coupling's rows; against every latent row) and, with
    /// `latent` false, no latent buffer (a rolling session keeps its own:
    /// `transflower::session`).
    pub fn carve_net<A: Carve<'s>>(
        a: &mut A,
        cfg: &TransflowerConfig,
        rows: usize,
        latent: bool,
    ) -> Result<Self, ArenaError> {
        let d = cfg.dhid as usize;
        let keys = cfg.latent_rows().max(cfg.coupling_rows());
        let rows = rows.max(cfg.coupling_rows()).min(keys);
        let width = d.max(cfg.flow.dhid as usize);
        let emb = cfg
            .inputs()
            .iter()
            .filter(|i| i.is_discrete())
            .map(|i| i.dim as usize)
            .max()
            .unwrap_or(0);
        Ok(StepScratch {
            net: TransformerScratch::carve_keys(a, rows, keys, width)?,
            emb: a.f32(emb)?,
            latent: a.f32(if latent { cfg.latent_rows() * d } else { 0 })?,
            cond: a.f32(cfg.cond_len as usize * d)?,
            x: a.f32(cfg.channels() * cfg.output_length as usize)?,
            flow: FlowScratch::carve(a, cfg)?,
        })
    }
}

/// The flow's reverse 1x1 weights, computed once ([`prepare`]).
pub struct Prepared<'s> {
    /// (S, C, C).
    pub inv_w: &'s mut [f32],
    inv: InverseScratch<'s>,
}

impl<'s> Prepared<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &TransflowerConfig) -> Result<Self, ArenaError> {
        let c = cfg.channels();
        let cc = c.checked_mul(c).ok_or(ArenaError::Overflow)?;
        let col: &'s mut [u32] = a.u32(2 * c)?;
        Ok(Prepared {
            inv_w: a.f32(
                cc.checked_mul(cfg.flow.steps as usize)
                    .ok_or(ArenaError::Overflow)?,
            )?,
            // f64 column: carved as u32 pairs (64-byte aligned; a planner's is empty).
            inv: InverseScratch {
                li: a.f32(cc)?,
                ui: a.f32(cc)?,
                col: bytemuck::try_cast_slice_mut(col).unwrap_or(&mut []),
            },
        })
    }
}

/// Fills `p.inv_w` with every flow step's reverse 1x1 weight.
pub fn prepare(model: &Model<'_>, p: &mut Prepared<'_>) {
    let c = model.cfg.channels();
    for (j, step) in model.flow.iter().enumerate() {
        inverse_weight(
            &step.conv,
            c,
            &mut p.inv,
            &mut p.inv_w[j * c * c..(j + 1) * c * c],
        );
    }
}

/// One step: `frames` (H, C) = the flow's sample given the windows (one
/// per input: rows (L_i, d_i) or a label) and the base sample `z` (C, H).
/// Windows are the caller's to check ([`generate`] does).
#[allow(clippy::too_many_arguments)]
pub fn step(
    model: &Model<'_>,
    p: &Prepared<'_>,
    windows: &[Window<'_>],
    z: &[f32],
    s: &mut StepScratch<'_>,
    frames: &mut [f32],
    probe: &mut dyn FnMut(Probe, &[f32]),
) {
    let cfg = &model.cfg;
    let (c, h) = (cfg.channels(), cfg.output_length as usize);
    encode_inputs(model, windows, &mut s.net, s.emb, s.latent, probe);
    condition(model, s.latent, &mut s.net, s.cond, probe);
    s.x.copy_from_slice(z);
    flow::reverse(model, p.inv_w, s.x, s.cond, &mut s.net, &mut s.flow, probe);
    // (C, H) -> (H, C).
    for ch in 0..c {
        for t in 0..h {
            frames[t * c + ch] = s.x[ch * h + t];
        }
    }
    probe(Probe::FlowOut, &frames[..h * c]);
}

/// Working memory of [`generate`].
struct GenerateScratch<'s> {
    prepared: Prepared<'s>,
    step: StepScratch<'s>,
    /// (L_out, C): the output modality's window (seed rows, then generated frames).
    window: &'s mut [f32],
    /// (C, H): the step's base sample.
    z: &'s mut [f32],
    /// (H, C): the step's sampled frames.
    frames: &'s mut [f32],
}

fn generate_scratch<'s, A: Carve<'s>>(
    a: &mut A,
    cfg: &TransflowerConfig,
) -> Result<GenerateScratch<'s>, ArenaError> {
    let ch = cfg.channels() * cfg.output_length as usize;
    Ok(GenerateScratch {
        prepared: Prepared::carve(a, cfg)?,
        step: StepScratch::carve(a, cfg)?,
        window: a.f32(cfg.output_input().length as usize * cfg.channels())?,
        z: a.f32(ch)?,
        frames: a.f32(ch)?,
    })
}

/// Scratch bytes of [`generate`] (any base address).
pub fn generate_scratch_bytes(cfg: &TransflowerConfig) -> Option<usize> {
    let mut p = Planner::new();
    generate_scratch(&mut p, cfg).ok()?;
    p.total_for_any_base()
}

/// The authors' loop: `out` (N, C) receives the N = [`steps`] generated
/// frames (the scaled features; frame t is song row `output_time_offset + t`).
/// Returns N.
pub fn generate<B: BaseSample>(
    model: &Model<'_>,
    inputs: &[Input<'_>],
    base: &mut B,
    scratch: &mut [u8],
    out: &mut [f32],
) -> Result<usize, Error> {
    generate_probed(model, inputs, base, scratch, out, &mut probe::none)
}

/// [`generate`] with a probe that sees every stage of every step
/// ([`crate::transflower::probe`]; step boundaries: each `FlowOut`).
pub fn generate_probed<B: BaseSample>(
    model: &Model<'_>,
    inputs: &[Input<'_>],
    base: &mut B,
    scratch: &mut [u8],
    out: &mut [f32],
    probe: &mut dyn FnMut(Probe, &[f32]),
) -> Result<usize, Error> {
    let cfg = &model.cfg;
    let n = steps(cfg, inputs)?;
    let c = cfg.channels();
    let h = cfg.output_length as usize;
    check_len(Buffer::Output, out.len(), n * c)?;
    base.check(n, c * h)?;
    let mut a = Arena::new(scratch);
    let GenerateScratch {
        mut prepared,
        step: mut s,
        window,
        z,
        frames,
    } = generate_scratch(&mut a, cfg)?;
    prepare(model, &mut prepared);
    let m = cfg.output as usize;
    let lm = cfg.inputs[m].length as usize;
    if let Input::Rows(seed) = inputs[m] {
        window.copy_from_slice(&seed[..lm * c]);
    }
    for t in 0..n {
        let mut windows = [Window::Label(0); MAX_INPUTS];
        for (i, (ic, inp)) in cfg.inputs().iter().zip(inputs).enumerate() {
            let (l, d) = (ic.length as usize, ic.dim as usize);
            windows[i] = match *inp {
                _ if i == m => Window::Rows(window),
                Input::Label(v) => Window::Label(v),
                Input::Rows(x) => Window::Rows(&x[t * d..(t + l) * d]),
            };
        }
        base.sample(t, z);
        step(
            model,
            &prepared,
            &windows[..cfg.inputs().len()],
            z,
            &mut s,
            frames,
            probe,
        );
        // Row 0 of the H sampled frames is kept and fed back.
        out[t * c..(t + 1) * c].copy_from_slice(&frames[..c]);
        window.copy_within(c.., 0);
        window[(lm - 1) * c..].copy_from_slice(&frames[..c]);
    }
    Ok(n)
}
