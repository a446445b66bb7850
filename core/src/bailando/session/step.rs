//! One step of several Bailando sessions at once: the GPT's new window row
//! of every session in one pass over the weights (`GptCache::append_many`),
//! the heads, the sampler, and the streaming VQ decoders that turn tokens
//! into frames. A session alone runs the same code as a batch of one.
//!
//! Step `k` of a session reads token `k` (up, down) and music row `k + 1`
//! in window slot `k - lo` (`lo` = `window_start(k, m, shift)`, positions
//! from 0 in every window, as R) and makes token `k + 1`.

use heapless::Vec;

use crate::bailando::config::{DOWN_JOINTS, N_STREAMS, POSE_DIM, UP_JOINTS};
use crate::bailando::model::Model;
use crate::bailando::session::config::window_rows;
use crate::bailando::session::state::{StepScratch, PREFILL_CHUNK};
use crate::bailando::session::Session;
use crate::error::Error;
use crate::kernels::{layernorm, linear};
use crate::nn::gpt_cache::{GptCache, GptItem, MAX_BATCH, MAX_ITEMS};
use crate::nn::quantizer::dequantise;
use crate::nn::stream_conv::StackW;
use crate::nn::window::{next_window, window_start};

/// The index of the session an error is about, and the error.
pub type BatchError = (usize, Error);

fn at(i: usize) -> impl Fn(Error) -> BatchError {
    move |e| (i, e)
}

/// The (3, C) input rows of token row `j` at window slot `p`: the music
/// row through `cond_emb`, the two token embeddings, each plus its
/// stream's position row `s * block_size + p`.
fn embed_row(
    model: &Model<'_>,
    tok: &[u32],
    music: &[f32],
    p: usize,
    x: &mut [f32],
) -> Result<(), Error> {
    let g = &model.cfg.gpt;
    let c = g.n_embd as usize;
    let bs = g.block_size as usize;
    linear(
        music,
        &model.gpt.cond_emb.w,
        model.gpt.cond_emb.b,
        &mut x[..c],
    );
    for (j, table) in model.gpt.tok_emb.iter().enumerate() {
        let t = tok[j];
        if t as usize >= table.rows() {
            return Err(Error::Token {
                stream: j as u8,
                token: t,
                vocab: table.rows() as u32,
            });
        }
        table.row_into(t as usize, &mut x[(1 + j) * c..(2 + j) * c]);
    }
    for s in 0..N_STREAMS {
        let pos = &model.gpt.pos_emb[(s * bs + p) * c..(s * bs + p + 1) * c];
        for (a, b) in x[s * c..(s + 1) * c].iter_mut().zip(pos) {
            *a += b;
        }
    }
    Ok(())
}

/// Rows `j` of `x` (n, 3C) for the session's tokens `from..to` at their
/// slots of the window starting at `lo`.
fn embed_rows(
    s: &Session<'_>,
    lo: usize,
    from: usize,
    to: usize,
    x: &mut [f32],
) -> Result<(), Error> {
    let w = N_STREAMS * s.model.cfg.gpt.n_embd as usize;
    for (i, j) in (from..to).enumerate() {
        let tok = s.st.toks.row(j)?;
        let music = s.music_row(j + 1)?;
        embed_row(s.model, tok, music, j - lo, &mut x[i * w..(i + 1) * w])?;
    }
    Ok(())
}

/// A ready session's GPT rows in one step: window rows `from..=k` go to
/// its window's cache, and with the spread schedule `ahead` = (first row,
/// rows, window start) of the next window's to the second cache.
#[derive(Clone, Copy)]
struct Rows {
    from: usize,
    ahead: Option<(usize, usize, usize)>,
}

/// Steps every ready session of `ss` once (at most `sc.n` of them; the
/// rest wait for the next call) and decodes the frames that became final.
/// Returns how many sessions stepped.
pub fn step_many(
    ss: &mut [&mut Session<'_>],
    sc: &mut StepScratch<'_>,
) -> Result<usize, BatchError> {
    let mut ready: Vec<usize, MAX_BATCH> = Vec::new();
    for (i, s) in ss.iter().enumerate() {
        if ready.len() < sc.n.min(MAX_BATCH) && s.can_step() {
            ready.push(i).map_err(|_| (i, Error::State))?;
        }
    }
    let Some(&first) = ready.first() else {
        return Ok(0);
    };
    let model = ss[first].model;
    for &i in ready.iter().skip(1) {
        if !core::ptr::eq(ss[i].model, model) {
            return Err((i, Error::State));
        }
    }
    let g = &model.cfg.gpt;
    let c = g.n_embd as usize;
    let nh = g.n_head as usize;
    let m = window_rows(&model.cfg);
    let w = N_STREAMS * c;
    let blocks = || model.gpt.base.iter().chain(model.gpt.head.iter());

    // Each ready session's rows this step (its window's own cache is the
    // first, the next window's the second, [`GptCache::enter_window`]).
    let mut plan: Vec<Rows, MAX_BATCH> = Vec::new();
    for &i in ready.iter() {
        let s = &mut *ss[i];
        let k = s.steps;
        let shift = s.cfg.shift as usize;
        let lo = window_start(k, m, shift);
        GptCache::enter_window(&mut s.st.gpt, lo).map_err(at(i))?;
        // Rows of this window not yet in its cache (all of them after a jump
        // without the spread, the rest of them where the spread fell short).
        let from = lo + s.st.gpt[0].rows();
        if from > k {
            return Err((i, Error::State));
        }
        let ahead = match s.st.gpt.get_mut(1) {
            Some(next) => {
                let (k2, lo2) = next_window(k, m, shift);
                next.ahead_share(k, k2, lo2).map(|(have, q)| {
                    let q = q.min(PREFILL_CHUNK);
                    s.spread_rows += q;
                    (have, q, lo2)
                })
            }
            None => None,
        };
        plan.push(Rows { from, ahead })
            .map_err(|_| (i, Error::State))?;
    }

    // Missing window rows ride with the new rows in one pass over the
    // weights while the scratch holds them all (a session's own scratch
    // holds a whole re-prefill); a session whose rows do not fit runs
    // them first, alone, in chunks of the scratch's size. The same numbers
    // either way: rows attend the rows cached before them and themselves.
    let cap = sc.x.len() / w;
    let mut main: usize = plan
        .iter()
        .map(|p| 1 + p.ahead.map_or(0, |(_, q, _)| q))
        .sum();
    for (&i, p) in ready.iter().zip(plan.iter_mut()) {
        let s = &mut *ss[i];
        let k = s.steps;
        let mut from = p.from;
        if main + (k - from) <= cap {
            main += k - from;
            continue;
        }
        let lo = s.st.gpt[0].window_start().ok_or((i, Error::State))?;
        while from < k {
            let to = (from + cap).min(k);
            embed_rows(s, lo, from, to, &mut sc.x[..(to - from) * w]).map_err(at(i))?;
            let mut items = [GptItem {
                cache: &mut s.st.gpt[0],
                rows: to - from,
                need_output: false,
            }];
            GptCache::append_many(
                blocks(),
                nh,
                2,
                &mut items,
                &mut sc.x[..(to - from) * w],
                &mut sc.block,
            )
            .map_err(at(i))?;
            s.prefilled += to - from;
            from = to;
        }
        p.from = from;
    }

    // The new row of every ready session (and its next window's rows),
    // through the GPT together.
    let mut rows = 0;
    for (&i, &Rows { from, ahead }) in ready.iter().zip(plan.iter()) {
        let s = &mut *ss[i];
        let k = s.steps;
        let lo = s.st.gpt[0].window_start().ok_or((i, Error::State))?;
        let n_new = k + 1 - from;
        embed_rows(s, lo, from, k + 1, &mut sc.x[rows * w..(rows + n_new) * w]).map_err(at(i))?;
        s.prefilled += n_new - 1;
        rows += n_new;
        if let Some((from, q, lo2)) = ahead {
            embed_rows(s, lo2, from, from + q, &mut sc.x[rows * w..(rows + q) * w])
                .map_err(at(i))?;
            rows += q;
        }
    }
    {
        let mut items: Vec<GptItem<'_, '_>, MAX_ITEMS> = Vec::new();
        let mut p = 0;
        for (i, s) in ss.iter_mut().enumerate() {
            if !ready.contains(&i) {
                continue;
            }
            let Rows { from, ahead } = plan[p];
            p += 1;
            let (a, b) = s.st.gpt.split_at_mut(1);
            let (c, n) = (&mut a[0], b.first_mut());
            let n_new = s.steps + 1 - from;
            items
                .push(GptItem {
                    cache: c,
                    rows: n_new,
                    need_output: true,
                })
                .map_err(|_| (i, Error::State))?;
            if let (Some((_, q, _)), Some(n)) = (ahead, n) {
                items
                    .push(GptItem {
                        cache: n,
                        rows: q,
                        need_output: false,
                    })
                    .map_err(|_| (i, Error::State))?;
            }
        }
        GptCache::append_many(
            blocks(),
            nh,
            2,
            &mut items,
            &mut sc.x[..rows * w],
            &mut sc.block,
        )
        .map_err(at(first))?;
    }
    let n = ready.len();

    // Heads and sampling: rows 2j, 2j + 1 of x are session j's up and down.
    let vu = g.vocab[0] as usize;
    for (j, &i) in ready.iter().enumerate() {
        let s = &mut *ss[i];
        let mut tok = [0u32; 2];
        for h in 0..2 {
            let row = &sc.x[(2 * j + h) * c..(2 * j + h + 1) * c];
            layernorm(row, model.gpt.ln_f.w, model.gpt.ln_f.b, sc.ln);
            let logits = if h == 0 {
                &mut sc.logits[..vu]
            } else {
                &mut sc.logits[vu..]
            };
            linear(sc.ln, &model.gpt.heads[h], None, logits);
            tok[h] = s.cfg.sampling.choose(logits, &mut s.rng);
        }
        s.st.toks.push(&tok).map_err(at(i))?;
        s.steps += 1;
        decode(s, sc).map_err(at(i))?;
    }
    Ok(n)
}

/// Feeds the session's tokens not yet in its decoders one at a time,
/// assembling the frames of every token that became final as soon as it
/// is (token q's frames from the tokens `..=q + d`, S's truncated prefix).
/// Where a token's push makes frames final, each decoder computes them in
/// the same pass over its weights as the push (`push_output`).
pub(super) fn decode(s: &mut Session<'_>, sc: &mut StepScratch<'_>) -> Result<(), Error> {
    let model = s.model;
    let hop = model.cfg.hop();
    loop {
        while s.frames_final() {
            frames_of(s, sc)?;
        }
        if s.dec_fed > s.steps {
            return Ok(());
        }
        let tok = s.st.toks.row(s.dec_fed)?;
        let tok = [tok[0], tok[1]];
        s.dec_fed += 1;
        let fused = s.frames_final();
        s.dec_fed -= 1;
        let t = s.decoded;
        let (up, rest) = s.st.dec_out.split_at_mut(hop * UP_JOINTS.len() * 3);
        let (down, vel) = rest.split_at_mut(hop * DOWN_JOINTS.len() * 3);
        for (h, out) in [up, down].into_iter().enumerate() {
            let vq = &model.parts[h];
            let emb = vq.cfg.emb_width as usize;
            dequantise(&vq.codebook, &tok[h..h + 1], h as u8, &mut sc.feat[..emb])?;
            let feat = &sc.feat[..emb];
            let dec = StackW::Decoder(&vq.pos);
            if fused {
                s.st.dec[h].push_output(dec, feat, t, hop, &mut sc.conv, out)?;
            } else {
                s.st.dec[h].push(dec, feat, &mut sc.conv)?;
            }
            if h == 1 {
                let root = StackW::Decoder(&model.root);
                if fused {
                    s.st.dec[2].push_output(root, feat, t, hop, &mut sc.conv, &mut vel[..])?;
                } else {
                    s.st.dec[2].push(root, feat, &mut sc.conv)?;
                }
            }
        }
        s.dec_fed += 1;
        if fused {
            assemble(s)?;
        }
    }
}

/// The `hop` frames of the session's next token from its decoders'
/// current prefix, assembled as R's `decode` does, into the pending ring.
fn frames_of(s: &mut Session<'_>, sc: &mut StepScratch<'_>) -> Result<(), Error> {
    let model = s.model;
    let hop = model.cfg.hop();
    let t = s.decoded;
    let st = &mut s.st;
    let (up, rest) = st.dec_out.split_at_mut(hop * UP_JOINTS.len() * 3);
    let (down, vel) = rest.split_at_mut(hop * DOWN_JOINTS.len() * 3);
    for (h, out) in [up, down].into_iter().enumerate() {
        let w = StackW::Decoder(&model.parts[h].pos);
        st.dec[h].output(w, t, hop, &mut sc.conv, out)?;
    }
    st.dec[2].output(StackW::Decoder(&model.root), t, hop, &mut sc.conv, vel)?;
    assemble(s)
}

/// The frames of the next token from the three decoders' outputs in
/// `dec_out` (up, down, root velocity) as R's `decode` assembles them (the
/// down half's pelvis slot replaced by the integrated root velocity, added
/// to every joint), into the pending ring.
fn assemble(s: &mut Session<'_>) -> Result<(), Error> {
    let hop = s.model.cfg.hop();
    let st = &mut s.st;
    let frames = &mut st.frames[..hop * POSE_DIM];
    let (up, rest) = st.dec_out.split_at(hop * UP_JOINTS.len() * 3);
    let (down, vel) = rest.split_at(hop * DOWN_JOINTS.len() * 3);
    for (joints, out) in [(&UP_JOINTS[..], up), (&DOWN_JOINTS[..], down)] {
        let w = joints.len() * 3;
        for f in 0..hop {
            for (i, &j) in joints.iter().enumerate() {
                let j = j as usize;
                frames[f * POSE_DIM + 3 * j..][..3].copy_from_slice(&out[f * w + 3 * i..][..3]);
            }
        }
    }
    for f in 0..hop {
        let r = s.root;
        let row = &mut frames[f * POSE_DIM..(f + 1) * POSE_DIM];
        row[..3].copy_from_slice(&r);
        for j in 1..POSE_DIM / 3 {
            for d in 0..3 {
                row[3 * j + d] += r[d];
            }
        }
        for d in 0..3 {
            s.root[d] += vel[f * 3 + d];
        }
    }
    for f in 0..hop {
        st.pending.push(&frames[f * POSE_DIM..(f + 1) * POSE_DIM])?;
    }
    s.decoded += hop;
    Ok(())
}
