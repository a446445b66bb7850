//! The base distributions the flow maps from (models/moglow/modules.py
//! `GaussianDiag`, `StudentT`; no temperature: `FlowPlusPlus.forward`
//! hard-codes `eps_std = 1`), and where a step's base sample comes from:
//!
//! - [`Replay`]: the caller's recorded samples (N, C, H), e.g. the
//!   authors' noise recorded by tools/reference/transflower: the goldens
//!   are matched on this path.
//! - [`Seeded`]: drawn here from a seeded RNG, the same numbers on every
//!   target (NOT the authors' torch/numpy streams):
//!   - uniforms: SplitMix64 ([`crate::nn::sampler::Rng`]), the top 53 bits
//!     of a draw scaled to [0, 1);
//!   - N(0, 1): Box-Muller in f64 (`r = sqrt(-2 ln(1 - u1))`, angle `2 pi u2`,
//!     cos first, the sin value kept for the next draw), rounded to f32;
//!   - Student-t (df): per output position one `chi2(df) / df` = `2
//!     Gamma(df / 2, 1) / df` (Marsaglia-Tsang, f64; shape < 1 boosted by
//!     `U^(1/shape)`), rounded to f32, shared by every channel, then
//!     `z = N(0, 1) / sqrt(chi)` in f32 ([`student_t`], the authors'
//!     composition). Draw order per step: the H chi-squares, then the C x H
//!     normals channel-major (as the authors: numpy before torch).

use crate::error::{check_len, Buffer, Error};
use crate::nn::sampler::Rng;
use crate::transflower::config::{BaseDist, TransflowerConfig};

/// Gives step `t`'s base sample z (C, H) channel-major.
pub trait BaseSample {
    /// Checked before the first step: `steps` samples of `per_step` values.
    fn check(&self, steps: usize, per_step: usize) -> Result<(), Error> {
        let _ = (steps, per_step);
        Ok(())
    }
    fn sample(&mut self, step: usize, z: &mut [f32]);
}

/// Recorded samples (N, C, H): step t reads the t-th.
#[derive(Clone, Copy, Debug)]
pub struct Replay<'n> {
    pub noise: &'n [f32],
}

impl BaseSample for Replay<'_> {
    fn check(&self, steps: usize, per_step: usize) -> Result<(), Error> {
        check_len(
            Buffer::Features,
            self.noise.len(),
            steps.saturating_mul(per_step),
        )?;
        crate::input::check(Buffer::Features, self.noise)
    }
    fn sample(&mut self, step: usize, z: &mut [f32]) {
        let n = z.len();
        z.copy_from_slice(&self.noise[step * n..(step + 1) * n]);
    }
}

/// `z` (C, H) = `normal` (C, H) / sqrt(`chi_over_df` (H)) in f32: the
/// authors' Student-t composition (bit for bit).
pub fn student_t(normal: &[f32], chi_over_df: &[f32], z: &mut [f32]) {
    let h = chi_over_df.len();
    if h == 0 {
        return;
    }
    for (zr, nr) in z.chunks_exact_mut(h).zip(normal.chunks_exact(h)) {
        for ((zv, &nv), &chi) in zr.iter_mut().zip(nr).zip(chi_over_df) {
            *zv = nv / libm::sqrtf(chi);
        }
    }
}

/// Base samples drawn from a seeded RNG (see the module doc).
#[derive(Clone, Copy, Debug)]
pub struct Seeded {
    rng: Rng,
    dist: BaseDist,
    /// H: positions per sample (the row width of z).
    h: usize,
    /// The second Box-Muller value, if not used yet.
    spare: Option<f64>,
}

impl Seeded {
    /// The model's base distribution (`cfg.flow.base`) over its H positions.
    pub fn new(seed: u64, cfg: &TransflowerConfig) -> Seeded {
        Seeded {
            rng: Rng(seed),
            dist: cfg.flow.base,
            h: cfg.output_length as usize,
            spare: None,
        }
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// N(0, 1).
    pub fn normal(&mut self) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        let r = libm::sqrt(-2.0 * libm::log(1.0 - self.uniform()));
        let th = 2.0 * core::f64::consts::PI * self.uniform();
        self.spare = Some(r * libm::sin(th));
        r * libm::cos(th)
    }

    /// Gamma(shape, 1), Marsaglia-Tsang (shape > 0).
    pub fn gamma(&mut self, shape: f64) -> f64 {
        if shape < 1.0 {
            let u = self.uniform();
            return self.gamma(shape + 1.0) * libm::pow(u, 1.0 / shape);
        }
        let d = shape - 1.0 / 3.0;
        let c = 1.0 / libm::sqrt(9.0 * d);
        loop {
            let x = self.normal();
            let v = 1.0 + c * x;
            if v <= 0.0 {
                continue;
            }
            let v = v * v * v;
            let u = self.uniform();
            if u > 0.0 && libm::log(u) < 0.5 * x * x + d - d * v + d * libm::log(v) {
                return d * v;
            }
        }
    }

    /// chi2(df) / df.
    pub fn chi2_over_df(&mut self, df: u32) -> f64 {
        let df = df.max(1) as f64;
        2.0 * self.gamma(df / 2.0) / df
    }
}

impl BaseSample for Seeded {
    fn sample(&mut self, _step: usize, z: &mut [f32]) {
        match self.dist {
            BaseDist::Normal => {
                for v in z.iter_mut() {
                    *v = self.normal() as f32;
                }
            }
            BaseDist::StudentT { df } => {
                // z (C, H): the chi-squares wait in the last row, each read
                // before its own slot is overwritten (channel-major order).
                let h = self.h;
                if h == 0 || z.len() < h {
                    return;
                }
                let last = z.len() - h;
                for t in 0..h {
                    z[last + t] = self.chi2_over_df(df) as f32;
                }
                for i in 0..z.len() {
                    let chi = z[last + i % h];
                    z[i] = (self.normal() as f32) / libm::sqrtf(chi);
                }
            }
        }
    }
}
