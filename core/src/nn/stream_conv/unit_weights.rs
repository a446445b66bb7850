//! The weights of one unit, checked against its geometry, and a unit's
//! share of a batched computation.

use super::*;

/// The weights of one unit.
#[derive(Clone, Copy)]
pub(super) enum UnitW<'r, 'a> {
    Conv(&'r ConvW<'a>),
    Res(&'r ResBlockW<'a>),
    ConvT(&'r ConvTW<'a>),
}

impl UnitW<'_, '_> {
    pub(super) fn c_out(&self) -> usize {
        match self {
            UnitW::Conv(c) => c.c_out,
            UnitW::Res(r) => r.conv_1x1.c_out,
            UnitW::ConvT(t) => t.c_out,
        }
    }
}

/// A conv's shapes match its geometry and channels.
fn conv_fits(c: &ConvW<'_>, g: ConvGeom, c_in: usize, c_out: usize) -> bool {
    c.geom == g
        && c.c_in == c_in
        && c.c_out == c_out
        && mat_fits(&c.w, c_out, c_in * g.kernel)
        && c.b.len() == c_out
}

fn mat_fits(m: &Matrix<'_>, rows: usize, cols: usize) -> bool {
    m.rows() == rows && m.cols() == cols
}

impl<'r, 'a> UnitW<'r, 'a> {
    /// True if these weights implement `u` (channels of the last decoder
    /// unit: at most `u.c_out`).
    pub(super) fn fits(&self, u: &Unit, inner: usize, last: bool) -> bool {
        let c_out_ok = |c: usize| {
            if last {
                c <= u.c_out && c > 0
            } else {
                c == u.c_out
            }
        };
        let geom = ConvGeom {
            kernel: u.kernel,
            stride: u.stride,
            pad: u.pad,
            dilation: u.dilation,
        };
        match (self, u.kind) {
            (UnitW::Conv(c), UnitKind::Conv) => {
                c_out_ok(c.c_out) && conv_fits(c, geom, u.c_in, c.c_out)
            }
            (UnitW::Res(r), UnitKind::Res) => {
                let g1 = ConvGeom {
                    kernel: 1,
                    stride: 1,
                    pad: 0,
                    dilation: 1,
                };
                conv_fits(&r.conv_dil, geom, u.c_in, inner)
                    && conv_fits(&r.conv_1x1, g1, inner, u.c_out)
            }
            (UnitW::ConvT(t), UnitKind::ConvT) => {
                c_out_ok(t.c_out)
                    && t.c_in == u.c_in
                    && (t.kernel, t.stride, t.pad) == (u.kernel, u.stride, u.pad)
                    && t.w.c_in() == u.c_in
                    && t.w.z_cols() == t.c_out * t.kernel
                    && t.b.len() == t.c_out
            }
            _ => false,
        }
    }

    /// Runs the unit for every job at once (one GEMM per kernel tile for
    /// all of them): job `j`'s outputs `[a, a + n_out)` from its `n_in`
    /// input columns gathered from `g0`, the jobs' inputs one after another
    /// in `x` (modified: ReLU in place for a residual block), their outputs
    /// likewise in `y`. `h`, `r`: residual scratch; `tile`: the kernel tile
    /// (im2col for a conv, the transposed conv's otherwise).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run(
        &self,
        u: &Unit,
        jobs: &[Job],
        x: &mut [f32],
        y: &mut [f32],
        h: &mut [f32],
        r: &mut [f32],
        tile: &mut [f32],
    ) -> Result<(), Error> {
        let mut segs: Vec<ConvSeg, MAX_STACKS> = Vec::new();
        for j in jobs {
            let pad = u.local_pad(j.a, j.g0).ok_or(Error::Length {
                buffer: Buffer::Features,
                len: j.g0,
                expected: j.a,
            })?;
            segs.push(ConvSeg {
                t_in: j.n_in,
                t_out: j.n_out,
                pad,
            })
            .map_err(|_| Error::State)?;
        }
        let (n_in, n_out) = (
            jobs.iter().map(|j| j.n_in).sum::<usize>(),
            jobs.iter().map(|j| j.n_out).sum::<usize>(),
        );
        let oc = self.c_out();
        if x.len() != n_in * u.c_in || y.len() != n_out * oc {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: y.len(),
                expected: n_out * oc,
            });
        }
        let geom = ConvGeom {
            kernel: u.kernel,
            stride: u.stride,
            pad: 0,
            dilation: u.dilation,
        };
        let need = match self {
            UnitW::ConvT(t) => convt_z_len(t.c_out, t.kernel),
            _ => conv1d_col_len(u.c_in, u.kernel),
        };
        if need > tile.len() {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: tile.len(),
                expected: need,
            });
        }
        match self {
            UnitW::Conv(c) => conv1d_segs(x, c.c_in, &c.w, c.b, geom, &segs, y, tile),
            UnitW::ConvT(t) => {
                conv_transpose1d_segs(x, &t.w, t.b, t.kernel, t.stride, &segs, y, tile)
            }
            UnitW::Res(b) => {
                let (w, inner) = (b.conv_dil.c_in, b.conv_dil.c_out);
                // Identity: output a + t of a job is its gathered row a + t - g0.
                let (mut xo, mut yo) = (0, 0);
                for j in jobs {
                    let id = (xo + j.a.saturating_sub(j.g0)) * w;
                    let src = x.get(id..id + j.n_out * w).ok_or(Error::Length {
                        buffer: Buffer::Features,
                        len: x.len(),
                        expected: id + j.n_out * w,
                    })?;
                    y[yo * w..(yo + j.n_out) * w].copy_from_slice(src);
                    xo += j.n_in;
                    yo += j.n_out;
                }
                relu_inplace(x);
                let h = first(h, n_out * inner)?;
                conv1d_segs(x, w, &b.conv_dil.w, b.conv_dil.b, geom, &segs, h, tile);
                relu_inplace(h);
                let r = first(r, n_out * w)?;
                let g1 = ConvGeom {
                    kernel: 1,
                    stride: 1,
                    pad: 0,
                    dilation: 1,
                };
                conv1d(h, inner, &b.conv_1x1.w, b.conv_1x1.b, g1, r, tile);
                for (o, v) in y.iter_mut().zip(r.iter()) {
                    *o += v;
                }
            }
        }
        Ok(())
    }
}

/// One stack's share of a unit computed for several stacks at once.
#[derive(Clone, Copy, Debug)]
pub(super) struct Job {
    /// First output column.
    pub(super) a: usize,
    /// First gathered input column.
    pub(super) g0: usize,
    pub(super) n_in: usize,
    pub(super) n_out: usize,
}

/// The first `n` floats of `b`, or a length error.
pub(super) fn first(b: &mut [f32], n: usize) -> Result<&mut [f32], Error> {
    let len = b.len();
    b.get_mut(..n).ok_or(Error::Length {
        buffer: Buffer::Features,
        len,
        expected: n,
    })
}
