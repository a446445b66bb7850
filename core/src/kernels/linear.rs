//! Dense layers: `y = x W^T + b` (nn.Linear, conv as GEMM) and `z = x W`
//! (the transposed-convolution GEMM). Written once against [`RowMatrix`].

use super::parallel::{split_cols, Cols};
use super::simd::{self, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};
use super::weights::{
    ExpandsToQ8, Matrix, PreparedAct, Q4Rows, Q8Rows, RowMatrix, X8Rows, Q8X8_ROWS,
};
use crate::arena::{ArenaError, Carve};

/// Weight bytes kept hot per pass over the activations (~L2-sized blocks:
/// 64 f32 rows at width 768, more rows for narrower weight types).
const BLOCK_BYTES: usize = 192 * 1024;

/// `y = x W^T + b`. `x`: (n, in), `w`: (out, in), `b`: (out) or None,
/// `y`: (n, out); `n = x.len() / in`. Callers check the lengths.
///
/// With a worker pool installed ([`super::parallel`]) the output columns
/// are split over its threads; the values are the same bit for bit.
pub fn linear(x: &[f32], w: &Matrix<'_>, b: Option<&[f32]>, y: &mut [f32]) {
    linear_with(x, w, b, y, &mut Q8Room::default())
}

/// [`linear`] with caller memory for the int8 activation panel: a call
/// whose rows `room` holds, or holds more of than the stack panel
/// ([`Q8_PANEL`] values), is quantised into `room` (calls of at most
/// 32 Ki values keep their small stack panel), so each weight
/// tile (and its AMX operands) is read and prepared once per `room`'s rows
/// rather than once per stack panel, and no stack panel is zeroed. The
/// values are the same bit for bit (rows are computed independently); an
/// empty `room` is [`linear`].
pub fn linear_with(
    x: &[f32],
    w: &Matrix<'_>,
    b: Option<&[f32]>,
    y: &mut [f32],
    room: &mut Q8Room<'_>,
) {
    linear_epilogue(x, w, Epilogue::bias(b), y, room)
}

/// `y = gelu(x W^T + b)`: [`linear_with`] then [`super::gelu_inplace`] of
/// `y`, bit for bit, with GELU applied to each output segment as the GEMM
/// writes it (while it is in L1, and on every thread of a split GEMM)
/// instead of in a second pass over `y`.
pub fn linear_gelu_with(
    x: &[f32],
    w: &Matrix<'_>,
    b: Option<&[f32]>,
    y: &mut [f32],
    room: &mut Q8Room<'_>,
) {
    linear_epilogue(
        x,
        w,
        Epilogue {
            bias: b,
            gelu: true,
        },
        y,
        room,
    )
}

/// What a GEMM does to its output values after the products (the usual
/// GEMM term): `b + t` (`0 + t` without a bias), then GELU where `gelu`
/// ([`simd::bias_act`]).
#[derive(Clone, Copy, Default)]
struct Epilogue<'b> {
    bias: Option<&'b [f32]>,
    gelu: bool,
}

impl<'b> Epilogue<'b> {
    fn bias(bias: Option<&'b [f32]>) -> Self {
        Epilogue { bias, gelu: false }
    }

    /// Writes `y = b[t0..] + t` (then GELU) for the output columns `t0 .. t0 + y.len()`.
    #[inline]
    fn put(self, y: &mut [f32], t0: usize, t: &[f32]) {
        simd::bias_act(t, self.bias.map(|b| &b[t0..t0 + y.len()]), self.gelu, y)
    }
}

/// [`linear_with`] with epilogue `e`.
fn linear_epilogue(
    x: &[f32],
    w: &Matrix<'_>,
    e: Epilogue<'_>,
    y: &mut [f32],
    room: &mut Q8Room<'_>,
) {
    let (n_in, n_out) = (w.cols(), w.rows());
    if n_in == 0 || n_out == 0 {
        return;
    }
    let n = (x.len() / n_in).min(y.len() / n_out);
    if n == 0 {
        return;
    }
    let (x, y) = (&x[..n * n_in], &mut y[..n * n_out]);
    if takes_q8_panel(w) {
        match w {
            Matrix::Q8(q) => return linear_q8(x, [q], [e], [y], room),
            Matrix::X8(q) => return linear_q8(x, [q], [e], [y], room),
            Matrix::Q4(q) => return linear_q8(x, [q], [e], [y], room),
            _ => {}
        }
    }
    let block = (BLOCK_BYTES / (w.weight_bytes() / n_out).max(1)).clamp(16, 1024);
    split_cols(
        y,
        n_out,
        w.weight_bytes().saturating_mul(n),
        |cols| crate::with_rows!(w, m => linear_impl(x, m, e, cols, block)),
    )
}

/// Whether [`linear`] runs `w` on the int8 panel path ([`linear_q8`]).
fn takes_q8_panel(w: &Matrix<'_>) -> bool {
    let n_in = w.cols();
    match w {
        Matrix::Q8(_) => n_in <= Q8_PANEL,
        // Packed in place on VNNI; expanded per tile (stack rows of at most
        // `Q4_FAST_COLS`) elsewhere.
        Matrix::X8(_) => n_in <= Q4_FAST_COLS || (n_in <= Q8_PANEL && simd::packed_q8_fast()),
        Matrix::Q4(_) => n_in <= Q4_FAST_COLS,
        _ => false,
    }
}

/// `y_k = x W_k^T + b_k` for `N` matrices over the same input rows (the
/// attention's query, key and value projections): the values of `N`
/// [`linear`] calls, bit for bit. Where all `N` are stored in the same
/// int8 layout, of the same width, for the same rows, and take the int8
/// panel path, the activation rows are quantised once for all of them.
pub fn linear_each<const N: usize>(
    x: &[f32],
    ws: [&Matrix<'_>; N],
    bs: [Option<&[f32]>; N],
    ys: [&mut [f32]; N],
) {
    linear_each_with(x, ws, bs, ys, &mut Q8Room::default())
}

/// [`linear_each`] with caller memory for the int8 panel (see [`linear_with`]).
pub fn linear_each_with<const N: usize>(
    x: &[f32],
    ws: [&Matrix<'_>; N],
    bs: [Option<&[f32]>; N],
    ys: [&mut [f32]; N],
    room: &mut Q8Room<'_>,
) {
    let n_in = ws.first().map_or(0, |w| w.cols());
    let rows = |k: usize, y: &[f32]| {
        if n_in == 0 || ws[k].rows() == 0 {
            0
        } else {
            (x.len() / n_in).min(y.len() / ws[k].rows())
        }
    };
    let n = ys.first().map_or(0, |y| rows(0, y));
    let shared = n > 0
        && ws.iter().all(|w| w.cols() == n_in && takes_q8_panel(w))
        && ys.iter().enumerate().all(|(k, y)| rows(k, y) == n);
    if shared {
        let x = &x[..n * n_in];
        if let Some(m) = same_layout(ws, |w| if let Matrix::X8(q) = w { Some(q) } else { None }) {
            return linear_q8(x, m, bs.map(Epilogue::bias), ys, room);
        }
        if let Some(m) = same_layout(ws, |w| if let Matrix::Q8(q) = w { Some(q) } else { None }) {
            return linear_q8(x, m, bs.map(Epilogue::bias), ys, room);
        }
        if let Some(m) = same_layout(ws, |w| if let Matrix::Q4(q) = w { Some(q) } else { None }) {
            return linear_q8(x, m, bs.map(Epilogue::bias), ys, room);
        }
    }
    for ((w, b), y) in ws.into_iter().zip(bs).zip(ys) {
        linear_with(x, w, b, y, room);
    }
}

/// The `N` matrices as one stored layout (`pick` takes a matrix's rows of
/// it), if every one is stored so; None for `N = 0`.
fn same_layout<'a, 'm, T, const N: usize>(
    ws: [&'a Matrix<'m>; N],
    pick: impl Fn(&'a Matrix<'m>) -> Option<&'a T>,
) -> Option<[&'a T; N]> {
    let m = ws.map(pick);
    let first = m.first().copied().flatten()?;
    m.iter()
        .all(Option::is_some)
        .then(|| m.map(|q| q.unwrap_or(first)))
}

/// Int8 activation values quantised at once by `linear` over a [`Q8Rows`]
/// matrix (a stack panel: `Q8_PANEL` i8 + `Q8_PANEL / 32` f32 scales and
/// `2 Q8_PANEL / 32` i32 corrections, 264 KiB on 64-bit targets, with
/// either `TN x Q8_PANEL / 32` f32 weight scales (96 KiB) or the packed
/// path's 26 KiB tile pack and 54 KiB of AMX weight operands; 7 KiB in all
/// on 32-bit ones). 192 KiB of values hold 64 rows of the widest GPT input,
/// 3072: eight AMX row groups per preparation of a tile pair's operands,
/// the weights read once per 64 rows (96 KiB: the R step's 768 x 3072
/// GEMM at 1.32x VNNI with AMX in the kernel bench, 1.70x at 192 KiB).
/// Rows of `x` are quantised once per call when `rows * in <= Q8_PANEL`
/// (every matrix-vector and small-batch product of the model), else once
/// per panel of `Q8_PANEL / in` rows (the weights are then read once per
/// panel). Wider matrices (`in > Q8_PANEL`) take the generic chunked path.
/// A caller with memory to spare passes a [`Q8Room`] ([`linear_with`]):
/// R mode's blocks quantise a whole window (290 rows x 3072) at once, so
/// a tile pair's AMX operands are prepared once per GEMM, not once per 64
/// rows (measured 2026-12-03 on the Xeon with AMX: the int8 R step
/// 0.89-0.95x the time in five quiet A/B rounds).
#[cfg(target_pointer_width = "64")]
pub const Q8_PANEL: usize = 192 * 1024;
/// See the 64-bit definition.
#[cfg(not(target_pointer_width = "64"))]
pub const Q8_PANEL: usize = 4 * 1024;
const Q8_PANEL_BLOCKS: usize = Q8_PANEL / Q8_BLOCK;

// Threads split the output columns at multiples of 8: whole x8 row groups.
const _: () = assert!(super::parallel::SPLIT_ALIGN % Q8X8_ROWS == 0);

/// Fewest activation rows of a panel for the packed int8 path.
const PACK_MIN_ROWS: usize = 4;

/// The panel of a call whose rows fit in 32 KiB of values (the streaming
/// step's GEMMs of one session: up to 10 rows of the widest input). Its
/// zeroed stack room is 44 KiB where the full panel's is 264 KiB, zeroed
/// on every call (which showed in the streaming step's profile).
const Q8_PANEL_SMALL: usize = if Q8_PANEL < 32 * 1024 {
    Q8_PANEL
} else {
    32 * 1024
};

/// Room for `Q` quantised activation values (`B = Q / 32` block scales,
/// `C = 2 B` VNNI corrections).
#[repr(C, align(64))]
struct PanelRoom<const Q: usize, const B: usize, const C: usize> {
    q: [i8; Q],
    d: [f32; B],
    c: [i32; C],
}

/// Caller memory for the quantised activation rows of [`linear_with`]
/// (values, their block scales and VNNI corrections); empty by default.
#[derive(Default)]
pub struct Q8Room<'a> {
    q: &'a mut [i8],
    d: &'a mut [f32],
    c: &'a mut [i32],
}

impl<'a> Q8Room<'a> {
    /// Room for `values` activation values (rows x width of the widest
    /// call that should be quantised at once).
    pub fn carve<A: Carve<'a>>(a: &mut A, values: usize) -> Result<Self, ArenaError> {
        let blocks = values.div_ceil(Q8_BLOCK);
        Ok(Q8Room {
            q: a.i8(values)?,
            d: a.f32(blocks)?,
            c: a.i32(blocks.checked_mul(2).ok_or(ArenaError::Overflow)?)?,
        })
    }

    /// The same memory, borrowed for a shorter time.
    pub fn reborrow(&mut self) -> Q8Room<'_> {
        Q8Room {
            q: self.q,
            d: self.d,
            c: self.c,
        }
    }

    /// Rows of width `n_in` it holds.
    fn rows(&self, n_in: usize) -> usize {
        panel_rows(self.q, self.d, self.c, n_in)
    }
}

/// Rows of width `n_in` (a multiple of 32) that panel memory of `q`
/// values, `d` scales and `c` corrections holds.
fn panel_rows(q: &[i8], d: &[f32], c: &[i32], n_in: usize) -> usize {
    let nb = n_in / Q8_BLOCK;
    if nb == 0 {
        return 0;
    }
    (q.len() / n_in).min(d.len() / nb).min(c.len() / (2 * nb))
}

/// Quantised activation rows of one panel (see [`Q8_PANEL`]): row `r`'s
/// values `q[r * in..][..in]`, scales `d[r * in / 32..]`, corrections
/// `c[2 r * in / 32..]`; or, where `grouped`, the same memory as the tile
/// pair kernel's call groups ([`pair_groups`], each laid out by
/// [`simd::pair_group_index`] from its first row's offsets on).
struct Q8Panel<'a> {
    q: &'a [i8],
    d: &'a [f32],
    c: &'a [i32],
    grouped: bool,
}

/// The call groups of the tile pair kernel over a panel of `rows` rows:
/// `f(first row, rows)` (the groups [`calls_of`] makes of `0..rows`).
#[inline(always)]
fn pair_groups(rows: usize, f: &mut impl FnMut(usize, usize)) {
    simd::even_passes(rows, simd::PAIR_CALL_ROWS, f)
}

/// Widest Q4 row the int8 panel path takes (its rows are expanded to Q8
/// blocks on the stack, `PACK_ROWS` at a time: 8 x 4352 bytes); wider
/// rows take the generic chunked path.
#[cfg(target_pointer_width = "64")]
pub const Q4_FAST_COLS: usize = 4096;
#[cfg(not(target_pointer_width = "64"))]
pub const Q4_FAST_COLS: usize = 1024;
const Q4_ROW_BYTES: usize = Q4_FAST_COLS / Q8_BLOCK * Q8_BLOCK_BYTES;

/// Weight rows as the int8 panel path reads them: as Q8Block32 rows (Q8
/// rows in place; Q4 and x8 rows expanded into a stack buffer, exact)
/// for [`simd::gemm_q8`], and as packed 8-row tiles for
/// [`simd::gemm_q8_packed`] (x8 groups in place; Q8 and Q4 rows packed
/// per tile).
trait Q8Source: RowMatrix {
    /// Room for `simd::PACK_ROWS` expanded rows (nothing for Q8).
    type Buf;
    /// Whether the tiles are stored packed (the packed kernel then pays
    /// off from one activation row on).
    const PREPACKED: bool;
    fn new_buf() -> Self::Buf;
    /// Rows `rows` (N <= `simd::PACK_ROWS`) as stored Q8Block32 rows.
    fn q8_rows<'s, const N: usize>(
        &'s self,
        rows: [usize; N],
        buf: &'s mut Self::Buf,
    ) -> [&'s [u8]; N];
    /// Rows `t0 .. t0 + 8` (`t0` a multiple of 8; rows past the matrix
    /// repeat its last row or are padding: their results are dropped) as
    /// a packed tile of `nb` blocks (`nb <= PACK_BLOCKS` unless PREPACKED).
    /// `pack` and `buf` are made on first use (a source stored packed
    /// needs neither: zeroing their ~60 KiB per call showed in the
    /// streaming step's profile).
    fn packed_tile<'s>(
        &'s self,
        t0: usize,
        nb: usize,
        pack: &'s mut Option<simd::Q8Pack8>,
        buf: &'s mut Option<Self::Buf>,
    ) -> simd::PackedQ8<'s> {
        let last = self.rows() - 1;
        let rows = self.q8_rows(
            core::array::from_fn(|j| (t0 + j).min(last)),
            buf.get_or_insert_with(Self::new_buf),
        );
        let pack = pack.get_or_insert_with(simd::Q8Pack8::new);
        simd::q8_pack8(rows, nb, pack);
        pack.view()
    }
    /// The stored bytes of rows `r0..r1` (for [`simd::prefetch`]).
    fn stored_rows(&self, r0: usize, r1: usize) -> &[u8];
    /// The packed tile of rows `t0..t0 + 8` as stored, where the source
    /// stores its tiles packed (no buffer: two tiles can be read at once);
    /// None otherwise.
    #[inline]
    fn stored_tile(&self, _t0: usize) -> Option<simd::PackedQ8<'_>> {
        None
    }
}

impl Q8Source for Q8Rows<'_> {
    type Buf = ();
    const PREPACKED: bool = false;
    #[inline]
    fn new_buf() {}
    #[inline]
    fn q8_rows<'s, const N: usize>(&'s self, rows: [usize; N], _: &'s mut ()) -> [&'s [u8]; N] {
        rows.map(|r| self.row(r))
    }
    #[inline]
    fn stored_rows(&self, r0: usize, r1: usize) -> &[u8] {
        self.rows_bytes(r0, r1)
    }
}

/// Room for `simd::PACK_ROWS` rows expanded to Q8Block32 (at most
/// `Q4_FAST_COLS` values each).
type ExpandBuf = [[u8; Q4_ROW_BYTES]; simd::PACK_ROWS];

/// Rows `rows` of a layout read through its Q8 expansion, expanded into
/// `buf` (the first `Q4_FAST_COLS` columns; callers keep rows that short).
#[inline]
fn expanded_rows<'s, W: ExpandsToQ8, const N: usize>(
    w: &W,
    rows: [usize; N],
    buf: &'s mut ExpandBuf,
) -> [&'s [u8]; N] {
    let nb = (w.dims().1 / Q8_BLOCK).min(Q4_FAST_COLS / Q8_BLOCK);
    for (dst, &r) in buf.iter_mut().zip(&rows) {
        w.expand_blocks(r, 0, nb, dst);
    }
    let buf: &'s ExpandBuf = buf;
    core::array::from_fn(|j| &buf[j.min(simd::PACK_ROWS - 1)][..nb * Q8_BLOCK_BYTES])
}

impl Q8Source for Q4Rows<'_> {
    type Buf = ExpandBuf;
    const PREPACKED: bool = false;
    #[inline]
    fn new_buf() -> ExpandBuf {
        [[0; Q4_ROW_BYTES]; simd::PACK_ROWS]
    }
    #[inline]
    fn q8_rows<'s, const N: usize>(
        &'s self,
        rows: [usize; N],
        buf: &'s mut ExpandBuf,
    ) -> [&'s [u8]; N] {
        expanded_rows(self, rows, buf)
    }
    #[inline]
    fn stored_rows(&self, r0: usize, r1: usize) -> &[u8] {
        self.rows_bytes(r0, r1)
    }
}

impl Q8Source for X8Rows<'_> {
    type Buf = ExpandBuf;
    const PREPACKED: bool = true;
    #[inline]
    fn new_buf() -> ExpandBuf {
        [[0; Q4_ROW_BYTES]; simd::PACK_ROWS]
    }
    #[inline]
    fn q8_rows<'s, const N: usize>(
        &'s self,
        rows: [usize; N],
        buf: &'s mut ExpandBuf,
    ) -> [&'s [u8]; N] {
        expanded_rows(self, rows, buf)
    }
    #[inline]
    fn packed_tile<'s>(
        &'s self,
        t0: usize,
        _nb: usize,
        _: &'s mut Option<simd::Q8Pack8>,
        _: &'s mut Option<Self::Buf>,
    ) -> simd::PackedQ8<'s> {
        self.group(t0 / Q8X8_ROWS)
    }
    #[inline]
    fn stored_rows(&self, r0: usize, r1: usize) -> &[u8] {
        self.rows_bytes(r0, r1)
    }
    #[inline]
    fn stored_tile(&self, t0: usize) -> Option<simd::PackedQ8<'_>> {
        Some(self.group(t0 / Q8X8_ROWS))
    }
}

/// `y = x W^T + b` over int8 weights: activation rows quantised once per
/// panel ([`simd::quantise_q8_corr`]), weight scales read once per tile of
/// `TN` weight rows ([`simd::q8_scales`]) and reused by every activation
/// tile of the panel ([`simd::gemm_q8`], `M` = 1..=4 rows, no padded rows).
///
/// `N` matrices of the same width over the same `n = x.len() / in` rows
/// (each `y` holds `n` rows; [`linear_each`] checks it) share the
/// quantised panel; each takes its own kernels, as if called alone.
fn linear_q8<W: Q8Source + Sync, const N: usize>(
    x: &[f32],
    ws: [&W; N],
    es: [Epilogue<'_>; N],
    ys: [&mut [f32]; N],
    room: &mut Q8Room<'_>,
) {
    let n_in = ws.first().map_or(0, |w| w.cols());
    let values = x.len().checked_div(n_in).map_or(0, |rows| rows * n_in);
    if values <= Q8_PANEL_SMALL {
        linear_q8_in::<
            W,
            N,
            Q8_PANEL_SMALL,
            { Q8_PANEL_SMALL / Q8_BLOCK },
            { 2 * Q8_PANEL_SMALL / Q8_BLOCK },
        >(x, ws, es, ys)
    } else if room.rows(n_in) * n_in >= values || room.rows(n_in) > Q8_PANEL / n_in {
        linear_q8_on(x, ws, es, ys, room.q, room.d, room.c)
    } else {
        linear_q8_in::<W, N, Q8_PANEL, Q8_PANEL_BLOCKS, { 2 * Q8_PANEL_BLOCKS }>(x, ws, es, ys)
    }
}

/// [`linear_q8`] with a stack panel of `Q` values (`B = Q / 32`, `C = 2 B`).
#[inline(never)]
fn linear_q8_in<
    W: Q8Source + Sync,
    const N: usize,
    const Q: usize,
    const B: usize,
    const C: usize,
>(
    x: &[f32],
    ws: [&W; N],
    es: [Epilogue<'_>; N],
    ys: [&mut [f32]; N],
) {
    let mut room = PanelRoom::<Q, B, C> {
        q: [0; Q],
        d: [0.0; B],
        c: [0; C],
    };
    linear_q8_on(x, ws, es, ys, &mut room.q, &mut room.d, &mut room.c)
}

/// [`linear_q8`] on panel memory `q` (values), `d` (block scales), `c`
/// (corrections): the rows in panels of as many rows as it holds.
#[inline(never)]
fn linear_q8_on<W: Q8Source + Sync, const N: usize>(
    x: &[f32],
    ws: [&W; N],
    es: [Epilogue<'_>; N],
    mut ys: [&mut [f32]; N],
    q: &mut [i8],
    d: &mut [f32],
    c: &mut [i32],
) {
    let Some(n_in) = ws.first().map(|w| w.cols()).filter(|&c| c > 0) else {
        return;
    };
    let n = x.len() / n_in;
    let nb = n_in / Q8_BLOCK;
    let per_panel = panel_rows(q, d, c, n_in);
    if per_panel == 0 {
        return;
    }
    let mut p0 = 0;
    while p0 < n {
        let p1 = (p0 + per_panel).min(n);
        // Packing 8 weight rows per call pays off from a few activation
        // rows on (measured: at 1 row the unpacked VNNI tile is faster);
        // stored packed tiles are faster from one row on.
        let packed = simd::packed_q8_fast()
            && (W::PREPACKED
                || (simd::q8_packing_pays()
                    && p1 - p0 >= PACK_MIN_ROWS
                    && nb <= simd::PACK_BLOCKS));
        // The tile pair kernel's panels (without AMX: it takes the rows
        // one after another) are quantised straight into its call groups.
        let grouped =
            packed && p1 - p0 >= PAIR_MIN_ROWS && simd::pair_takes(nb) && !simd::amx_enabled();
        if grouped {
            quantise_grouped(&x[p0 * n_in..p1 * n_in], n_in, q, d, c);
        } else {
            for i in p0..p1 {
                let r = i - p0;
                simd::quantise_q8_corr(
                    &x[i * n_in..(i + 1) * n_in],
                    &mut q[r * n_in..(r + 1) * n_in],
                    &mut d[r * nb..(r + 1) * nb],
                    &mut c[2 * r * nb..2 * (r + 1) * nb],
                );
            }
        }
        let p = &Q8Panel {
            q: &*q,
            d: &*d,
            c: &*c,
            grouped,
        };
        for ((w, e), y) in ws.iter().zip(es).zip(ys.iter_mut()) {
            let n_out = w.rows();
            let work = (n_out * nb * Q8_BLOCK_BYTES).saturating_mul(p1 - p0);
            split_cols(&mut y[p0 * n_out..p1 * n_out], n_out, work, |cols| {
                if packed {
                    q8_panel_packed(*w, e, cols, p, p1 - p0, n_in)
                } else {
                    q8_panel_tiles_for(*w, e, cols, p, p1 - p0, n_in)
                }
            });
        }
        p0 = p1;
    }
}

/// One quantised row of at most [`simd::PACK_BLOCKS`] blocks (a grouped
/// panel's rows pass through it: 4.6 KiB on the stack).
struct RowRoom {
    q: [i8; simd::PACK_BLOCKS * Q8_BLOCK],
    d: [f32; simd::PACK_BLOCKS],
    c: [i32; 2 * simd::PACK_BLOCKS],
}

impl RowRoom {
    fn new() -> Self {
        RowRoom {
            q: [0; simd::PACK_BLOCKS * Q8_BLOCK],
            d: [0.0; simd::PACK_BLOCKS],
            c: [0; 2 * simd::PACK_BLOCKS],
        }
    }
}

/// The rows of `x` (`n_in` values each, at most [`simd::PACK_BLOCKS`]
/// blocks; the panel memory holds them) quantised as
/// [`simd::quantise_q8_corr`] does, each written into its place in the
/// tile pair kernel's call groups ([`pair_groups`], [`simd::pair_group_index`]).
#[inline(never)]
fn quantise_grouped(x: &[f32], n_in: usize, q: &mut [i8], d: &mut [f32], c: &mut [i32]) {
    let nb = n_in / Q8_BLOCK;
    let mut row = RowRoom::new();
    pair_groups(x.len() / n_in, &mut |i0, rows| {
        let (gq, gd, gc) = (
            &mut q[i0 * n_in..(i0 + rows) * n_in],
            &mut d[i0 * nb..(i0 + rows) * nb],
            &mut c[2 * i0 * nb..2 * (i0 + rows) * nb],
        );
        for m in 0..rows {
            let i = i0 + m;
            simd::quantise_q8_corr(
                &x[i * n_in..(i + 1) * n_in],
                &mut row.q[..n_in],
                &mut row.d[..nb],
                &mut row.c[..2 * nb],
            );
            for b in 0..nb {
                let g = simd::pair_group_index(b, m, rows);
                gq[Q8_BLOCK * g..Q8_BLOCK * (g + 1)]
                    .copy_from_slice(&row.q[Q8_BLOCK * b..Q8_BLOCK * (b + 1)]);
                gd[g] = row.d[b];
                gc[2 * g..2 * g + 2].copy_from_slice(&row.c[2 * b..2 * b + 2]);
            }
        }
    });
}

/// Row `r` of a grouped panel of `rows` rows back in one piece (in `row`).
fn grouped_row<'r>(
    p: &Q8Panel<'_>,
    rows: usize,
    r: usize,
    n_in: usize,
    row: &'r mut RowRoom,
) -> Q8Panel<'r> {
    let nb = n_in / Q8_BLOCK;
    pair_groups(rows, &mut |i0, mt| {
        if (i0..i0 + mt).contains(&r) {
            let m = r - i0;
            for b in 0..nb {
                let g = simd::pair_group_index(b, m, mt);
                let (o, go) = (Q8_BLOCK * b, i0 * n_in + Q8_BLOCK * g);
                row.q[o..o + Q8_BLOCK].copy_from_slice(&p.q[go..go + Q8_BLOCK]);
                row.d[b] = p.d[i0 * nb + g];
                let gc = 2 * (i0 * nb + g);
                row.c[2 * b..2 * b + 2].copy_from_slice(&p.c[gc..gc + 2]);
            }
        }
    });
    Q8Panel {
        q: &row.q[..n_in],
        d: &row.d[..nb],
        c: &row.c[..2 * nb],
        grouped: false,
    }
}

/// Output columns `y.lo()..y.hi()` of the generic path (`n = x.len() / in` rows).
fn linear_impl<W: RowMatrix>(x: &[f32], w: &W, e: Epilogue<'_>, mut y: Cols<'_>, block: usize) {
    let n_in = w.cols();
    let n = x.len() / n_in;
    let chunk = W::CHUNK.min(n_in);
    let mut act = W::Act::new();
    // Output blocks (weights kept hot in L2) x activation tiles of TM rows
    // (prepared once per block and chunk) x weight tiles of TN rows. Tails
    // repeat the last real row / output and drop the extra results.
    let mut o0 = y.lo();
    while o0 < y.hi() {
        let o1 = (o0 + block).min(y.hi());
        let mut i0 = 0;
        while i0 < n {
            let mt = TM.min(n - i0);
            for i in i0..i0 + mt {
                let yi = y.seg(i, o0, o1);
                match e.bias {
                    Some(b) => yi.copy_from_slice(&b[o0..o1]),
                    None => yi.fill(0.0),
                }
            }
            let mut c0 = 0;
            while c0 < n_in {
                let c1 = (c0 + chunk).min(n_in);
                let mut m = 0;
                let xt: [&[f32]; TM] = [(); TM].map(|_| {
                    let i = i0 + m.min(mt - 1);
                    m += 1;
                    &x[i * n_in + c0..i * n_in + c1]
                });
                W::prepare(&xt[..mt], &mut act);
                let mut t0 = o0;
                while t0 < o1 {
                    let nt = TN.min(o1 - t0);
                    let mut j = 0;
                    let ot: [usize; TN] = [(); TN].map(|_| {
                        j += 1;
                        t0 + (j - 1).min(nt - 1)
                    });
                    let tile = w.dot_tile(ot, c0, xt, &act);
                    for (r, tr) in tile.iter().enumerate().take(mt) {
                        for (yo, t) in y.seg(i0 + r, t0, t0 + nt).iter_mut().zip(tr) {
                            *yo += t;
                        }
                    }
                    t0 += nt;
                }
                c0 = c1;
            }
            if e.gelu {
                for i in i0..i0 + mt {
                    simd::gelu_inplace(y.seg(i, o0, o1));
                }
            }
            i0 += mt;
        }
        o0 = o1;
    }
}

/// `z = x W` (no transpose). `x`: (n, rows), `w`: (rows, cols), `z`: (n, cols).
pub fn linear_xw(x: &[f32], w: &Matrix<'_>, z: &mut [f32]) {
    crate::with_rows!(w, m => linear_xw_impl(x, m, z))
}

/// Weight rows per pass of [`linear_xw`] over its output rows: each output
/// lane is loaded and stored once per this many weight rows.
const XW_ROWS: usize = 8;

/// Per output row `i`, `z_i = sum_r x[i, r] row(r)` with the rows `r` in
/// order (each row's `axpy`: the numbers of one `axpy` per (row, input
/// row)); in passes of [`XW_ROWS`] weight rows, the output rows
/// [`simd::QUERY_GROUP`] at a time (a dense row's lanes loaded once for
/// them).
fn linear_xw_impl<W: RowMatrix>(x: &[f32], w: &W, z: &mut [f32]) {
    let (rows, cols) = (w.rows(), w.cols());
    if rows == 0 || cols == 0 {
        return;
    }
    let n = (x.len() / rows).min(z.len() / cols);
    z[..n * cols].fill(0.0);
    for r0 in (0..rows).step_by(XW_ROWS) {
        let r1 = (r0 + XW_ROWS).min(rows);
        for i0 in (0..n).step_by(simd::QUERY_GROUP) {
            let g = simd::QUERY_GROUP.min(n - i0);
            w.axpy_rows_group(
                r0,
                r1,
                &x[i0 * rows + r0..],
                rows,
                &mut z[i0 * cols..],
                cols,
                g,
            );
        }
    }
}

/// [`q8_panel_tiles`] with weight-scale room for `in / 32` blocks: rows of
/// at most `PACK_BLOCKS` blocks (every matrix of the model; 1.5 KiB zeroed
/// per call) or the widest the panel takes (96 KiB). Off AVX512-VNNI every
/// int8 GEMM of a streaming step runs here.
fn q8_panel_tiles_for<W: Q8Source>(
    w: &W,
    e: Epilogue<'_>,
    y: Cols<'_>,
    p: &Q8Panel<'_>,
    n_rows: usize,
    n_in: usize,
) {
    if n_in / Q8_BLOCK <= simd::PACK_BLOCKS {
        q8_panel_tiles::<W, { simd::PACK_BLOCKS }>(w, e, y, p, n_rows, n_in)
    } else {
        q8_panel_tiles::<W, Q8_PANEL_BLOCKS>(w, e, y, p, n_rows, n_in)
    }
}

/// Output tiles of `TN` weight rows x activation tiles of up to `TM` rows
/// of one quantised panel (`rows` rows; output columns `y.lo()..y.hi()`),
/// with [`simd::gemm_q8`].
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn q8_panel_tiles<W: Q8Source, const WB: usize>(
    w: &W,
    e: Epilogue<'_>,
    mut y: Cols<'_>,
    p: &Q8Panel<'_>,
    n_rows: usize,
    n_in: usize,
) {
    let nb = n_in / Q8_BLOCK;
    let mut ws = [[0.0f32; WB]; TN];
    let mut buf = W::new_buf();
    let mut t0 = y.lo();
    while t0 < y.hi() {
        let nt = TN.min(y.hi() - t0);
        let rows: [usize; TN] = core::array::from_fn(|j| t0 + j.min(nt - 1));
        let wr = w.q8_rows(rows, &mut buf);
        for (s, r) in ws.iter_mut().zip(&wr) {
            simd::q8_scales(r, &mut s[..nb]);
        }
        simd::prefetch(w.stored_rows(t0 + TN, (t0 + 2 * TN).min(y.hi())));
        let wd: [&[f32]; TN] = core::array::from_fn(|j| &ws[j][..nb]);
        let mut i0 = 0;
        while i0 < n_rows {
            let mt = TM.min(n_rows - i0);
            let pr = |m: usize| i0 + m.min(mt - 1);
            let q = |m: usize| &p.q[pr(m) * n_in..(pr(m) + 1) * n_in];
            let d = |m: usize| &p.d[pr(m) * nb..(pr(m) + 1) * nb];
            let c = |m: usize| &p.c[2 * pr(m) * nb..2 * (pr(m) + 1) * nb];
            let mut put = |m: usize, t: [f32; TN]| e.put(y.seg(i0 + m, t0, t0 + nt), t0, &t);
            match mt {
                1 => {
                    let t = simd::gemm_q8::<1>(wr, wd, [q(0)], [d(0)], [c(0)]);
                    put(0, t[0]);
                }
                2 => {
                    let t = simd::gemm_q8::<2>(wr, wd, [q(0), q(1)], [d(0), d(1)], [c(0), c(1)]);
                    t.into_iter().enumerate().for_each(|(m, r)| put(m, r));
                }
                3 => {
                    let t = simd::gemm_q8::<3>(
                        wr,
                        wd,
                        [q(0), q(1), q(2)],
                        [d(0), d(1), d(2)],
                        [c(0), c(1), c(2)],
                    );
                    t.into_iter().enumerate().for_each(|(m, r)| put(m, r));
                }
                _ => {
                    let t = simd::gemm_q8::<4>(
                        wr,
                        wd,
                        core::array::from_fn(q),
                        core::array::from_fn(d),
                        core::array::from_fn(c),
                    );
                    t.into_iter().enumerate().for_each(|(m, r)| put(m, r));
                }
            }
            i0 += mt;
        }
        t0 += nt;
    }
}

/// [`q8_panel_tiles`] over packed tiles of 8 weight rows (stored packed,
/// or packed once per tile: [`Q8Source::packed_tile`]) and activation
/// tiles of up to [`PACKED_CALL_ROWS`] rows ([`simd::gemm_q8_packed`]).
/// Where the tile pair kernels run ([`simd::pair_takes`]: AVX-512 VNNI, AVX-VNNI,
/// AVX2 up to 1536 values a row) and the panel has at least [`PAIR_MIN_ROWS`] rows, tiles go in pairs,
/// laid out once per pair as one 16-row operand ([`simd::TilePair`]). With
/// AMX ([`simd::amx_enabled`], at least [`AMX_MIN_ROWS`] rows) the whole
/// 8-row groups of activation rows take the AMX kernel and the rows after
/// them the 8-row kernel per tile; without AMX every row takes the 16-row
/// VNNI kernels ([`simd::gemm_q8_pair`]). Every route gives the same values
/// bit for bit.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn q8_panel_packed<W: Q8Source>(
    w: &W,
    e: Epilogue<'_>,
    mut y: Cols<'_>,
    p: &Q8Panel<'_>,
    n_rows: usize,
    n_in: usize,
) {
    const R: usize = simd::PACK_ROWS;
    let nb = n_in / Q8_BLOCK;
    let (mut pack, mut buf) = (None, None);
    let mut pair = (n_rows >= PAIR_MIN_ROWS && simd::pair_takes(nb)).then(simd::TilePair::new);
    // The AMX kernel's rows of this panel (whole 8-row groups; 0 if it would refuse the extents).
    let amx_planned = if n_rows >= AMX_MIN_ROWS && simd::amx_enabled() {
        simd::amx_rows(nb, n_rows * n_in, n_in, n_rows * nb, n_rows)
    } else {
        0
    };
    let mut t0 = y.lo();
    while t0 < y.hi() {
        let nt = R.min(y.hi() - t0);
        // The second tile (or, at the end, this one again as a second operand whose results are dropped).
        let t1 = t0 + R;
        let nt1 = if t1 < y.hi() { R.min(y.hi() - t1) } else { 0 };
        // Two tiles stored packed: laid out together in one pass.
        let second = if nt1 > 0 { w.stored_tile(t1) } else { None };
        let both = match (pair.as_mut(), w.stored_tile(t0), second) {
            (Some(a), Some(s0), Some(s1)) => Some(a.prepare_both(s0, s1)),
            _ => None,
        };
        let tile = w.packed_tile(t0, nb, &mut pack, &mut buf);
        let paired = both.unwrap_or_else(|| pair.as_mut().is_some_and(|a| a.prepare(0, tile)));
        let a = match pair.as_mut() {
            Some(a) if paired => a,
            _ => {
                // The weights two tiles ahead stream into L2 while this one is
                // multiplied, the prefetches spread over the kernel's blocks.
                let ahead = if n_rows < AMX_MIN_ROWS && t0 + PREFETCH_TILES * R < y.hi() {
                    w.stored_rows(
                        t0 + PREFETCH_TILES * R,
                        (t0 + (PREFETCH_TILES + 1) * R).min(y.hi()),
                    )
                } else {
                    &[]
                };
                tile_rows(tile, p, n_rows, 0, n_in, ahead, |i, t| {
                    put_row(&mut y, e, i, t0, nt, t)
                });
                t0 += nt;
                continue;
            }
        };
        let prepared = match both {
            Some(ok) => ok,
            None if nt1 > 0 => a.prepare(1, w.packed_tile(t1, nb, &mut pack, &mut buf)),
            None => a.prepare(1, tile),
        };
        // The next pair's weights stream in (into L2) while this pair is multiplied.
        let ahead = w.stored_rows(t0 + 2 * R, (t0 + 4 * R).min(y.hi()));
        // The two tiles' columns are adjacent (t1 = t0 + 8): one segment per row.
        let cols = nt + nt1;
        let done = if prepared && amx_planned > 0 {
            amx_pair(a, p, amx_planned, n_in, ahead, &mut y, e, t0, cols)
        } else {
            0
        };
        let rest = if done > 0 { &[][..] } else { ahead };
        // The rows after the AMX rows (all of them without AMX) on the pair
        // kernel where the pair and the panel are laid out for it
        // (unsigned, grouped: no AMX), else (and if it refused: not
        // reached, kept so that a refusal never leaves outputs unwritten)
        // per tile on the 8-row kernel.
        let on_pair = prepared
            && a.ready()
            && pair_rows(a, p, done, n_rows, n_in, rest, |i0, rows| {
                put_rows(&mut y, e, i0, t0, cols, rows)
            });
        if !on_pair {
            for (tt, ntt) in [(t0, nt), (t1, nt1)] {
                if ntt > 0 {
                    let tile = w.packed_tile(tt, nb, &mut pack, &mut buf);
                    tile_rows(tile, p, n_rows, done, n_in, &[], |i, t| {
                        put_row(&mut y, e, i, tt, ntt, t)
                    });
                }
            }
        }
        t0 += cols;
    }
}

/// How many packed tiles ahead [`q8_panel_packed`] prefetches (into L2;
/// see [`simd::prefetch_l2`]).
const PREFETCH_TILES: usize = 2;

/// The fewest rows of a panel for which the AMX kernel runs (below it the
/// VNNI rows with the next tile's prefetch are as fast: the S step's panels).
const AMX_MIN_ROWS: usize = 16;

/// The fewest rows of a panel for which tiles go in laid-out pairs
/// ([`simd::gemm_q8_pair`]): below it, laying out the pair costs more than
/// the 16-row kernel saves (a streaming step's panels of 1-10 rows lost 2-8
/// points of peak: docs/PERFORMANCE.md).
const PAIR_MIN_ROWS: usize = 16;

/// `y[i0 + m][t0..t0 + nt]` = the epilogue of `rows[m][..nt]`, every row of
/// a tile pair call at once ([`simd::bias_act_rows`]: the rows' GELUs
/// interleaved), then copied out: the values [`put_row`] gives, bit for bit.
#[inline]
fn put_rows(
    y: &mut Cols<'_>,
    e: Epilogue<'_>,
    i0: usize,
    t0: usize,
    nt: usize,
    rows: &mut [[f32; simd::AMX_COLS]],
) {
    const C: usize = simd::AMX_COLS;
    let nt = nt.min(C);
    // The bias of the call's columns: the model's own 16 values where the
    // call has 16 columns (no copy: it was a `memcpy` call per pair call),
    // else copied, 0 past them (those lanes are dropped).
    let mut b = [0f32; C];
    let bias: Option<&[f32; C]> = match e.bias {
        None => None,
        Some(bias) => Some(match <&[f32; C]>::try_from(&bias[t0..t0 + nt]) {
            Ok(full) => full,
            Err(_) => {
                b[..nt].copy_from_slice(&bias[t0..t0 + nt]);
                &b
            }
        }),
    };
    simd::bias_act_rows(rows, bias, e.gelu);
    for (m, r) in rows.iter().enumerate() {
        let seg = y.seg(i0 + m, t0, t0 + nt);
        match <&mut [f32; C]>::try_from(&mut *seg) {
            Ok(full) => *full = *r,
            Err(_) => seg.copy_from_slice(&r[..nt]),
        }
    }
}

/// `y[i][t0..t0 + nt]` = the epilogue of `t[..nt]` ([`Epilogue::put`]).
#[inline]
fn put_row(y: &mut Cols<'_>, e: Epilogue<'_>, i: usize, t0: usize, nt: usize, t: &[f32]) {
    e.put(y.seg(i, t0, t0 + nt), t0, &t[..nt])
}

/// Most activation rows per call of the packed int8 kernel. The rows of a
/// panel go in the fewest calls, shared evenly ([`simd::even_passes`]): a
/// GPT step's 10 rows in one call, 16 as 8 + 8, 20 as 10 + 10. Each call
/// reads the tile's blocks and widens their scales once for all its rows
/// (on AVX-512 VNNI 12 accumulators and the two blocks' groups still fit
/// the 32 registers). Measured on AVX512-VNNI (2026-12-03, int8 x8, 128 MB
/// of distinct weights): at most 12 against at most 8 rows per call, 10
/// rows of 3072x768 / 768x3072 / 2304x768 / 768x768 0.86-0.92x the time
/// cold, 0.71-0.83x hot; 12 and 20 rows 0.86-0.98x. Until then 8, and until
/// 2026-12-03 morning 8 + 2 for 10 rows (5 + 5 was ~8% faster). A row's
/// numbers do not depend on its call's size. The AVX2 and NEON packed
/// kernels split a call into passes of at most 4 rows themselves.
const PACKED_CALL_ROWS: usize = 12;

/// `$run!(n)` for the row count `$mt` (a `const` per listed count; larger
/// counts take `$last`).
macro_rules! by_rows {
    ($mt:expr, $run:ident, [$($n:literal),*], $last:literal) => {
        match $mt {
            $($n => $run!($n),)*
            _ => $run!($last),
        }
    };
}

/// [`vnni_rows`] from row `r0` to the end of a panel of `rows` rows in
/// either layout: a grouped panel (only where the tile pair kernel refused)
/// one row at a time, each gathered back into one piece.
#[inline]
fn tile_rows(
    tile: simd::PackedQ8<'_>,
    p: &Q8Panel<'_>,
    rows: usize,
    r0: usize,
    n_in: usize,
    ahead: &[u8],
    mut put: impl FnMut(usize, &[f32; simd::PACK_ROWS]),
) {
    if !p.grouped {
        return vnni_rows(tile, p, r0, rows, n_in, ahead, put);
    }
    grouped_tile_rows(tile, p, rows, r0, n_in, &mut put);
}

/// [`tile_rows`] on a grouped panel (one instance for every caller: it is
/// not reached unless the pair kernel refused).
#[inline(never)]
fn grouped_tile_rows(
    tile: simd::PackedQ8<'_>,
    p: &Q8Panel<'_>,
    rows: usize,
    r0: usize,
    n_in: usize,
    put: &mut dyn FnMut(usize, &[f32; simd::PACK_ROWS]),
) {
    let mut room = RowRoom::new();
    for r in r0..rows {
        let one = grouped_row(p, rows, r, n_in, &mut room);
        vnni_rows(tile, &one, 0, 1, n_in, &[], |_, t| put(r, t));
    }
}

/// Activation rows `r0..r1` of a panel against one packed tile on
/// [`simd::gemm_q8_packed_ahead`], in calls of up to [`PACKED_CALL_ROWS`]
/// rows (`put(row, values)`), prefetching `ahead` (each call its share:
/// [`simd::part_bytes`]).
#[inline]
fn vnni_rows(
    tile: simd::PackedQ8<'_>,
    p: &Q8Panel<'_>,
    r0: usize,
    r1: usize,
    n_in: usize,
    ahead: &[u8],
    mut put: impl FnMut(usize, &[f32; simd::PACK_ROWS]),
) {
    let nb = n_in / Q8_BLOCK;
    calls_of(r0, r1, PACKED_CALL_ROWS, ahead, |i0, mt, share| {
        let pr = |m: usize| i0 + m.min(mt - 1);
        let q = |m: usize| &p.q[pr(m) * n_in..(pr(m) + 1) * n_in];
        let d = |m: usize| &p.d[pr(m) * nb..(pr(m) + 1) * nb];
        let c = |m: usize| &p.c[2 * pr(m) * nb..2 * (pr(m) + 1) * nb];
        macro_rules! run {
            ($m:literal) => {{
                let t = simd::gemm_q8_packed_ahead::<$m>(
                    tile,
                    core::array::from_fn(q),
                    core::array::from_fn(d),
                    core::array::from_fn(c),
                    share,
                );
                for (m, r) in t.iter().enumerate() {
                    put(i0 + m, r);
                }
            }};
        }
        by_rows!(mt, run, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11], 12);
    });
}

/// Rows `r0..r1` in the fewest calls of at most `most` rows, shared evenly
/// ([`simd::even_passes`]): `call(first row, rows, share)`, where the
/// calls' shares split `ahead` in order ([`simd::part_bytes`]).
#[inline(always)]
fn calls_of(
    r0: usize,
    r1: usize,
    most: usize,
    ahead: &[u8],
    mut call: impl FnMut(usize, usize, &[u8]),
) {
    let rows = r1.saturating_sub(r0);
    let calls = rows.div_ceil(most);
    let mut k = 0;
    simd::even_passes(rows, most, &mut |m0, mt| {
        let (a0, a1) = simd::part_bytes(ahead.len(), k, calls);
        k += 1;
        call(r0 + m0, mt, &ahead[a0..a1]);
    });
}

/// Activation rows `r0..r1` of a panel against the tile pair `a`
/// ([`simd::gemm_q8_pair`]), in calls of up to [`simd::PAIR_CALL_ROWS`]
/// rows shared evenly (`put(first row, rows)`: each call's rows of 16 columns, to be finished in place), prefetching
/// `ahead` (each call its share); false (rows from the refused call on not
/// written) if the kernel refuses.
#[inline]
fn pair_rows(
    a: &simd::TilePair,
    p: &Q8Panel<'_>,
    r0: usize,
    r1: usize,
    n_in: usize,
    ahead: &[u8],
    mut put: impl FnMut(usize, &mut [[f32; simd::AMX_COLS]]),
) -> bool {
    // The kernel reads the panel's call groups: all of its rows.
    if !p.grouped || r0 != 0 {
        return false;
    }
    let nb = n_in / Q8_BLOCK;
    let mut ok = true;
    calls_of(r0, r1, simd::PAIR_CALL_ROWS, ahead, |i0, mt, share| {
        let (q, d, c) = (&p.q[i0 * n_in..], &p.d[i0 * nb..], &p.c[2 * i0 * nb..]);
        macro_rules! run {
            ($m:literal) => {{
                match simd::gemm_q8_pair::<$m>(a, q, d, c, n_in, share) {
                    Some(mut t) if ok => put(i0, &mut t),
                    _ => ok = false,
                }
            }};
        }
        // Panels of PAIR_MIN_ROWS = 16 rows or more are shared into calls of
        // 5-8 rows (`even_passes`, checked for 16-20000 rows): no kernel
        // instance for 1-4 rows (C library size); such a call would refuse.
        match mt {
            5 => run!(5),
            6 => run!(6),
            7 => run!(7),
            8 => run!(8),
            _ => ok = false,
        }
    });
    ok
}

/// The first `rows` activation rows of a panel (whole row groups:
/// [`simd::amx_rows`]) against the two tiles prepared in `a`, on the AMX
/// kernel in one call, which writes `y`'s columns `t0 .. t0 + cols` of
/// those rows through the epilogue `e` itself, prefetching `ahead`;
/// returns the rows done.
#[allow(clippy::too_many_arguments)]
fn amx_pair(
    a: &simd::TilePair,
    p: &Q8Panel<'_>,
    rows: usize,
    n_in: usize,
    ahead: &[u8],
    y: &mut Cols<'_>,
    e: Epilogue<'_>,
    t0: usize,
    cols: usize,
) -> usize {
    let nb = n_in / Q8_BLOCK;
    let bias = e.bias.map(|b| &b[t0..t0 + cols]);
    simd::gemm_q8_packed_amx(
        a,
        &p.q[..rows * n_in],
        n_in,
        &p.d[..rows * nb],
        y.window(0, rows, t0, t0 + cols),
        bias,
        e.gelu,
        ahead,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pair_rows` has kernel instances for calls of 5-8 rows only: every
    /// panel that takes tile pairs (>= PAIR_MIN_ROWS rows) is shared into
    /// such calls.
    #[test]
    fn pair_panels_make_calls_of_five_to_eight_rows() {
        for rows in PAIR_MIN_ROWS..=8192 {
            let mut next = 0;
            pair_groups(rows, &mut |i0, mt| {
                assert_eq!(i0, next, "{rows} rows");
                assert!(
                    (5..=simd::PAIR_CALL_ROWS).contains(&mt),
                    "{rows} rows: a call of {mt}"
                );
                next += mt;
            });
            assert_eq!(next, rows);
        }
    }

    /// A grouped panel holds every row's quantised blocks (written by
    /// [`quantise_grouped`], read back by [`grouped_row`]: equal to the
    /// row-major quantisation), and the refused-pair fallback over it
    /// ([`tile_rows`]) gives what the row-major panel gives, bit for bit, for
    /// panel sizes whose call groups are 8, 7 and mixed rows.
    #[test]
    fn grouped_panels_keep_every_row_and_the_fallback_reads_them() {
        let (n_in, nb) = (96, 3);
        let mut s = 0x2545_f491u32;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s % 2001) as f32 / 1000.0 - 1.0
        };
        // One packed tile of 8 weight rows.
        let v: std::vec::Vec<u8> = (0..nb * simd::PACK_BLOCK_VALUES)
            .map(|i| (i * 37 % 251) as u8)
            .collect();
        let mut group = v.clone();
        for _ in 0..nb * simd::PACK_BLOCK_SCALES / 2 {
            group.extend_from_slice(
                &half::f16::from_f32(0.01 + next().abs() * 0.02)
                    .to_bits()
                    .to_le_bytes(),
            );
        }
        let tile = simd::PackedQ8::from_group(&group, nb).expect("one group");
        for rows in [16usize, 17, 21, 29] {
            let x: std::vec::Vec<f32> = (0..rows * n_in).map(|_| next()).collect();
            let (mut q, mut d, mut c) = (
                vec![0i8; rows * n_in],
                vec![0f32; rows * nb],
                vec![0i32; 2 * rows * nb],
            );
            let (mut gq, mut gd, mut gc) = (q.clone(), d.clone(), c.clone());
            for i in 0..rows {
                simd::quantise_q8_corr(
                    &x[i * n_in..(i + 1) * n_in],
                    &mut q[i * n_in..(i + 1) * n_in],
                    &mut d[i * nb..(i + 1) * nb],
                    &mut c[2 * i * nb..2 * (i + 1) * nb],
                );
            }
            quantise_grouped(&x, n_in, &mut gq, &mut gd, &mut gc);
            let plain = Q8Panel {
                q: &q,
                d: &d,
                c: &c,
                grouped: false,
            };
            let grouped = Q8Panel {
                q: &gq,
                d: &gd,
                c: &gc,
                grouped: true,
            };
            let mut room = RowRoom::new();
            for r in 0..rows {
                let one = grouped_row(&grouped, rows, r, n_in, &mut room);
                assert_eq!(
                    one.q,
                    &q[r * n_in..(r + 1) * n_in],
                    "rows {rows} row {r} values"
                );
                assert_eq!(
                    one.d,
                    &d[r * nb..(r + 1) * nb],
                    "rows {rows} row {r} scales"
                );
                assert_eq!(
                    one.c,
                    &c[2 * r * nb..2 * (r + 1) * nb],
                    "rows {rows} row {r} corrections"
                );
            }
            // Grouped memory is a permutation within each call group, not a copy.
            assert_ne!(gq, q, "rows {rows}");
            let (mut want, mut got) = (vec![f32::NAN; rows * 8], vec![f32::NAN; rows * 8]);
            vnni_rows(tile, &plain, 3, rows, n_in, &[], |i, t| {
                want[8 * i..8 * i + 8].copy_from_slice(t)
            });
            tile_rows(tile, &grouped, rows, 3, n_in, &[], |i, t| {
                got[8 * i..8 * i + 8].copy_from_slice(t)
            });
            let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<std::vec::Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "rows {rows}");
            assert!(
                got[..24].iter().all(|v| v.is_nan()) && got[24..].iter().all(|v| v.is_finite())
            );
        }
    }
}
