//! Sample-rate conversion: a Kaiser-windowed sinc evaluated on a polyphase
//! grid (rational ratios up to 4096 phases exactly, other ratios with the
//! read position rounded to 1/4096 input sample).
//!
//! Design: 32 zero crossings each side (at the lower of the two rates),
//! pass band to 0.92 of the lower Nyquist, Kaiser beta 10 (about 100 dB
//! stop band). The original pipeline used essentia's MonoLoader, i.e.
//! libsamplerate `SRC_SINC_MEDIUM_QUALITY`; docs/MUSIC.md reports the
//! measured sample and feature deviation from it.

use crate::music::octave::bessel_i0;

const ZEROS: f64 = 32.0;
const ROLLOFF: f64 = 0.92;
const BETA: f64 = 10.0;
const MAX_PHASES: usize = 4096;

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// Resamples `x` from `from` Hz to `to` Hz; output length `ceil(len * to / from)`.
pub fn resample(x: &[f32], from: u32, to: u32) -> Vec<f32> {
    if from == to || x.is_empty() {
        return x.to_vec();
    }
    let g = gcd(from as u64, to as u64);
    let (up, down) = (to as u64 / g, from as u64 / g);
    let phases = if up as usize <= MAX_PHASES {
        up as usize
    } else {
        MAX_PHASES
    };
    let ratio = to as f64 / from as f64;
    let scale = ratio.min(1.0); // cutoff relative to the input Nyquist
    let cutoff = ROLLOFF * scale;
    let half = (ZEROS / scale).ceil() as isize; // taps each side, in input samples
    let width = (2 * half) as usize; // taps per phase: offsets -half+1 ..= half
    let i0b = bessel_i0(BETA);
    // (phases, width) taps: phase p = fractional position p/phases
    let mut bank = vec![0.0f32; phases * width];
    for p in 0..phases {
        let frac = p as f64 / phases as f64;
        for (j, w) in bank[p * width..(p + 1) * width].iter_mut().enumerate() {
            let d = (j as isize - half + 1) as f64 - frac; // input offset minus position
            let x = cutoff * d;
            let sinc = if x == 0.0 {
                1.0
            } else {
                (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x)
            };
            let r = d / (half as f64);
            let win = if r.abs() >= 1.0 {
                0.0
            } else {
                bessel_i0(BETA * (1.0 - r * r).sqrt()) / i0b
            };
            *w = (cutoff * sinc * win) as f32;
        }
    }
    let n_out = ((x.len() as u128 * to as u128).div_ceil(from as u128)) as usize;
    let mut y = Vec::with_capacity(n_out);
    let n = x.len() as isize;
    for t in 0..n_out {
        // exact position t * down / up in input samples
        let num = t as u128 * down as u128;
        let base = (num / up as u128) as isize;
        let rem = (num % up as u128) as u64;
        let p = if phases == up as usize {
            rem as usize
        } else {
            ((rem as f64 / up as f64) * phases as f64).round() as usize
        };
        let (base, p) = if p == phases {
            (base + 1, 0)
        } else {
            (base, p)
        };
        let taps = &bank[p * width..(p + 1) * width];
        let first = base - half + 1;
        let acc = if first >= 0 && first + width as isize <= n {
            crate::music::mel::dot(taps, &x[first as usize..first as usize + width])
        } else {
            let mut s = 0.0f32;
            for (j, &w) in taps.iter().enumerate() {
                let i = first + j as isize;
                if i >= 0 && i < n {
                    s += w * x[i as usize];
                }
            }
            s
        };
        y.push(acc);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tone_survives_44100_to_15360() {
        let f = 1000.0;
        let x: Vec<f32> = (0..44100)
            .map(|i| (2.0 * std::f64::consts::PI * f * i as f64 / 44100.0).sin() as f32)
            .collect();
        let y = resample(&x, 44100, 15360);
        assert_eq!(y.len(), 15360);
        let err = (200..15000)
            .map(|i| {
                (y[i] as f64 - (2.0 * std::f64::consts::PI * f * i as f64 / 15360.0).sin()).abs()
            })
            .fold(0.0, f64::max);
        assert!(err < 1e-3, "{err}");
    }

    #[test]
    fn removes_content_above_new_nyquist() {
        let x: Vec<f32> = (0..48000)
            .map(|i| (2.0 * std::f64::consts::PI * 12000.0 * i as f64 / 48000.0).sin() as f32)
            .collect();
        let y = resample(&x, 48000, 15360);
        let rms = (y[500..14000].iter().map(|v| v * v).sum::<f32>() / 13500.0).sqrt();
        assert!(rms < 1e-4, "{rms}");
    }
}
