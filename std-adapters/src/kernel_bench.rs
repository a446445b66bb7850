//! The int8 GEMM shapes the engine runs against this CPU's int8
//! multiply-accumulate peak (issue #40): `duolando bench --kernels` and
//! `cargo bench -p duolando --bench kernels -- peak` print them.
//!
//! - the peak: the register-only probes of
//!   `duolando_core::kernels::simd::peak` (each checked against its scalar
//!   twin here as well, so a figure never comes from a wrong loop), timed
//!   on the calling thread, GMAC/s = int8 multiply-accumulates per second;
//! - the shapes: `linear` over `Q8Block32x8` weights (what `convert --dtype
//!   int8` writes) at the Duolando GPT's matrices (768 -> 768 attention
//!   projections, 768 -> 3072 and 3072 -> 768 MLP) for the row counts it
//!   runs them at: the R step (29-token window x 10 streams = 290 rows, one
//!   panel in caller memory as `BlockScratch` gives it), a re-prefill chunk
//!   (`REPREFILL_CHUNK` = 8 window rows = 80), 16 sessions in one
//!   `step_many` (160), an S step (10 rows) and a LAT push (1 row); shapes
//!   of fewer than 64 rows cycle over 64 MB of distinct matrices, so their
//!   weights come from memory as in a step, larger ones reuse one matrix
//!   (compute-bound). Achieved GMAC/s = rows x out x in / time, and its
//!   fraction of the selected ISA's probe ([`Probe::for_isa`]), measured
//!   again right before each shape (on a shared machine the two figures of
//!   a ratio should come from the same moment); the peak printed is the
//!   median of those.

use std::time::Instant;

use duolando_core::arena::Arena;
use duolando_core::kernels::simd::peak::{self, Operands, Probe};
use duolando_core::kernels::simd::{self, Isa};
use duolando_core::kernels::{linear_with, Matrix, Q8Room, X8Rows};

use crate::duo_writer::quantise_q8_block32x8;

/// One GEMM shape: `rows` activation rows times an `out x inp` matrix.
#[derive(Clone, Copy, Debug)]
pub struct Shape {
    /// JSON key part (`r_fc`, `s_fc_out`, ...).
    pub key: &'static str,
    /// In words.
    pub what: &'static str,
    pub rows: usize,
    pub out: usize,
    pub inp: usize,
}

/// The shapes measured (largest R-step GEMM first).
pub const SHAPES: [Shape; 11] = [
    Shape {
        key: "r_fc",
        what: "R step MLP fc",
        rows: 290,
        out: 3072,
        inp: 768,
    },
    Shape {
        key: "r_fc_out",
        what: "R step MLP fc_out",
        rows: 290,
        out: 768,
        inp: 3072,
    },
    Shape {
        key: "r_proj",
        what: "R step q/k/v/proj",
        rows: 290,
        out: 768,
        inp: 768,
    },
    Shape {
        key: "batch16_fc",
        what: "16 sessions step_many fc",
        rows: 160,
        out: 3072,
        inp: 768,
    },
    Shape {
        key: "batch16_fc_out",
        what: "16 sessions step_many fc_out",
        rows: 160,
        out: 768,
        inp: 3072,
    },
    Shape {
        key: "prefill_fc",
        what: "re-prefill chunk fc",
        rows: 80,
        out: 3072,
        inp: 768,
    },
    Shape {
        key: "prefill_fc_out",
        what: "re-prefill chunk fc_out",
        rows: 80,
        out: 768,
        inp: 3072,
    },
    Shape {
        key: "s_fc",
        what: "S step fc",
        rows: 10,
        out: 3072,
        inp: 768,
    },
    Shape {
        key: "s_fc_out",
        what: "S step fc_out",
        rows: 10,
        out: 768,
        inp: 3072,
    },
    Shape {
        key: "s_proj",
        what: "S step q/k/v/proj",
        rows: 10,
        out: 768,
        inp: 768,
    },
    Shape {
        key: "lat_proj",
        what: "LAT push q/k/v/proj",
        rows: 1,
        out: 768,
        inp: 768,
    },
];

/// The CPU's model name (`/proc/cpuinfo`'s `model name`; elsewhere, or
/// where it has none, the architecture).
pub fn cpu_name() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| format!("unknown {} CPU", std::env::consts::ARCH))
}

/// The probes this CPU can run, best first.
pub fn probes() -> Vec<Probe> {
    Probe::ALL.iter().copied().filter(|&p| cpu_has(p)).collect()
}

fn cpu_has(p: Probe) -> bool {
    crate::simd::probe_supported(p)
}

/// The fixed operands the probes multiply (unsigned side below 128, as the
/// kernels' sign trick keeps it, so no `vpmaddubsw` saturation).
fn operands() -> Operands {
    let mut o = Operands {
        a: [0; 64],
        b: [0; 64],
    };
    for i in 0..64 {
        o.a[i] = (i * 37 % 128) as u8;
        o.b[i] = (i as i32 * 53 % 255 - 127) as i8;
    }
    o
}

/// Probe `p`'s GMAC/s on the calling thread: the median of 7 runs of
/// about 20 ms each (after one to size them); an error if a run's
/// checksum differs from the scalar twin's.
pub fn peak_gmacs(p: Probe) -> anyhow::Result<f64> {
    anyhow::ensure!(
        cpu_has(p),
        "this CPU ({}) cannot run the {} probe",
        cpu_name(),
        p.name()
    );
    let o = operands();
    let time = |iters: u64| -> anyhow::Result<f64> {
        let s = Instant::now();
        let got = crate::simd::run_probe(p, iters, std::hint::black_box(&o));
        let t = s.elapsed().as_secs_f64();
        let got = got.ok_or_else(|| anyhow::anyhow!("no {} probe in this build", p.name()))?;
        anyhow::ensure!(
            got == peak::twin(p, iters, &o),
            "{} probe: checksum {got} differs from its twin's",
            p.name()
        );
        Ok(t)
    };
    let mut iters = 1u64 << 16;
    while time(iters)? < 0.005 && iters < 1 << 34 {
        iters *= 4;
    }
    let t1 = time(iters)?;
    let iters = ((iters as f64) * 0.02 / t1.max(1e-9)).max(1.0) as u64;
    let mut t: Vec<f64> = (0..7).map(|_| time(iters)).collect::<anyhow::Result<_>>()?;
    t.sort_by(|a, b| a.total_cmp(b));
    Ok((iters * p.macs_per_iter()) as f64 / t[3] / 1e9)
}

/// One shape's figures under one ISA.
#[derive(Clone, Copy, Debug)]
pub struct ShapeFigure {
    pub shape: Shape,
    /// Median ms per call.
    pub ms: f64,
    pub gmacs: f64,
    /// The ISA's probe, measured right before the shape.
    pub peak_gmacs: f64,
    /// `gmacs` over `peak_gmacs`.
    pub of_peak: f64,
}

/// The kernel section under the ISA selected now.
#[derive(Clone, Debug)]
pub struct Report {
    pub isa: Isa,
    pub probe: Probe,
    pub peak_gmacs: f64,
    pub shapes: Vec<ShapeFigure>,
}

/// xorshift weights/activations in [-0.05, 0.05).
fn values(seed: &mut u64, n: usize) -> Vec<f32> {
    (0..n)
        .map(|_| {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            ((*seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * 0.05
        })
        .collect()
}

/// Median seconds of `reps` calls of `f` after one warm-up.
fn median_secs(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(|a, b| a.total_cmp(b));
    t[t.len() / 2]
}

/// The distinct `Q8Block32x8` matrices of one (out, in) matrix shape.
type WeightSet = ((usize, usize), Vec<Vec<u8>>);

/// Weight sets, one per distinct (out, in), quantised once for every ISA.
pub struct Weights {
    sets: Vec<WeightSet>,
}

impl Weights {
    /// 64 MB of distinct `Q8Block32x8` matrices per matrix shape of
    /// [`SHAPES`] (`quick`: 16 MB).
    pub fn new(quick: bool) -> Weights {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut sets: Vec<WeightSet> = Vec::new();
        for s in SHAPES {
            if sets.iter().any(|(d, _)| *d == (s.out, s.inp)) {
                continue;
            }
            let bytes = s.out * s.inp * 34 / 32;
            let n = ((if quick { 16 } else { 64 } << 20) / bytes).max(2);
            // One random matrix, its copies with the rows rotated: distinct
            // bytes in memory, quantised once.
            let base = quantise_q8_block32x8(&values(&mut seed, s.out * s.inp), s.inp);
            let mut v = Vec::with_capacity(n);
            for k in 0..n {
                let mut m = base.clone();
                m.rotate_left((k * 8 * s.inp * 34 / 32) % base.len());
                v.push(m);
            }
            sets.push(((s.out, s.inp), v));
        }
        Weights { sets }
    }

    fn get(&self, out: usize, inp: usize) -> &[Vec<u8>] {
        &self
            .sets
            .iter()
            .find(|(d, _)| *d == (out, inp))
            .expect("a set per shape")
            .1
    }
}

/// Times every shape of [`SHAPES`] under the ISA selected now (one thread)
/// and the ISA's probe.
pub fn run(weights: &Weights, reps: usize) -> anyhow::Result<Report> {
    let isa = simd::isa();
    let probe = Probe::for_isa(isa);
    let mut seed = 0x5eedu64;
    let mut shapes = Vec::new();
    for s in SHAPES {
        let mats = weights.get(s.out, s.inp);
        let sets = if s.rows < 64 { mats.len() } else { 1 };
        let x = values(&mut seed, s.rows * s.inp);
        let b = values(&mut seed, s.out);
        let mut y = vec![0f32; s.rows * s.out];
        // The whole panel in caller memory, as R mode's blocks carve it.
        let mut room_bytes = vec![0u8; s.rows * s.inp * 2 + 4096];
        let mut arena = Arena::new(&mut room_bytes);
        let mut room = Q8Room::carve(&mut arena, s.rows * s.inp)
            .map_err(|e| anyhow::anyhow!("panel: {e:?}"))?;
        let reps = if s.rows >= 64 { reps.min(5) } else { reps };
        let peak = peak_gmacs(probe)?;
        let t = median_secs(reps, || {
            for m in &mats[..sets] {
                let w = Matrix::X8(X8Rows::new(m, s.out, s.inp).expect("a Q8Block32x8 matrix"));
                linear_with(&x, &w, Some(&b), &mut y, &mut room);
            }
            std::hint::black_box(&y);
        }) / sets as f64;
        anyhow::ensure!(
            y.iter().all(|v| v.is_finite()),
            "{}: non-finite output",
            s.what
        );
        let gmacs = (s.rows * s.out * s.inp) as f64 / t / 1e9;
        shapes.push(ShapeFigure {
            shape: s,
            ms: t * 1e3,
            gmacs,
            peak_gmacs: peak,
            of_peak: gmacs / peak,
        });
    }
    let mut peaks: Vec<f64> = shapes.iter().map(|f| f.peak_gmacs).collect();
    peaks.sort_by(|a, b| a.total_cmp(b));
    Ok(Report {
        isa,
        probe,
        peak_gmacs: peaks[peaks.len() / 2],
        shapes,
    })
}

impl Report {
    /// The report's lines, each starting with `label`.
    pub fn lines(&self, label: &str) -> Vec<String> {
        let mut v = vec![format!(
            "{label}int8 MAC peak ({}, register-only, {} chains): {:.1} GMAC/s (median of the measurements before each shape)",
            self.probe.name(),
            self.probe.chains(),
            self.peak_gmacs
        )];
        for f in &self.shapes {
            let s = f.shape;
            v.push(format!(
                "{label}int8x8 linear {:<29} {:>3} x {:>4} -> {:>4}: {:9.3} ms  {:7.1} GMAC/s  {:5.1}% of peak ({:.1} GMAC/s just before)",
                s.what,
                s.rows,
                s.inp,
                s.out,
                f.ms,
                f.gmacs,
                100.0 * f.of_peak,
                f.peak_gmacs
            ));
        }
        v
    }

    /// JSON entries (`peak_gmacs`, `gemm_<shape>_{ms,gmacs,of_peak}`), each
    /// key ending in `suffix`.
    pub fn json(&self, j: &mut serde_json::Map<String, serde_json::Value>, suffix: &str) {
        j.insert(format!("peak_gmacs{suffix}"), self.peak_gmacs.into());
        j.insert(format!("peak_probe{suffix}"), self.probe.name().into());
        for f in &self.shapes {
            let k = f.shape.key;
            j.insert(format!("gemm_{k}_ms{suffix}"), f.ms.into());
            j.insert(format!("gemm_{k}_gmacs{suffix}"), f.gmacs.into());
            j.insert(format!("gemm_{k}_of_peak{suffix}"), f.of_peak.into());
            j.insert(format!("gemm_{k}_peak_gmacs{suffix}"), f.peak_gmacs.into());
        }
    }
}
