//! A Transflower session's memory, carved once: the inputs' rows (each
//! sliding input a linear buffer, compacted when it runs out), the motion
//! window, the frames not yet pulled, and (stale-rows S mode) every
//! transformer's kept keys and values.

use heapless::Vec;

use crate::arena::{ArenaError, Carve};
use crate::error::{Buffer, Error};
use crate::nn::encoder_layer::LayerKv;
use crate::transflower::config::{TransflowerConfig, INPUT_LAYERS, MAX_INPUTS, MAX_LAYERS};
use crate::transflower::session::config::SessionConfig;

/// One sliding input's rows: rows `[off, off + held)` of `rows` (cap, d)
/// are the ones from the current window's first row on.
pub struct Feed<'s> {
    rows: &'s mut [f32],
    d: usize,
    off: usize,
    held: usize,
}

impl<'s> Feed<'s> {
    fn carve<A: Carve<'s>>(a: &mut A, cap: usize, d: usize) -> Result<Self, ArenaError> {
        Ok(Feed {
            rows: a.f32(cap.checked_mul(d).ok_or(ArenaError::Overflow)?)?,
            d,
            off: 0,
            held: 0,
        })
    }

    pub fn cap(&self) -> usize {
        self.rows.len().checked_div(self.d).unwrap_or(0)
    }

    pub fn held(&self) -> usize {
        self.held
    }

    /// Appends whole rows; refused (nothing kept) past the capacity.
    pub fn push(&mut self, x: &[f32], buffer: Buffer) -> Result<(), Error> {
        let n = x.len() / self.d.max(1);
        if self.held + n > self.cap() {
            return Err(Error::Backlog {
                buffer,
                held: self.held + n,
                capacity: self.cap(),
            });
        }
        if self.off + self.held + n > self.cap() {
            self.rows
                .copy_within(self.off * self.d..(self.off + self.held) * self.d, 0);
            self.off = 0;
        }
        let at = (self.off + self.held) * self.d;
        self.rows[at..at + x.len()].copy_from_slice(x);
        self.held += n;
        Ok(())
    }

    /// Rows `[r, r + l)` of the held rows.
    pub fn rows(&self, r: usize, l: usize) -> &[f32] {
        &self.rows[(self.off + r) * self.d..(self.off + r + l) * self.d]
    }

    /// Drops the oldest row.
    pub fn advance(&mut self) {
        if self.held > 0 {
            self.off += 1;
            self.held -= 1;
        }
    }

    pub fn clear(&mut self) {
        self.off = 0;
        self.held = 0;
    }
}

/// The stale-rows mode's kept rows. Every transformer's rows sit in slots
/// (input i's window rows in a ring of L_i slots; the cross-modal rows at
/// `offset_i + input i's slot`); `head[i]` is the slot of input i's oldest
/// row.
pub struct Stale<'s> {
    /// Input i's layer l at `i * INPUT_LAYERS + l`: (L_i, D) keys and values.
    pub input_kv: Vec<LayerKv<'s>, { MAX_INPUTS * INPUT_LAYERS as usize }>,
    /// The cross-modal layers' (sum L, D) keys and values.
    pub cross_kv: Vec<LayerKv<'s>, { MAX_LAYERS as usize }>,
    /// (sum L, D): every input transformer's output row, by cross-modal slot.
    pub latent: &'s mut [f32],
    /// (sum L): the window position of each slot within its input.
    pub ipos: &'s mut [u32],
    /// (sum L): the latent position of each cross-modal slot (`offset_i + ipos`).
    pub xpos: &'s mut [u32],
    pub head: [usize; MAX_INPUTS],
    /// Steps since everything was recomputed (0: recompute now).
    pub since: u32,
}

impl<'s> Stale<'s> {
    fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &TransflowerConfig,
        sc: &SessionConfig,
    ) -> Result<Self, ArenaError> {
        let d = cfg.dhid as usize;
        let n = cfg.latent_rows();
        let mut input_kv = Vec::new();
        for i in cfg.inputs() {
            for _ in 0..INPUT_LAYERS {
                input_kv
                    .push(LayerKv::carve(a, sc.kv, i.length as usize, d)?)
                    .map_err(|_| ArenaError::Overflow)?;
            }
        }
        let mut cross_kv = Vec::new();
        for _ in 0..cfg.nlayers {
            cross_kv
                .push(LayerKv::carve(a, sc.kv, n, d)?)
                .map_err(|_| ArenaError::Overflow)?;
        }
        Ok(Stale {
            input_kv,
            cross_kv,
            latent: a.f32(n.checked_mul(d).ok_or(ArenaError::Overflow)?)?,
            ipos: a.u32(n)?,
            xpos: a.u32(n)?,
            head: [0; MAX_INPUTS],
            since: 0,
        })
    }

    /// Slots in window order again (after a whole recomputation).
    pub fn reset_slots(&mut self, cfg: &TransflowerConfig) {
        let mut off = 0;
        for (i, c) in cfg.inputs().iter().enumerate() {
            let l = c.length as usize;
            for j in 0..l {
                self.ipos[off + j] = j as u32;
                self.xpos[off + j] = (off + j) as u32;
            }
            self.head[i] = 0;
            off += l;
        }
    }

    /// Input `i` (window rows L at latent offset `off`) moves one row on:
    /// returns the slot its newest row takes (the oldest one's).
    pub fn slide(&mut self, i: usize, off: usize, l: usize) -> usize {
        let slot = self.head[i];
        self.head[i] = (slot + 1) % l.max(1);
        for j in 0..l {
            let p = (j + l - self.head[i]) % l;
            self.ipos[off + j] = p as u32;
            self.xpos[off + j] = (off + p) as u32;
        }
        slot
    }

    /// The cross-modal slot of latent position `p`.
    pub fn slot_of(&self, cfg: &TransflowerConfig, p: usize) -> usize {
        let mut off = 0;
        for (i, c) in cfg.inputs().iter().enumerate() {
            let l = c.length as usize;
            if p < off + l {
                return off + (self.head[i] + p - off) % l;
            }
            off += l;
        }
        p
    }
}

/// Everything a session keeps.
pub struct State<'s> {
    /// One per input (empty for the output modality and a label).
    pub feeds: Vec<Feed<'s>, MAX_INPUTS>,
    /// (L_out, C): the output modality's window (seed rows, then frames).
    pub window: &'s mut [f32],
    /// (L_out, C): the seed, for `reset`.
    pub seed: &'s mut [f32],
    /// (P, C): frames made and not pulled, a ring.
    pub pending: &'s mut [f32],
    pub pend_head: usize,
    pub pend_len: usize,
    /// (C, H): the step's base sample.
    pub z: &'s mut [f32],
    /// (H, C): the step's sampled frames.
    pub frames: &'s mut [f32],
    pub stale: Option<Stale<'s>>,
}

/// Rows input `i` must hold for a step: its window, and for the last input
/// the longest window (R's step count).
pub fn need_rows(cfg: &TransflowerConfig, i: usize) -> usize {
    let l = cfg.inputs[i].length as usize;
    if i + 1 == cfg.inputs().len() {
        l.max(cfg.max_window())
    } else {
        l
    }
}

/// Whether input `i` is fed by `push` (a continuous input other than the output).
pub fn is_fed(cfg: &TransflowerConfig, i: usize) -> bool {
    i != cfg.output as usize && !cfg.inputs[i].is_discrete()
}

impl<'s> State<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &TransflowerConfig,
        sc: &SessionConfig,
    ) -> Result<Self, ArenaError> {
        let c = cfg.channels();
        let lc = (cfg.output_input().length as usize)
            .checked_mul(c)
            .ok_or(ArenaError::Overflow)?;
        let ch = c
            .checked_mul(cfg.output_length as usize)
            .ok_or(ArenaError::Overflow)?;
        let mut feeds = Vec::new();
        for (i, ic) in cfg.inputs().iter().enumerate() {
            let cap = if is_fed(cfg, i) {
                need_rows(cfg, i) + sc.input_buffer_rows as usize
            } else {
                0
            };
            feeds
                .push(Feed::carve(a, cap, ic.dim as usize)?)
                .map_err(|_| ArenaError::Overflow)?;
        }
        Ok(State {
            feeds,
            window: a.f32(lc)?,
            seed: a.f32(lc)?,
            pending: a.f32(
                (sc.pending_frames as usize)
                    .checked_mul(c)
                    .ok_or(ArenaError::Overflow)?,
            )?,
            pend_head: 0,
            pend_len: 0,
            z: a.f32(ch)?,
            frames: a.f32(ch)?,
            stale: if sc.stale() {
                Some(Stale::carve(a, cfg, sc)?)
            } else {
                None
            },
        })
    }
}
