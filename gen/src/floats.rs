//! Hostile `f32` values and synthetic (finite, plausible) motion.

use arbitrary::Arbitrary;

/// A float drawn from the special values that break numeric code, or raw bits.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum Hostile {
    Nan,
    /// A NaN with a payload and sign (quiet or signalling).
    NanBits(u32),
    PosInf,
    NegInf,
    /// +-1e30 (finite, squares overflow f32).
    Huge(bool),
    /// f32::MAX / MIN.
    Max(bool),
    /// A subnormal: raw mantissa bits, exponent 0.
    Denormal(u32),
    NegZero,
    /// Any bit pattern.
    Bits(u32),
    /// A finite value in +-1e3.
    Small(i16),
}

impl Hostile {
    pub fn value(self) -> f32 {
        match self {
            Hostile::Nan => f32::NAN,
            Hostile::NanBits(b) => f32::from_bits(0x7f80_0000 | (b & 0x807f_ffff) | 1),
            Hostile::PosInf => f32::INFINITY,
            Hostile::NegInf => f32::NEG_INFINITY,
            Hostile::Huge(neg) => {
                if neg {
                    -1e30
                } else {
                    1e30
                }
            }
            Hostile::Max(neg) => {
                if neg {
                    f32::MIN
                } else {
                    f32::MAX
                }
            }
            Hostile::Denormal(m) => f32::from_bits(m & 0x807f_ffff),
            Hostile::NegZero => -0.0,
            Hostile::Bits(b) => f32::from_bits(b),
            Hostile::Small(v) => v as f32 / 32.0,
        }
    }
}

/// Synthetic leader motion: `base` (one recorded pose, 165 floats) with
/// every joint swaying on its own slow sinusoid and the whole body walking
/// a 2 m circle (bounded, so a million frames stay in range).
pub fn synthetic_leader(base: &[f32], t: u64, out: &mut [f32]) {
    let t = (t % (1 << 24)) as f32 / 30.0;
    let (cx, cz) = (2.0 * (t * 0.05).cos(), 2.0 * (t * 0.05).sin());
    for (j, (o, &b)) in out.iter_mut().zip(base).enumerate() {
        let joint = (j / 3) as f32;
        let w = 0.7 + 0.13 * joint;
        let sway = 0.05 * (w * t + joint).sin();
        *o = b
            + sway
            + match j % 3 {
                0 => cx,
                2 => cz,
                _ => 0.0,
            };
    }
}
