//! The streaming stack: push columns, settle them unit by unit, and read
//! outputs (settled, or the tail cone computed on request).

// Fixed-capacity vectors (no allocation: core has no alloc crate).
use heapless::Vec;

use super::*;

/// State of one streaming stack: a ring of settled input columns per unit
/// and a ring of settled outputs, carved from an arena.
pub struct StreamStack<'s> {
    plan: StackPlan,
    /// Ring `u`: (plan.ring[u], c_in of unit u) settled inputs of unit `u`.
    rings: Vec<ColRing<'s>, MAX_UNITS>,
    /// (plan.out_ring, c_out of the last unit) settled outputs.
    out: ColRing<'s>,
    counts: Counts,
    pushed: usize,
    /// Output channels of the weights pushed with (0 before the first push).
    out_ch: usize,
    /// Scratch this stack's pushes need (checked before a push mutates).
    need: ScratchNeed,
    /// A push failed half-way: every call errors until `reset`.
    broken: bool,
}

impl<'s> StreamStack<'s> {
    /// A stack of `kind` for `cfg`, serving requests `lag` pushes behind the
    /// newest (encoder: feature `q` after push `q + lag + 1`; decoder:
    /// frames `[hop q, hop q + hop)` after push `q + lag + 1`). Any lag
    /// works; requests with a smaller lag also work (the shared scratch
    /// covers `0..=future_max`), older ones than `lag` may error.
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &VqConfig,
        kind: StackKind,
        lag: usize,
    ) -> Result<Self, ArenaError> {
        let plan = StackPlan::new(cfg, kind, lag).ok_or(ArenaError::Overflow)?;
        let mut rings = Vec::new();
        for (u, unit) in plan.geometry.units().iter().enumerate() {
            let ring = ColRing::carve(a, plan.ring[u], unit.c_in)?;
            rings.push(ring).map_err(|_| ArenaError::Overflow)?;
        }
        let last = plan.geometry.units()[plan.geometry.n_units - 1];
        let out = ColRing::carve(a, plan.out_ring, last.c_out)?;
        let need = plan.scratch_need();
        Ok(StreamStack {
            plan,
            rings,
            out,
            counts: Counts::ZERO,
            pushed: 0,
            out_ch: 0,
            need,
            broken: false,
        })
    }

    /// Back to zero columns pushed (no allocation).
    pub fn reset(&mut self) {
        for r in self.rings.iter_mut() {
            r.n = 0;
        }
        self.out.n = 0;
        self.counts = Counts::ZERO;
        self.pushed = 0;
        self.out_ch = 0;
        self.broken = false;
    }

    /// Pushes so far.
    pub fn pushed(&self) -> usize {
        self.pushed
    }

    /// Output columns of the stack on the prefix pushed so far.
    pub fn len(&self) -> usize {
        self.counts.n_out[self.plan.geometry.n_units - 1]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Output columns that no further push can change.
    pub fn settled(&self) -> usize {
        self.counts.set[self.plan.geometry.n_units - 1]
    }

    /// The sizes this stack was carved with.
    pub fn plan(&self) -> &StackPlan {
        &self.plan
    }

    fn in_buffer(&self) -> Buffer {
        match self.plan.geometry.kind {
            StackKind::Encoder => Buffer::Pose,
            StackKind::Decoder => Buffer::Features,
        }
    }

    fn out_buffer(&self) -> Buffer {
        match self.plan.geometry.kind {
            StackKind::Encoder => Buffer::Features,
            StackKind::Decoder => Buffer::Output,
        }
    }

    /// The weights of every unit, checked against the geometry.
    fn bind<'r, 'a>(&self, w: StackW<'r, 'a>) -> Result<Vec<UnitW<'r, 'a>, MAX_UNITS>, Error> {
        let mut v: Vec<UnitW<'r, 'a>, MAX_UNITS> = Vec::new();
        let bad = Error::Length {
            buffer: self.out_buffer(),
            len: 0,
            expected: 0,
        };
        match (w, self.plan.geometry.kind) {
            (StackW::Encoder(e), StackKind::Encoder) => {
                for (conv, res) in e.stages.iter() {
                    v.push(UnitW::Conv(conv)).map_err(|_| bad.clone())?;
                    for b in res.iter() {
                        v.push(UnitW::Res(b)).map_err(|_| bad.clone())?;
                    }
                }
                v.push(UnitW::Conv(&e.out)).map_err(|_| bad.clone())?;
            }
            (StackW::Decoder(d), StackKind::Decoder) => {
                v.push(UnitW::Conv(&d.input)).map_err(|_| bad.clone())?;
                for (res, up) in d.stages.iter() {
                    for b in res.iter() {
                        v.push(UnitW::Res(b)).map_err(|_| bad.clone())?;
                    }
                    v.push(UnitW::ConvT(up)).map_err(|_| bad.clone())?;
                }
                v.push(UnitW::Conv(&d.out)).map_err(|_| bad.clone())?;
            }
            _ => return Err(bad),
        }
        let g = &self.plan.geometry;
        if v.len() != g.n_units {
            return Err(Error::Length {
                buffer: self.out_buffer(),
                len: v.len(),
                expected: g.n_units,
            });
        }
        for (u, (uw, unit)) in v.iter().zip(g.units()).enumerate() {
            if !uw.fits(unit, g.inner, u + 1 == g.n_units) {
                return Err(Error::Length {
                    buffer: self.out_buffer(),
                    len: uw.c_out(),
                    expected: unit.c_out,
                });
            }
        }
        Ok(v)
    }

    /// Appends one push of input columns: encoder `cols` = (hop,
    /// in_channels) frames; decoder (1, emb_width) one dequantised code.
    /// On an error before any state changed the stack is unchanged; an
    /// error half-way (impossible with the planned sizes) leaves it broken
    /// until [`StreamStack::reset`].
    pub fn push(
        &mut self,
        w: StackW<'_, '_>,
        cols: &[f32],
        s: &mut StreamScratch<'_>,
    ) -> Result<(), Error> {
        Self::push_many(&mut [self], w, &[cols], s)
    }

    /// [`StreamStack::push`] of `cols[i]` into `stacks[i]` for several
    /// stacks of one geometry (the same stack of several sessions), every
    /// unit computed for all of them at once: one read of its weights per
    /// kernel tile instead of one per stack. Each stack ends bit for bit as
    /// after its own push (row-independent kernels). `s` must hold the
    /// stacks' needs together ([`StreamScratch::carve`] for `n` stacks).
    pub fn push_many(
        stacks: &mut [&mut StreamStack<'s>],
        w: StackW<'_, '_>,
        cols: &[&[f32]],
        s: &mut StreamScratch<'_>,
    ) -> Result<(), Error> {
        let Some((units, oc)) = Self::check_push(stacks, w, cols, s)? else {
            return Ok(());
        };
        for st in stacks.iter_mut() {
            st.broken = true;
        }
        Self::settle(stacks, &units, cols, None, s)?;
        Self::pushed_one(stacks, oc);
        Ok(())
    }

    /// [`StreamStack::push`] then [`StreamStack::output`] of `[t, t + n)`,
    /// each unit's weights read once ([`StreamStack::push_output_many`]).
    pub fn push_output(
        &mut self,
        w: StackW<'_, '_>,
        cols: &[f32],
        t: usize,
        n: usize,
        s: &mut StreamScratch<'_>,
        out: &mut [f32],
    ) -> Result<(), Error> {
        Self::push_output_many(&mut [self], w, &[cols], &[t], n, s, &mut [out])
    }

    /// [`StreamStack::push_many`], then [`StreamStack::output_many`] of
    /// columns `[ts[i], ts[i] + n)` of `stacks[i]` on the prefix after the
    /// push into `outs[i]`, with each unit's tail computed right before
    /// its newly settled columns, while the unit's weights are in cache
    /// (the two calls read every unit's weights twice). Bit for bit the two
    /// calls; everything both check is checked before anything changes.
    pub fn push_output_many(
        stacks: &mut [&mut StreamStack<'s>],
        w: StackW<'_, '_>,
        cols: &[&[f32]],
        ts: &[usize],
        n: usize,
        s: &mut StreamScratch<'_>,
        outs: &mut [&mut [f32]],
    ) -> Result<(), Error> {
        let Some((units, oc)) = Self::check_push(stacks, w, cols, s)? else {
            return Ok(());
        };
        if ts.len() != stacks.len() || outs.len() != stacks.len() {
            return Err(Error::Length {
                buffer: stacks[0].out_buffer(),
                len: ts.len().min(outs.len()),
                expected: stacks.len(),
            });
        }
        let g = &stacks[0].plan.geometry;
        let last = g.n_units - 1;
        let expected = n.checked_mul(oc).ok_or(Error::Length {
            buffer: stacks[0].out_buffer(),
            len: n,
            expected: usize::MAX,
        })?;
        // Per stack: the unsettled columns [a, end) to compute after the push.
        let mut want: Vec<Option<(usize, usize)>, MAX_STACKS> = Vec::new();
        for ((st, &t), out) in stacks.iter().zip(ts).zip(outs.iter()) {
            let mut after = st.counts;
            after.advance(g);
            let (len, set) = (after.n_out[last], after.set[last]);
            let end = t.saturating_add(n);
            if out.len() != expected {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: out.len(),
                    expected,
                });
            }
            if end > len {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: end,
                    expected: len,
                });
            }
            // Settled columns come from the output ring after the push.
            let oldest = set.saturating_sub(st.out.cap);
            if t < set && t < oldest {
                return Err(evicted(t, oldest, set));
            }
            want.push((end > set).then(|| (t.max(set), end)))
                .map_err(|_| Error::State)?;
        }
        for st in stacks.iter_mut() {
            st.broken = true;
        }
        let (tail, at) = Self::settle(stacks, &units, cols, Some(&want), s)?;
        for (i, (st, out)) in stacks.iter().zip(outs.iter_mut()).enumerate() {
            let (t, set) = (ts[i], st.settled());
            for (j, o) in (t..(t + n).min(set)).zip(out.chunks_exact_mut(oc)) {
                o.copy_from_slice(&st.out.col(j)?[..oc]);
            }
            if let Some((a, end)) = want[i] {
                let src = tail
                    .get(at[i] * oc..(at[i] + end - a) * oc)
                    .ok_or(Error::State)?;
                out[(a - t) * oc..].copy_from_slice(src);
            }
        }
        Self::pushed_one(stacks, oc);
        Ok(())
    }

    /// What a push checks before it changes anything; the bound weights
    /// and the last unit's output channels (`None`: no stacks).
    #[allow(clippy::type_complexity)]
    fn check_push<'r, 'a>(
        stacks: &[&mut StreamStack<'s>],
        w: StackW<'r, 'a>,
        cols: &[&[f32]],
        s: &StreamScratch<'_>,
    ) -> Result<Option<(Vec<UnitW<'r, 'a>, MAX_UNITS>, usize)>, Error> {
        let units = Self::check_many(stacks.iter().map(|st| &**st), w, s)?;
        let Some(first) = stacks.first() else {
            return Ok(None);
        };
        if cols.len() != stacks.len() {
            return Err(Error::Length {
                buffer: first.in_buffer(),
                len: cols.len(),
                expected: stacks.len(),
            });
        }
        let g = &first.plan.geometry;
        let expected = g.in_per_push * g.units[0].c_in;
        if let Some(c) = cols.iter().find(|c| c.len() != expected) {
            return Err(Error::Length {
                buffer: first.in_buffer(),
                len: c.len(),
                expected,
            });
        }
        let oc = units[g.n_units - 1].c_out();
        Ok(Some((units, oc)))
    }

    /// Every stack has taken one more push (no longer broken).
    fn pushed_one(stacks: &mut [&mut StreamStack<'s>], oc: usize) {
        for st in stacks.iter_mut() {
            st.out_ch = oc;
            st.pushed += 1;
            st.broken = false;
        }
    }

    /// The checks every `*_many` call makes before it changes anything:
    /// at most [`MAX_STACKS`] stacks, none broken, one geometry, weights
    /// that fit it (and the output channels of earlier pushes), scratch for
    /// all of them together. Returns the bound weights.
    fn check_many<'r, 'a, 'x>(
        stacks: impl Iterator<Item = &'x StreamStack<'s>> + Clone,
        w: StackW<'r, 'a>,
        s: &StreamScratch<'_>,
    ) -> Result<Vec<UnitW<'r, 'a>, MAX_UNITS>, Error>
    where
        's: 'x,
    {
        let Some(first) = stacks.clone().next() else {
            return Ok(Vec::new());
        };
        let units = first.bind(w)?;
        let oc = units[first.plan.geometry.n_units - 1].c_out();
        let mut need = ScratchNeed::default();
        for (i, st) in stacks.enumerate() {
            if st.broken || i >= MAX_STACKS || st.plan.geometry != first.plan.geometry {
                return Err(Error::State);
            }
            if st.out_ch != 0 && oc != st.out_ch {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: oc,
                    expected: st.out_ch,
                });
            }
            need = need.plus(st.need);
        }
        if !need.fits(s) {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: s.g.len(),
                expected: need.g,
            });
        }
        Ok(units)
    }

    /// The push proper: new input columns into ring 0 of every stack, then
    /// unit after unit every stack's newly settled outputs (one computation
    /// for all stacks) into the next ring. With `want` (per stack, the
    /// unsettled output columns `[a, b)` of the last unit wanted after the
    /// push, as [`StreamStack::output_many`] computes them), each unit's
    /// tail is computed right before its settled outputs, while its weights
    /// are in cache; the tails are returned as by [`StreamStack::tails`].
    #[allow(clippy::type_complexity)]
    fn settle<'x>(
        stacks: &mut [&mut StreamStack<'s>],
        units: &[UnitW<'_, '_>],
        cols: &[&[f32]],
        want: Option<&[Option<(usize, usize)>]>,
        s: &'x mut StreamScratch<'_>,
    ) -> Result<(&'x [f32], [usize; MAX_STACKS]), Error> {
        let g = stacks[0].plan.geometry.clone();
        let mut counts: Vec<Counts, MAX_STACKS> = Vec::new();
        let mut new: Vec<[Span; MAX_UNITS], MAX_STACKS> = Vec::new();
        for (st, c) in stacks.iter_mut().zip(cols) {
            let mut k = st.counts;
            new.push(k.advance(&g)).map_err(|_| Error::State)?;
            counts.push(k).map_err(|_| Error::State)?;
            for col in c.chunks_exact(st.rings[0].ch) {
                st.rings[0].push(col)?;
            }
        }
        let need = match want {
            Some(w) => Self::cones(&g, &counts, w)?,
            None => Vec::new(),
        };
        let u0 = Self::first_tail_unit(&g, &need);
        let StreamScratch {
            g: gs,
            h,
            r,
            ta,
            tb,
            tile,
        } = s;
        // prev: tails of the unit below (stack i's from row prev_at[i]);
        // cur: this unit's; settled outputs go through `prev` once it is dead.
        let (mut prev, mut cur): (&'x mut [f32], &'x mut [f32]) = (&mut ta[..], &mut tb[..]);
        let (mut prev_at, mut cur_at) = ([0usize; MAX_STACKS], [0usize; MAX_STACKS]);
        for (u, uw) in units.iter().enumerate() {
            let tail = u0.is_some_and(|u0| u >= u0);
            if tail {
                let w = Work { g: gs, h, r, tile };
                Self::tail_unit(
                    stacks,
                    &counts,
                    &need,
                    u,
                    uw,
                    prev,
                    &prev_at,
                    cur,
                    &mut cur_at,
                    w,
                )?;
            }
            let w = Work { g: gs, h, r, tile };
            Self::settle_unit(stacks, &counts, &new, u, uw, prev, w)?;
            if tail {
                core::mem::swap(&mut prev, &mut cur);
                core::mem::swap(&mut prev_at, &mut cur_at);
            }
        }
        for (st, c) in stacks.iter_mut().zip(counts) {
            st.counts = c;
        }
        Ok((prev, prev_at))
    }

    /// Unit `u`'s newly settled outputs `new[i][u]` of every stack, computed
    /// together into `y` (scratch) and pushed into the next ring (the
    /// output ring for the last unit).
    #[allow(clippy::too_many_arguments)]
    fn settle_unit(
        stacks: &mut [&mut StreamStack<'s>],
        counts: &[Counts],
        new: &[[Span; MAX_UNITS]],
        u: usize,
        uw: &UnitW<'_, '_>,
        y: &mut [f32],
        w: Work<'_>,
    ) -> Result<(), Error> {
        let g = &stacks[0].plan.geometry;
        let unit = g.units[u];
        let last = g.n_units - 1;
        // (stack, its job); the jobs' inputs gathered one after another into w.g.
        let mut jobs: Vec<(usize, Job), MAX_STACKS> = Vec::new();
        let (mut xo, mut yo) = (0, 0);
        for (i, st) in stacks.iter().enumerate() {
            let Span { lo, hi } = new[i][u];
            if lo >= hi {
                continue;
            }
            let (g0, g1) = unit.gather_span(lo, hi, counts[i].n_in(u));
            let ring = &st.rings[u];
            if ring.n != counts[i].set_in(u) {
                return Err(evicted(g1, g0, ring.n));
            }
            let x = cols_at(w.g, xo, g1 - g0, unit.c_in)?;
            for (c, xc) in (g0..g1).zip(x.chunks_exact_mut(unit.c_in)) {
                xc.copy_from_slice(ring.col(c)?);
            }
            jobs.push((
                i,
                Job {
                    a: lo,
                    g0,
                    n_in: g1 - g0,
                    n_out: hi - lo,
                },
            ))
            .map_err(|_| Error::State)?;
            xo += g1 - g0;
            yo += hi - lo;
        }
        if jobs.is_empty() {
            return Ok(());
        }
        let oc = uw.c_out();
        let js: Vec<Job, MAX_STACKS> = jobs.iter().map(|&(_, j)| j).collect();
        let y = first(y, yo * oc)?;
        uw.run(&unit, &js, first(w.g, xo * unit.c_in)?, y, w.h, w.r, w.tile)?;
        let mut rows = y.chunks_exact(oc);
        for &(i, j) in jobs.iter() {
            let st = &mut *stacks[i];
            let next = if u == last {
                &mut st.out
            } else {
                &mut st.rings[u + 1]
            };
            for c in rows.by_ref().take(j.n_out) {
                next.push(c)?;
            }
        }
        Ok(())
    }

    /// Output columns `[t, t + n)` of the stack on the prefix pushed so far
    /// into `out` (n, C): encoder features (C = emb_width), decoder frames
    /// (C = the decoder's output channels). Settled columns come from the
    /// output ring (bit-identical to the full conv); unsettled ones are
    /// computed now from the tail cone. Errors if `t + n` exceeds the
    /// prefix's output, or a column is older than the output ring holds.
    pub fn output(
        &self,
        w: StackW<'_, '_>,
        t: usize,
        n: usize,
        s: &mut StreamScratch<'_>,
        out: &mut [f32],
    ) -> Result<(), Error> {
        Self::output_many(&[self], w, &[t], n, s, &mut [out])
    }

    /// [`StreamStack::output`] of columns `[ts[i], ts[i] + n)` of
    /// `stacks[i]` into `outs[i]` for several stacks of one geometry, the
    /// tails of all of them computed together (one read of each unit's
    /// weights); bit for bit what each stack's own call gives.
    pub fn output_many(
        stacks: &[&StreamStack<'s>],
        w: StackW<'_, '_>,
        ts: &[usize],
        n: usize,
        s: &mut StreamScratch<'_>,
        outs: &mut [&mut [f32]],
    ) -> Result<(), Error> {
        let units = Self::check_many(stacks.iter().copied(), w, s)?;
        let Some(first) = stacks.first() else {
            return Ok(());
        };
        if ts.len() != stacks.len() || outs.len() != stacks.len() {
            return Err(Error::Length {
                buffer: first.out_buffer(),
                len: ts.len().min(outs.len()),
                expected: stacks.len(),
            });
        }
        let oc = units[first.plan.geometry.n_units - 1].c_out();
        let expected = n.checked_mul(oc).ok_or(Error::Length {
            buffer: first.out_buffer(),
            len: n,
            expected: usize::MAX,
        })?;
        // Per stack: the unsettled columns [a, end) still to compute, if any.
        let mut want: Vec<Option<(usize, usize)>, MAX_STACKS> = Vec::new();
        for ((st, &t), out) in stacks.iter().zip(ts).zip(outs.iter()) {
            if out.len() != expected {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: out.len(),
                    expected,
                });
            }
            let end = t.saturating_add(n);
            if end > st.len() {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: end,
                    expected: st.len(),
                });
            }
            let set = st.settled();
            want.push((end > set).then(|| (t.max(set), end)))
                .map_err(|_| Error::State)?;
        }
        for ((st, &t), out) in stacks.iter().zip(ts).zip(outs.iter_mut()) {
            let set = st.settled();
            for (j, o) in (t..(t + n).min(set)).zip(out.chunks_exact_mut(oc)) {
                o.copy_from_slice(&st.out.col(j)?[..oc]);
            }
        }
        if want.iter().any(Option::is_some) {
            let (tail, at) = Self::tails(stacks, &units, &want, s)?;
            for (i, out) in outs.iter_mut().enumerate() {
                if let Some((a, end)) = want[i] {
                    let src = tail
                        .get(at[i] * oc..(at[i] + end - a) * oc)
                        .ok_or(Error::State)?;
                    out[(a - ts[i]) * oc..].copy_from_slice(src);
                }
            }
        }
        Ok(())
    }

    /// Computes the unsettled outputs `want[i] = [a, b)` of the last unit
    /// of each stack through its tail cone, all stacks unit by unit
    /// together; returns them in a scratch buffer: stack `i`'s `(b - a,
    /// c_out)` rows from row `at[i]`.
    #[allow(clippy::type_complexity)]
    fn tails<'x>(
        stacks: &[&StreamStack<'s>],
        units: &[UnitW<'_, '_>],
        want: &[Option<(usize, usize)>],
        s: &'x mut StreamScratch<'_>,
    ) -> Result<(&'x [f32], [usize; MAX_STACKS]), Error> {
        let g = &stacks[0].plan.geometry;
        let mut counts: Vec<Counts, MAX_STACKS> = Vec::new();
        for st in stacks.iter() {
            counts.push(st.counts).map_err(|_| Error::State)?;
        }
        let need = Self::cones(g, &counts, want)?;
        let u0 = Self::first_tail_unit(g, &need).unwrap_or(g.n_units - 1);
        let StreamScratch {
            g: gs,
            h,
            r,
            ta,
            tb,
            tile,
        } = s;
        let (mut prev, mut cur): (&'x mut [f32], &'x mut [f32]) = (&mut ta[..], &mut tb[..]);
        let (mut prev_at, mut cur_at) = ([0usize; MAX_STACKS], [0usize; MAX_STACKS]);
        for (u, uw) in units.iter().enumerate().skip(u0) {
            let w = Work { g: gs, h, r, tile };
            Self::tail_unit(
                stacks,
                &counts,
                &need,
                u,
                uw,
                prev,
                &prev_at,
                cur,
                &mut cur_at,
                w,
            )?;
            core::mem::swap(&mut prev, &mut cur);
            core::mem::swap(&mut prev_at, &mut cur_at);
        }
        Ok((prev, prev_at))
    }

    /// The tail cone of every stack: per stack and unit, the unsettled
    /// outputs needed for `want[i]` (empty spans for `None`).
    fn cones(
        g: &Geometry,
        counts: &[Counts],
        want: &[Option<(usize, usize)>],
    ) -> Result<Vec<[Span; MAX_UNITS], MAX_STACKS>, Error> {
        let mut need: Vec<[Span; MAX_UNITS], MAX_STACKS> = Vec::new();
        for (c, w) in counts.iter().zip(want) {
            let cone = match *w {
                Some((a, b)) => c.cone(g, a, b),
                None => [Span::default(); MAX_UNITS],
            };
            need.push(cone).map_err(|_| Error::State)?;
        }
        Ok(need)
    }

    /// The first unit with a tail to compute in any stack's cone.
    fn first_tail_unit(g: &Geometry, need: &[[Span; MAX_UNITS]]) -> Option<usize> {
        (0..g.n_units).find(|&u| need.iter().any(|nd| !nd[u].is_empty()))
    }

    /// Unit `u`'s unsettled outputs `need[i][u]` of every stack into `cur`
    /// (stack i's rows from `cur_at[i]`): settled inputs from the unit's
    /// ring, unsettled ones from `prev`, the tails of unit `u - 1` (stack
    /// i's from row `prev_at[i]`).
    #[allow(clippy::too_many_arguments)]
    fn tail_unit<S: core::ops::Deref<Target = StreamStack<'s>>>(
        stacks: &[S],
        counts: &[Counts],
        need: &[[Span; MAX_UNITS]],
        u: usize,
        uw: &UnitW<'_, '_>,
        prev: &[f32],
        prev_at: &[usize; MAX_STACKS],
        cur: &mut [f32],
        cur_at: &mut [usize; MAX_STACKS],
        w: Work<'_>,
    ) -> Result<(), Error> {
        let unit = stacks[0].plan.geometry.units[u];
        let mut jobs: Vec<Job, MAX_STACKS> = Vec::new();
        let (mut xo, mut yo) = (0, 0);
        for (i, st) in stacks.iter().enumerate() {
            let Span { lo, hi } = need[i][u];
            if lo >= hi {
                continue;
            }
            let c = &counts[i];
            let (g0, g1) = unit.gather_span(lo, hi, c.n_in(u));
            let (set_in, ring) = (c.set_in(u), &st.rings[u]);
            let x = cols_at(w.g, xo, g1 - g0, unit.c_in)?;
            for (col, xc) in (g0..g1).zip(x.chunks_exact_mut(unit.c_in)) {
                if col < set_in {
                    xc.copy_from_slice(ring.col(col)?);
                } else {
                    // Unsettled input: tail of unit u-1, which covers [set_in, g1).
                    let below = if u > 0 {
                        need[i][u - 1]
                    } else {
                        Span::default()
                    };
                    let k = col.checked_sub(below.lo).filter(|_| col < below.hi);
                    let src = k.and_then(|k| {
                        prev.get((prev_at[i] + k) * unit.c_in..(prev_at[i] + k + 1) * unit.c_in)
                    });
                    xc.copy_from_slice(src.ok_or(evicted(col, set_in, c.n_in(u)))?);
                }
            }
            jobs.push(Job {
                a: lo,
                g0,
                n_in: g1 - g0,
                n_out: hi - lo,
            })
            .map_err(|_| Error::State)?;
            cur_at[i] = yo;
            xo += g1 - g0;
            yo += hi - lo;
        }
        let oc = uw.c_out();
        let y = first(cur, yo * oc)?;
        uw.run(
            &unit,
            &jobs,
            first(w.g, xo * unit.c_in)?,
            y,
            w.h,
            w.r,
            w.tile,
        )
    }
}

/// The scratch a unit's computation works in (gathered inputs, residual
/// inner and 1x1 rows, the kernel tile), borrowed from a [`StreamScratch`].
struct Work<'a> {
    g: &'a mut [f32],
    h: &'a mut [f32],
    r: &'a mut [f32],
    tile: &'a mut [f32],
}

/// Columns `[at, at + n)` of `c` floats each of `b`, or a length error.
pub(super) fn cols_at(b: &mut [f32], at: usize, n: usize, c: usize) -> Result<&mut [f32], Error> {
    let len = b.len();
    b.get_mut(at * c..(at + n) * c).ok_or(Error::Length {
        buffer: Buffer::Features,
        len,
        expected: (at + n) * c,
    })
}
