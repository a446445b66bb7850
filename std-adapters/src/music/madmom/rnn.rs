//! madmom's downbeat networks: an ensemble of bidirectional LSTM stacks
//! with a 3-way softmax (non-beat, beat, downbeat), averaged
//! (`madmom.ml.nn`: `BidirectionalLayer`, `LSTMLayer` with peephole
//! gates, `FeedForwardLayer`, `average_predictions`), read from the plain
//! file `tools/madmom_weights.py` writes (format in its docstring and
//! docs/TRANSFLOWER.md).
//!
//! One LSTM step, as madmom computes it (`Gate.activate` order):
//! `i = sig(x Wi + bi + c' pi + h' Ri)`, `f = sig(x Wf + bf + c' pf + h' Rf)`,
//! `g = tanh(x Wc + bc + h' Rc)`, `c = g i + c' f`,
//! `o = sig(x Wo + bo + c po + h' Ro)`, `h = tanh(c) o`; zero initial state.

use thiserror::Error;

/// The file's first bytes.
pub const MAGIC: &[u8; 8] = b"DUOMMRNN";
pub const VERSION: u32 = 1;
/// Limits on a header (madmom's downbeat ensemble: 8 networks, 3 layers of 25).
pub const MAX_NETS: u32 = 64;
pub const MAX_LAYERS: u32 = 16;
pub const MAX_HIDDEN: u32 = 1024;
pub const MAX_INPUTS: u32 = 4096;
/// Outputs: non-beat, beat, downbeat.
pub const OUTPUTS: u32 = 3;

/// Why a downbeat network file was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RnnFileError {
    #[error("not a madmom network file of the engine (magic {found:?}, want \"DUOMMRNN\"; convert madmom's models with tools/madmom_weights.py)")]
    Magic { found: Vec<u8> },
    #[error("network file version {0}, this engine reads version 1")]
    Version(u32),
    #[error("network file header: {field} = {value} (allowed {min}..={max})")]
    Header {
        field: &'static str,
        value: u32,
        min: u32,
        max: u32,
    },
    #[error("network file: {got} bytes, the header's sizes need {expected}")]
    Length { got: usize, expected: usize },
    #[error("network file: weight {index} is {value} (not finite)")]
    NonFinite { index: usize, value: f32 },
    /// Finite weights can still overflow f32 (a hostile or corrupt file).
    #[error("the networks' output at frame {frame} is not finite (weights that overflow f32)")]
    NonFiniteOutput { frame: usize },
}

/// One gate's weights: W (in, hidden), bias, recurrent (hidden, hidden), peephole.
struct Gate {
    w: Vec<f32>,
    b: Vec<f32>,
    r: Vec<f32>,
    /// Empty for the cell.
    p: Vec<f32>,
}

/// Input, forget, cell, output gates of one direction of one layer.
struct Lstm {
    gates: [Gate; 4],
}

struct Network {
    /// Per layer: (forward, backward).
    layers: Vec<(Lstm, Lstm)>,
    /// (2 hidden, 3) and (3,).
    out_w: Vec<f32>,
    out_b: Vec<f32>,
}

/// The ensemble of a network file.
pub struct Ensemble {
    nets: Vec<Network>,
    inputs: usize,
    hidden: usize,
}

/// Reads f32s off the file's body in order.
struct Reader<'a> {
    body: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Vec<f32> {
        let b = &self.body[self.at * 4..(self.at + n) * 4];
        self.at += n;
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    }
}

fn header_field(bytes: &[u8], i: usize) -> u32 {
    let o = 8 + 4 * i;
    u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]])
}

impl Ensemble {
    /// Parses a file's bytes: header limits, exact length, every weight finite.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, RnnFileError> {
        const HEADER: usize = 8 + 6 * 4;
        if bytes.len() < HEADER || &bytes[..8] != MAGIC {
            return Err(RnnFileError::Magic {
                found: bytes[..bytes.len().min(8)].to_vec(),
            });
        }
        let version = header_field(bytes, 0);
        if version != VERSION {
            return Err(RnnFileError::Version(version));
        }
        let field = |i: usize, name: &'static str, min: u32, max: u32| {
            let v = header_field(bytes, i);
            if (min..=max).contains(&v) {
                Ok(v as usize)
            } else {
                Err(RnnFileError::Header {
                    field: name,
                    value: v,
                    min,
                    max,
                })
            }
        };
        let nets = field(1, "networks", 1, MAX_NETS)?;
        let inputs = field(2, "inputs", 1, MAX_INPUTS)?;
        let layers = field(3, "layers", 1, MAX_LAYERS)?;
        let hidden = field(4, "hidden", 1, MAX_HIDDEN)?;
        field(5, "outputs", OUTPUTS, OUTPUTS)?;
        let out = OUTPUTS as usize;
        // per direction: 4 gates of (in + hidden + 1) x hidden, 3 peepholes;
        // checked: the limits' product overflows a 32-bit usize
        let dir = |width: usize| -> Option<usize> {
            (width + hidden + 1)
                .checked_mul(hidden)?
                .checked_mul(4)?
                .checked_add(3 * hidden)
        };
        let per_net = (|| {
            let first = dir(inputs)?.checked_mul(2)?;
            let upper = dir(2 * hidden)?.checked_mul(2)?.checked_mul(layers - 1)?;
            first
                .checked_add(upper)?
                .checked_add(2 * hidden * out + out)
        })();
        let expected = per_net
            .and_then(|p| p.checked_mul(nets)?.checked_mul(4)?.checked_add(HEADER))
            .unwrap_or(usize::MAX);
        if bytes.len() != expected {
            return Err(RnnFileError::Length {
                got: bytes.len(),
                expected,
            });
        }
        let body = &bytes[HEADER..];
        for (index, c) in body.chunks_exact(4).enumerate() {
            let value = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
            if !value.is_finite() {
                return Err(RnnFileError::NonFinite { index, value });
            }
        }
        let mut rd = Reader { body, at: 0 };
        let lstm = |width: usize, rd: &mut Reader<'_>| {
            let mut gate = |peep: bool| Gate {
                w: rd.take(width * hidden),
                b: rd.take(hidden),
                r: rd.take(hidden * hidden),
                p: if peep { rd.take(hidden) } else { Vec::new() },
            };
            let gates = [gate(true), gate(true), gate(false), gate(true)];
            Lstm { gates }
        };
        let nets = (0..nets)
            .map(|_| {
                let layers = (0..layers)
                    .map(|l| {
                        let width = if l == 0 { inputs } else { 2 * hidden };
                        (lstm(width, &mut rd), lstm(width, &mut rd))
                    })
                    .collect();
                Network {
                    layers,
                    out_w: rd.take(2 * hidden * out),
                    out_b: rd.take(out),
                }
            })
            .collect();
        Ok(Ensemble {
            nets,
            inputs,
            hidden,
        })
    }

    /// Inputs per frame the networks take.
    pub fn inputs(&self) -> usize {
        self.inputs
    }

    /// Networks in the ensemble.
    pub fn len(&self) -> usize {
        self.nets.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nets.is_empty()
    }

    /// Beat and downbeat activations of `x` (frames, inputs): the mean of
    /// the networks' softmax outputs without the non-beat column.
    ///
    /// Refused if a value is not finite (weights that overflow f32).
    /// Panics if `x` is not a whole number of rows of [`Self::inputs`].
    pub fn activations(&self, x: &[f32]) -> Result<Vec<[f32; 2]>, RnnFileError> {
        assert_eq!(x.len() % self.inputs, 0, "rows of {} inputs", self.inputs);
        let frames = x.len() / self.inputs;
        let mut sum = vec![[0f32; 3]; frames];
        for net in &self.nets {
            let p = net.forward(x, frames, self.inputs, self.hidden);
            for (s, q) in sum.iter_mut().zip(&p) {
                for k in 0..3 {
                    s[k] += q[k];
                }
            }
        }
        let n = self.nets.len() as f32;
        if let Some(frame) = sum.iter().position(|s| !s.iter().all(|v| v.is_finite())) {
            return Err(RnnFileError::NonFiniteOutput { frame });
        }
        Ok(sum.iter().map(|s| [s[1] / n, s[2] / n]).collect())
    }
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// `out[j] += sum_i x[i] w[i, j]` for w (x.len(), out.len()) row-major.
fn acc_dot(x: &[f32], w: &[f32], out: &mut [f32]) {
    let n = out.len();
    for (xi, row) in x.iter().zip(w.chunks_exact(n)) {
        for (o, &wv) in out.iter_mut().zip(row) {
            *o += xi * wv;
        }
    }
}

impl Lstm {
    /// Runs over `x` (frames, width) forwards or backwards; writes h into
    /// columns `col..col + hidden` of `out` (frames, 2 hidden) at each frame's own row.
    fn run(
        &self,
        x: &[f32],
        width: usize,
        hidden: usize,
        backwards: bool,
        out: &mut [f32],
        col: usize,
    ) {
        let frames = x.len() / width;
        let (mut h, mut c) = (vec![0f32; hidden], vec![0f32; hidden]);
        let mut pre = [
            vec![0f32; hidden],
            vec![0f32; hidden],
            vec![0f32; hidden],
            vec![0f32; hidden],
        ];
        for step in 0..frames {
            let t = if backwards { frames - 1 - step } else { step };
            let xt = &x[t * width..(t + 1) * width];
            for (p, g) in pre.iter_mut().zip(&self.gates) {
                p.copy_from_slice(&g.b);
                acc_dot(xt, &g.w, p);
            }
            let [gi, gf, gc, go] = &self.gates;
            let [pi, pf, pc, po] = &mut pre;
            for j in 0..hidden {
                pi[j] += c[j] * gi.p[j];
                pf[j] += c[j] * gf.p[j];
            }
            acc_dot(&h, &gi.r, pi);
            acc_dot(&h, &gf.r, pf);
            acc_dot(&h, &gc.r, pc);
            for j in 0..hidden {
                let i = sigmoid(pi[j]);
                let f = sigmoid(pf[j]);
                let g = pc[j].tanh();
                c[j] = g * i + c[j] * f;
            }
            for j in 0..hidden {
                po[j] += c[j] * go.p[j];
            }
            acc_dot(&h, &go.r, po);
            for j in 0..hidden {
                h[j] = c[j].tanh() * sigmoid(po[j]);
            }
            out[t * 2 * hidden + col..t * 2 * hidden + col + hidden].copy_from_slice(&h);
        }
    }
}

impl Network {
    fn forward(&self, x: &[f32], frames: usize, inputs: usize, hidden: usize) -> Vec<[f32; 3]> {
        // (frames, 2 hidden) outputs of the last layer run; the first reads `x` in place
        let mut cur: Vec<f32> = Vec::new();
        for (l, (fwd, bwd)) in self.layers.iter().enumerate() {
            let (input, width) = if l == 0 {
                (x, inputs)
            } else {
                (&cur[..], 2 * hidden)
            };
            let mut next = vec![0f32; frames * 2 * hidden];
            fwd.run(input, width, hidden, false, &mut next, 0);
            bwd.run(input, width, hidden, true, &mut next, hidden);
            cur = next;
        }
        cur.chunks_exact(2 * hidden)
            .map(|h| {
                let mut z = [self.out_b[0], self.out_b[1], self.out_b[2]];
                acc_dot(h, &self.out_w, &mut z);
                let m = z[0].max(z[1]).max(z[2]);
                let e = z.map(|v| (v - m).exp());
                let s = e[0] + e[1] + e[2];
                e.map(|v| v / s)
            })
            .collect()
    }
}
