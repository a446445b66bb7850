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
use crate::transflower::encoders::{encode_inputs_recorded, input_rows, Window};
use crate::transflower::exact::{Prepared, StepScratch};
use crate::transflower::flow;
use crate::transflower::model::Model;
use crate::transflower::probe;
use crate::transflower::session::config::SessionConfig;
use crate::transflower::session::state::{is_fed, need_rows, State};
use crate::transflower::transformer::{forward_chunked, forward_rows};

/// Rows a rolling session's nets compute at a time: a stale step's rows
/// through one net, at least [`MIN_CHUNK`] (the first step's chunks), at
/// most every latent row.
pub fn chunk_rows(cfg: &TransflowerConfig, sc: &SessionConfig) -> usize {
    let (mut most, mut cross) = (0, cfg.cond_len as usize);
    for ic in cfg.inputs() {
        let l = ic.length as usize;
        if ic.is_discrete() {
            cross += usize::from(sc.rolling);
        } else {
            let r = 1 + share(sc, l);
            most = most.max(r);
            cross += r;
        }
    }
    most.max(cross).max(MIN_CHUNK).min(cfg.latent_rows())
}

/// The fewest rows a rolling session's first step computes at a time.
pub const MIN_CHUNK: usize = 32;

/// Rows of an input of window `l` a stale step recomputes besides its
/// newest row: rolling, `ceil(l / refresh)` of them (round robin).
fn share(sc: &SessionConfig, l: usize) -> usize {
    if sc.rolling {
        l.div_ceil(sc.refresh.max(1) as usize)
            .min(l.saturating_sub(1))
    } else {
        0
    }
}

/// Working memory of a step (shared by the sessions of a batch).
pub struct Scratch<'s> {
    pub(crate) step: StepScratch<'s>,
    /// (sum L, D): the rows a stale step computes, gathered.
    rows: &'s mut [f32],
    /// (sum L): their slots.
    slots: &'s mut [u32],
    /// (sum L): the cross-modal slots recomputed besides the conditioning rows.
    extra: &'s mut [u32],
    /// (max L_i, max d_i): an input's rows recomputed by its net.
    inrows: &'s mut [f32],
}

impl<'s> Scratch<'s> {
    /// The step memory of a session with config `sc`, or (None) of a
    /// [`StepBatch`](super::StepBatch) that steps sessions of any config.
    /// A rolling session's nets compute a chunk of rows at a time
    /// ([`chunk_rows`]); the others' a whole step's rows.
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &TransflowerConfig,
        sc: Option<&SessionConfig>,
    ) -> Result<Self, ArenaError> {
        let stale = sc.is_none_or(|sc| sc.stale());
        let n = if stale { cfg.latent_rows() } else { 0 };
        Ok(Scratch {
            step: match sc {
                Some(sc) if sc.rolling => {
                    StepScratch::carve_net(a, cfg, chunk_rows(cfg, sc), false)?
                }
                _ => StepScratch::carve(a, cfg)?,
            },
            rows: a.f32(
                n.checked_mul(cfg.dhid as usize)
                    .ok_or(ArenaError::Overflow)?,
            )?,
            slots: a.u32(n)?,
            extra: a.u32(n)?,
            inrows: a.f32(if stale {
                let l = cfg.max_window();
                let din = cfg
                    .inputs()
                    .iter()
                    .map(|i| i.dim as usize)
                    .max()
                    .unwrap_or(0);
                l.checked_mul(din).ok_or(ArenaError::Overflow)?
            } else {
                0
            })?,
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
    sc: &SessionConfig,
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
        .is_none_or(|x| x.since.is_multiple_of(sc.refresh.max(1)) && (!sc.rolling || x.since == 0));
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
            Some(x) if sc.rolling => {
                // The first step: every row, a chunk at a time.
                x.reset_slots(cfg);
                let n = cfg.latent_rows();
                for (j, id) in s.slots[..n].iter_mut().enumerate() {
                    *id = j as u32;
                }
                let mut off = 0;
                for (i, ic) in cfg.inputs().iter().enumerate() {
                    let (l, net) = (ic.length as usize, &model.inputs[i]);
                    let input = input_rows(net, windows[i], ss.emb);
                    let layers = i * INPUT_LAYERS as usize..(i + 1) * INPUT_LAYERS as usize;
                    forward_chunked(
                        net,
                        input,
                        &s.slots[..l],
                        &x.ipos[off..off + l],
                        l,
                        &mut x.input_kv[layers],
                        &mut s.rows[..l * d],
                        &mut ss.net,
                        &mut x.latent[off * d..(off + l) * d],
                    );
                    off += l;
                }
                forward_chunked(
                    &model.cross_modal,
                    x.latent,
                    &s.slots[..n],
                    x.xpos,
                    cfg.cond_len as usize,
                    &mut x.cross_kv,
                    s.rows,
                    &mut ss.net,
                    ss.cond,
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
        // Each sliding input's newest row (and, rolling, its next share of
        // rows) through its net, against the kept rows.
        let mut extra = 0;
        let mut off = 0;
        for (i, ic) in cfg.inputs().iter().enumerate() {
            let l = ic.length as usize;
            if ic.is_discrete() {
                if sc.rolling {
                    s.extra[extra] = off as u32;
                    extra += 1;
                }
                off += l;
                continue;
            }
            let newest = x.slide(i, off, l);
            let mut mi = 0;
            s.slots[mi] = newest as u32;
            mi += 1;
            for _ in 0..share(sc, l) {
                let mut j = x.cursor[i] % l;
                if j == newest {
                    j = (j + 1) % l;
                }
                x.cursor[i] = (j + 1) % l;
                s.slots[mi] = j as u32;
                mi += 1;
            }
            let din = ic.dim as usize;
            for (r, &j) in s.slots[..mi].iter().enumerate() {
                let pos = x.ipos[off + j as usize] as usize;
                let row: &[f32] = if i == m {
                    &st.window[pos * din..(pos + 1) * din]
                } else {
                    st.feeds[i].rows(pos, 1)
                };
                s.inrows[r * din..(r + 1) * din].copy_from_slice(row);
            }
            let kv = &mut x.input_kv[i * INPUT_LAYERS as usize..(i + 1) * INPUT_LAYERS as usize];
            forward_rows(
                &model.inputs[i],
                &s.inrows[..mi * din],
                &s.slots[..mi],
                &x.ipos[off..off + l],
                mi,
                kv,
                &mut s.step.net,
                &mut s.rows[..mi * d],
            );
            for (r, &j) in s.slots[..mi].iter().enumerate() {
                let at = off + j as usize;
                x.latent[at * d..(at + 1) * d].copy_from_slice(&s.rows[r * d..(r + 1) * d]);
                s.extra[extra] = at as u32;
                extra += 1;
            }
            off += l;
        }
        // The cross-modal rows: the conditioning rows first (their decoder
        // output is `cond`), then the other recomputed rows, once each.
        let keep = cfg.cond_len as usize;
        let mut rows = 0;
        for p in 0..keep {
            s.slots[rows] = x.slot_of(cfg, p) as u32;
            rows += 1;
        }
        for k in 0..extra {
            let slot = s.extra[k];
            if x.xpos[slot as usize] as usize >= keep && !s.slots[keep..rows].contains(&slot) {
                s.slots[rows] = slot;
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
        x.since = if sc.rolling {
            1
        } else {
            (x.since + 1) % sc.refresh.max(1)
        };
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
