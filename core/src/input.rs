//! Input policy for frames that come from trackers and audio front ends
//! (issue #6, docs/ROBUSTNESS.md §3), shared by R mode (`exact`) and the
//! streaming session: a frame holding NaN or infinity is refused with
//! [`Error::NonFinite`]; a finite value whose magnitude exceeds the limit
//! of its buffer is refused with [`Error::OutOfRange`]. A refused frame
//! changes nothing (the session keeps its state; the caller may push its
//! last good frame instead to keep the clock).
//!
//! The limits are far outside any real motion or feature value and low
//! enough that every accepted input keeps the whole network finite (the
//! largest products of the encoders stay many orders below `f32::MAX`).

use crate::error::{Buffer, Error};

/// Largest accepted |coordinate| of a leader or seed joint position, in
/// metres (10 km: trackers report metres; a stage is ~10 m).
pub const MAX_POSITION_M: f32 = 1.0e4;
/// Largest accepted |value| of a music feature (the 54 features of
/// docs/MUSIC.md stay within ~1e3).
pub const MAX_MUSIC_FEATURE: f32 = 1.0e6;

/// The magnitude limit of an input buffer.
pub fn limit_of(buffer: Buffer) -> f32 {
    match buffer {
        Buffer::Music | Buffer::Features => MAX_MUSIC_FEATURE,
        _ => MAX_POSITION_M,
    }
}

/// Checks one input buffer against the policy: the first NaN/infinity
/// (`NonFinite`) takes precedence over the first over-limit value
/// (`OutOfRange`); both report the flat index.
pub fn check(buffer: Buffer, x: &[f32]) -> Result<(), Error> {
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite { buffer, index });
    }
    let limit = limit_of(buffer);
    match x.iter().position(|v| v.abs() > limit) {
        Some(index) => Err(Error::OutOfRange { buffer, index }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_before_out_of_range() {
        let x = [0.0, 2e4, f32::NAN];
        assert_eq!(
            check(Buffer::LeaderPos3d, &x),
            Err(Error::NonFinite {
                buffer: Buffer::LeaderPos3d,
                index: 2
            })
        );
        assert_eq!(
            check(Buffer::LeaderPos3d, &x[..2]),
            Err(Error::OutOfRange {
                buffer: Buffer::LeaderPos3d,
                index: 1
            })
        );
        // 2e4 is a valid music feature, 2e6 is not.
        assert_eq!(check(Buffer::Music, &x[..2]), Ok(()));
        assert_eq!(
            check(Buffer::Music, &[2e6]),
            Err(Error::OutOfRange {
                buffer: Buffer::Music,
                index: 0
            })
        );
    }

    #[test]
    fn limits_are_inclusive_and_symmetric() {
        assert_eq!(
            check(
                Buffer::LeaderPos3d,
                &[MAX_POSITION_M, -MAX_POSITION_M, -0.0, f32::MIN_POSITIVE]
            ),
            Ok(())
        );
        let above = f32::from_bits(MAX_POSITION_M.to_bits() + 1);
        assert!(check(Buffer::SeedFrames, &[-above]).is_err());
        assert_eq!(check(Buffer::Music, &[MAX_MUSIC_FEATURE]), Ok(()));
    }
}
