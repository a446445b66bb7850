//! The deterministic motion set of the metric goldens, rebuilt bit for bit
//! from a small integer recipe (mirrored in `tools/metrics_goldens.py`, which
//! runs the authors' code on it): integer hashing, float64 `+ * /` and
//! `sin`, rounded once to f32. Only the tests use it; it lives here so that
//! unit and CLI tests share one copy.

use std::path::Path;

use anyhow::Result;

const MASK_MUL: u64 = 1_000_003;
/// 2 pi (the script writes the literal 6.283185307179586: the same double).
const TWO_PI: f64 = std::f64::consts::TAU;
/// 4 pi, exactly 2 x TWO_PI (the script's 12.566370614359172).
const FOUR_PI: f64 = 2.0 * std::f64::consts::TAU;

/// The recipe's parameters (the JSON's `recipe`).
#[derive(Clone, Debug)]
pub struct Recipe {
    pub seed: u64,
    pub n_real: usize,
    pub n_gen: usize,
    /// 165 integers: the base pose in millimetres.
    pub base_pose_mm: Vec<i64>,
}

fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Recipe {
    /// A float64 in [0, 1) from integer keys.
    pub fn unit(&self, keys: &[u64]) -> f64 {
        let mut k = self.seed;
        for &v in keys {
            k = k.wrapping_mul(MASK_MUL).wrapping_add(v);
        }
        (splitmix64(k) >> 11) as f64 / 9007199254740992.0
    }

    pub fn clip_frames(&self, set: u64, k: u64, role: u64) -> usize {
        let mut base = 40 + (self.unit(&[set, k, 900]) * 40.0) as i64;
        if role == 1 {
            base += (self.unit(&[set, k, 901]) * 9.0) as i64 - 4;
        }
        base as usize
    }

    /// (T, 165) motion of clip `k` of set `set` (0 real, 1 generated), role 0 follower, 1 leader.
    pub fn motion(&self, set: u64, k: u64, role: u64) -> Vec<f32> {
        let t_len = self.clip_frames(set, k, role);
        let amp = 0.01 + 0.2 * self.unit(&[set, k, role, 1]);
        let sway = 0.05 + 0.5 * self.unit(&[set, k, role, 2]);
        let tempo = 0.5 + 2.0 * self.unit(&[set, k, role, 3]);
        let gen_bias = 0.03 * set as f64;
        let chans: Vec<(f64, f64, f64)> = (0..165u64)
            .map(|ch| {
                (
                    tempo * (0.3 + 1.5 * self.unit(&[set, k, role, 10, ch])),
                    TWO_PI * self.unit(&[set, k, role, 11, ch]),
                    (amp + gen_bias) * self.unit(&[set, k, role, 12, ch]),
                )
            })
            .collect();
        let fr = 0.2 + 0.6 * self.unit(&[set, k, role, 4]);
        let mut out = vec![0.0f32; t_len * 165];
        for t in 0..t_len {
            let time = t as f64 / 30.0;
            let root = [
                sway * (TWO_PI * fr * time).sin(),
                0.04 * sway * (FOUR_PI * fr * time + 1.0).sin(),
                sway * 0.5 * (TWO_PI * fr * time + 2.0).sin(),
            ];
            for (ch, &(f1, p1, a1)) in chans.iter().enumerate() {
                let v = self.base_pose_mm[ch] as f64 / 1000.0
                    + root[ch % 3]
                    + a1 * (TWO_PI * f1 * time + p1).sin();
                out[t * 165 + ch] = v as f32;
            }
        }
        out
    }

    /// (T_m, 54) music features with beats in column 53.
    pub fn music(&self, set: u64, k: u64, motion_frames: usize) -> Vec<f32> {
        let t_len = (motion_frames as i64 + (self.unit(&[set, k, 950]) * 11.0) as i64 - 5) as usize;
        let period = 8 + (self.unit(&[set, k, 951]) * 9.0) as usize;
        let offset = (self.unit(&[set, k, 952]) * period as f64) as usize;
        let mut out = vec![0.0f32; t_len * 54];
        let mut t = offset;
        while t < t_len {
            out[t * 54 + 53] = 1.0;
            t += period;
        }
        out
    }

    pub fn name(set: u64, k: u64) -> String {
        format!("Synth_{set:02}_{k:02}")
    }

    /// Writes DIR/{real,gen}/<name>_{00,01}.npy and DIR/music/<name>.npy;
    /// returns (relative path, checksum) per file.
    pub fn write(&self, dir: &Path) -> Result<Vec<(String, u64)>> {
        let mut sums = Vec::new();
        std::fs::create_dir_all(dir.join("music"))?;
        for (set, sub, n) in [(0u64, "real", self.n_real), (1, "gen", self.n_gen)] {
            std::fs::create_dir_all(dir.join(sub))?;
            for k in 0..n as u64 {
                let nm = Self::name(set, k);
                let f = self.motion(set, k, 0);
                let l = self.motion(set, k, 1);
                let m = self.music(set, k, f.len() / 165);
                crate::npy::write_f32(
                    &dir.join(sub).join(format!("{nm}_00.npy")),
                    &f,
                    &[f.len() / 165, 165],
                )?;
                crate::npy::write_f32(
                    &dir.join(sub).join(format!("{nm}_01.npy")),
                    &l,
                    &[l.len() / 165, 165],
                )?;
                crate::npy::write_f32(
                    &dir.join("music").join(format!("{nm}.npy")),
                    &m,
                    &[m.len() / 54, 54],
                )?;
                sums.push((format!("{sub}/{nm}_00.npy"), checksum(&f)));
                sums.push((format!("{sub}/{nm}_01.npy"), checksum(&l)));
                sums.push((format!("music/{nm}.npy"), checksum(&m)));
            }
        }
        Ok(sums)
    }
}

/// The bits of the float64 sum of f32 values in order (the JSON's checksums).
pub fn checksum(v: &[f32]) -> u64 {
    v.iter().fold(0.0f64, |s, &x| s + x as f64).to_bits()
}
