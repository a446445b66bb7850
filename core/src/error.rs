//! The engine's error type: enums with numeric context, no strings.

use crate::arena::ArenaError;
use crate::nn::bind::BindError;

/// A caller buffer or input whose length is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Buffer {
    LeaderPos3d,
    Music,
    SeedFrames,
    Tokens,
    FollowerPos3d,
    FollowerRotmat,
    Logits,
    Features,
    Codes,
    Pose,
    Output,
    LeaderTokens,
    FollowerTokens,
}

/// Everything the inference functions can reject.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Error {
    /// Scratch memory too small (ask `*_scratch_bytes`).
    Arena(ArenaError),
    Bind(BindError),
    /// `buffer` has `len` elements where `expected` were required.
    Length {
        buffer: Buffer,
        len: usize,
        expected: usize,
    },
    /// `buffer` length is not a whole number of rows of `row` elements.
    Ragged {
        buffer: Buffer,
        len: usize,
        row: usize,
    },
    /// Too few frames: `frames` given, at least `min` needed.
    TooShort {
        buffer: Buffer,
        frames: usize,
        min: usize,
    },
    /// A token outside its vocabulary (`stream` 0..4 = up, down, lhand, rhand, transl).
    Token {
        stream: u8,
        token: u32,
        vocab: u32,
    },
    /// A window context outside `1..=max`.
    Context {
        c: usize,
        max: usize,
    },
    /// A non-finite input value (NaN or infinity) at flat index `index`.
    NonFinite {
        buffer: Buffer,
        index: usize,
    },
    /// A finite input value whose magnitude exceeds its buffer's limit
    /// (`input::limit_of`) at flat index `index`.
    OutOfRange {
        buffer: Buffer,
        index: usize,
    },
    /// A streaming-session setting outside `0..=max` (or `1..=max`).
    Setting {
        setting: Setting,
        value: u32,
        max: u32,
    },
    /// A streaming session refused an input because its buffers are full
    /// (follower frames not pulled, or music pushed too far ahead); the
    /// session is unchanged: pull frames (or push leader frames) and retry.
    Backlog {
        buffer: Buffer,
        held: usize,
        capacity: usize,
    },
    /// A streaming-session ring was read outside the rows it holds (an
    /// engine bug: the sizes make this impossible; reported, never a panic).
    Evicted {
        index: usize,
        oldest: usize,
        len: usize,
    },
    /// The operation does not fit the session's state (e.g. a music track
    /// set after music frames were pushed).
    State,
    /// A streaming session was told the leader has ended
    /// (`Session::finish`, after `frames` leader frames): no leader frame
    /// (or forced history) is taken any more until `Session::reset`.
    Ended {
        frames: usize,
    },
}

impl From<ArenaError> for Error {
    fn from(e: ArenaError) -> Self {
        Error::Arena(e)
    }
}

impl From<BindError> for Error {
    fn from(e: BindError) -> Self {
        Error::Bind(e)
    }
}

/// `Ok` if `len == expected`, else a [`Error::Length`].
pub fn check_len(buffer: Buffer, len: usize, expected: usize) -> Result<(), Error> {
    if len != expected {
        return Err(Error::Length {
            buffer,
            len,
            expected,
        });
    }
    Ok(())
}

/// `Ok` if `len >= expected`, else a [`Error::Length`].
pub fn check_at_least(buffer: Buffer, len: usize, expected: usize) -> Result<(), Error> {
    if len < expected {
        return Err(Error::Length {
            buffer,
            len,
            expected,
        });
    }
    Ok(())
}

/// A streaming-session setting outside its range ([`Error::Setting`]): the
/// names of the knobs a session of any family may have.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Setting {
    Lookahead,
    EncFuture,
    DecFuture,
    Shift,
    MusicLookahead,
    LatPast,
    TopK,
    /// [`crate::nn::sampler::Sampling::Softmax`]'s temperature, in thousandths.
    Temperature,
    PendingFrames,
    MusicBuffer,
    /// GPT caches a staggered schedule needs (value) above the session's
    /// window capacity (Duolando: `MAX_WINDOWS`).
    Windows,
    /// Sessions of a step batch outside `1..=MAX_BATCH`.
    Batch,
    /// Steps between exact recomputations (Transflower's stale-rows S mode).
    Refresh,
}
