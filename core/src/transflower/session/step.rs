//! One session step: the transformers (every row, or only the changed
//! rows against the kept ones), the flow, and the windows moved on.
//!
//! ```text
//! whole step (R, and every `refresh`-th step of the stale mode):
//!   latent = input nets over their windows   [keys/values kept per layer]
//!   cond   = cross-modal over latent, first cond_len rows  [kept per layer]
//! stale step (the windows moved one row since the last step):
//!   each sliding input i: its newest row takes its oldest row's slot;
//!     latent[slot] = input net over that row vs the kept rows
//!   cond = cross-modal over the cond rows + the newest rows vs the kept rows
//! then: x = flow_reverse(z, cond); frame = x[:, 0]; window += frame
//! ```

use crate::arena::{ArenaError, Carve};
use crate::transflower::config::{TransflowerConfig, INPUT_LAYERS, MAX_INPUTS};
use crate::transflower::cross_modal::condition_recorded;
use crate::transflower::encoders::{encode_inputs_recorded, Window};
use crate::transflower::exact::{Prepared, StepScratch};
use crate::transflower::flow;
use crate::transflower::model::Model;
use crate::transflower::probe;
use crate::transflower::session::state::{is_fed, need_rows, State};
use crate::transflower::transformer::forward_rows;

/// Working memory of a step (shared by the sessions of a batch).
pub struct Scratch<'s> {
    pub(crate) step: StepScratch<'s>,
    /// (sum L, D): the rows a stale step computes, gathered.
    rows: &'s mut [f32],
    /// (sum L): their slots.
    slots: &'s mut [u32],
}

impl<'s> Scratch<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &TransflowerConfig,
        stale: bool,
    ) -> Result<Self, ArenaError> {
        let n = if stale { cfg.latent_rows() } else { 0 };
        Ok(Scratch {
            step: StepScratch::carve(a, cfg)?,
            rows: a.f32(
                n.checked_mul(cfg.dhid as usize)
                    .ok_or(ArenaError::Overflow)?,
            )?,
            slots: a.u32(n)?,
        })
    }

    pub fn stale_rows(&self) -> usize {
        self.slots.len()
    }
}

/// Steps one session whose inputs are ready: `st.z` holds the base
/// sample; the frames land in `st.frames` (H, C); the motion window takes
/// frame 0 and every sliding input moves one row on.
pub(crate) fn step(
    model: &Model<'_>,
    p: &Prepared<'_>,
    refresh: u32,
    labels: &[u32; MAX_INPUTS],
    st: &mut State<'_>,
    s: &mut Scratch<'_>,
) {
    let cfg = &model.cfg;
    let d = cfg.dhid as usize;
    let m = cfg.output as usize;
    let whole = st
        .stale
        .as_ref()
        .is_none_or(|x| x.since.is_multiple_of(refresh.max(1)));
    if whole {
        let mut windows = [Window::Label(0); MAX_INPUTS];
        for (i, ic) in cfg.inputs().iter().enumerate() {
            windows[i] = if i == m {
                Window::Rows(st.window)
            } else if ic.is_discrete() {
                Window::Label(labels[i])
            } else {
                Window::Rows(st.feeds[i].rows(0, ic.length as usize))
            };
        }
        let n_in = cfg.inputs().len();
        let ss = &mut s.step;
        match st.stale.as_mut() {
            None => {
                encode_inputs_recorded(
                    model,
                    &windows[..n_in],
                    &mut ss.net,
                    ss.emb,
                    ss.latent,
                    &mut probe::none,
                    &mut |_, _, _| {},
                );
                condition_recorded(
                    model,
                    ss.latent,
                    &mut ss.net,
                    ss.cond,
                    &mut probe::none,
                    &mut |_, _| {},
                );
            }
            Some(x) => {
                let kv = &mut x.input_kv;
                encode_inputs_recorded(
                    model,
                    &windows[..n_in],
                    &mut ss.net,
                    ss.emb,
                    ss.latent,
                    &mut probe::none,
                    &mut |i, l, qkv| {
                        if let Some(k) = kv.get_mut(i * INPUT_LAYERS as usize + l) {
                            k.store_all(qkv, d);
                        }
                    },
                );
                x.latent.copy_from_slice(ss.latent);
                x.reset_slots(cfg);
                let kv = &mut x.cross_kv;
                condition_recorded(
                    model,
                    ss.latent,
                    &mut ss.net,
                    ss.cond,
                    &mut probe::none,
                    &mut |l, qkv| {
                        if let Some(k) = kv.get_mut(l) {
                            k.store_all(qkv, d);
                        }
                    },
                );
            }
        }
    } else if let Some(x) = st.stale.as_mut() {
        // Each sliding input's newest row through its net, against the kept rows.
        let mut newest = [usize::MAX; MAX_INPUTS];
        let mut off = 0;
        for (i, ic) in cfg.inputs().iter().enumerate() {
            let l = ic.length as usize;
            if !ic.is_discrete() {
                let slot = x.slide(i, off, l);
                newest[i] = off + slot;
                let row: &[f32] = if i == m {
                    &st.window[(l - 1) * ic.dim as usize..]
                } else {
                    st.feeds[i].rows(l - 1, 1)
                };
                s.slots[0] = slot as u32;
                let kv =
                    &mut x.input_kv[i * INPUT_LAYERS as usize..(i + 1) * INPUT_LAYERS as usize];
                let out = &mut x.latent[(off + slot) * d..(off + slot + 1) * d];
                forward_rows(
                    &model.inputs[i],
                    row,
                    &s.slots[..1],
                    &x.ipos[off..off + l],
                    1,
                    kv,
                    &mut s.step.net,
                    out,
                );
            }
            off += l;
        }
        // The cross-modal rows: the conditioning rows first, then the newest rows.
        let keep = cfg.cond_len as usize;
        let mut rows = 0;
        for p in 0..keep {
            s.slots[rows] = x.slot_of(cfg, p) as u32;
            rows += 1;
        }
        for &slot in newest.iter().filter(|&&v| v != usize::MAX) {
            if x.xpos[slot] as usize >= keep {
                s.slots[rows] = slot as u32;
                rows += 1;
            }
        }
        for (r, &slot) in s.slots[..rows].iter().enumerate() {
            let slot = slot as usize;
            s.rows[r * d..(r + 1) * d].copy_from_slice(&x.latent[slot * d..(slot + 1) * d]);
        }
        forward_rows(
            &model.cross_modal,
            &s.rows[..rows * d],
            &s.slots[..rows],
            x.xpos,
            keep,
            &mut x.cross_kv,
            &mut s.step.net,
            s.step.cond,
        );
    }
    if let Some(x) = st.stale.as_mut() {
        x.since = (x.since + 1) % refresh.max(1);
    }
    // The flow: z (C, H) -> frames (H, C).
    let (c, h) = (cfg.channels(), cfg.output_length as usize);
    let ss = &mut s.step;
    ss.x.copy_from_slice(st.z);
    flow::reverse(
        model,
        p.inv_w,
        ss.x,
        ss.cond,
        &mut ss.net,
        &mut ss.flow,
        &mut probe::none,
    );
    for ch in 0..c {
        for t in 0..h {
            st.frames[t * c + ch] = ss.x[ch * h + t];
        }
    }
    // Frame 0 is fed back; the sliding inputs move on.
    let lm = cfg.inputs[m].length as usize;
    st.window.copy_within(c.., 0);
    st.window[(lm - 1) * c..].copy_from_slice(&st.frames[..c]);
    for (i, f) in st.feeds.iter_mut().enumerate() {
        if is_fed(cfg, i) {
            f.advance();
        }
    }
}

/// Whether every sliding input holds the rows of the next step.
pub(crate) fn ready(cfg: &TransflowerConfig, st: &State<'_>) -> bool {
    (0..cfg.inputs().len()).all(|i| !is_fed(cfg, i) || st.feeds[i].held() >= need_rows(cfg, i))
}
