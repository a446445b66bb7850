//! Human-readable messages for core's numeric error enums (core builds no
//! strings; the std side says what went wrong in words).

use duolando_core::error::{Buffer, Error};

/// What a [`Buffer`] is, in words a CLI user recognises.
pub fn buffer_name(b: Buffer) -> &'static str {
    match b {
        Buffer::LeaderPos3d => "leader positions (T, 165)",
        Buffer::Music => "music features (T, 54)",
        Buffer::SeedFrames => "follower start frames (F, 165)",
        Buffer::Tokens => "tokens",
        Buffer::FollowerPos3d => "follower positions output",
        Buffer::FollowerRotmat => "follower rotations output",
        Buffer::Logits => "logits output",
        Buffer::Features => "encoder features",
        Buffer::Codes => "codes",
        Buffer::Pose => "pose",
        Buffer::Output => "output",
        Buffer::LeaderTokens => "leader tokens",
        Buffer::FollowerTokens => "follower tokens",
    }
}

/// One sentence describing why a model could not be bound.
pub fn describe_bind(b: &duolando_core::nn::bind::BindError) -> String {
    use duolando_core::nn::bind::BindError;
    match b {
        BindError::Family { expected, found } => format!(
            "this is a {} model ({}); a {} model ({}) is needed here",
            found.name(),
            what(*found),
            expected.name(),
            what(*expected)
        ),
        other => format!("the model cannot be bound: {other:?}"),
    }
}

fn what(f: duolando_core::family::Family) -> &'static str {
    match f {
        duolando_core::family::Family::Duolando => "a follower that dances with a leader to music",
        duolando_core::family::Family::Bailando => "a solo dancer to music",
    }
}

/// One sentence describing a core error.
pub fn describe(e: &Error) -> String {
    const STREAMS: [&str; 5] = ["up", "down", "lhand", "rhand", "transl"];
    match e {
        Error::Arena(a) => format!("scratch memory too small ({a:?})"),
        Error::Bind(b) => describe_bind(b),
        Error::Length { buffer, len, expected } => {
            format!("{} has {len} values, {expected} expected", buffer_name(*buffer))
        }
        Error::Ragged { buffer, len, row } => {
            format!("{} has {len} values, not a whole number of rows of {row}", buffer_name(*buffer))
        }
        Error::TooShort { buffer, frames, min } => {
            format!("{} has {frames} frames, at least {min} needed", buffer_name(*buffer))
        }
        Error::Token { stream, token, vocab } => format!(
            "token {token} of stream {} is outside its vocabulary of {vocab}",
            STREAMS.get(*stream as usize).copied().unwrap_or("?")
        ),
        Error::Context { c, max } => format!("window context {c} outside 1..={max}"),
        Error::NonFinite { buffer, index } => {
            format!("{} contains NaN or infinity at flat index {index}", buffer_name(*buffer))
        }
        Error::OutOfRange { buffer, index } => format!(
            "{} holds a value above {:e} in magnitude at flat index {index} (input policy, docs/ROBUSTNESS.md)",
            buffer_name(*buffer),
            duolando_core::input::limit_of(*buffer)
        ),
        Error::Setting { setting, value, max } => {
            format!("session setting {} = {value} is outside its range (at most {max} for this model)", setting_name(*setting))
        }
        Error::Backlog { buffer, held, capacity } => format!(
            "the session is full ({held} of {capacity} {} held): {}",
            buffer_name(*buffer),
            match buffer {
                Buffer::Music => "push leader frames before more music, or music before more leader frames",
                _ => "pull follower frames before pushing more leader frames",
            }
        ),
        Error::Evicted { index, oldest, len } => format!(
            "internal error: a session buffer was read at {index}, outside the rows it holds ({oldest}..{len}); please report this"
        ),
        Error::Ended { frames } => format!(
            "the leader has ended (finish() after {frames} leader frames): the session takes no more leader frames; pull the remaining follower frames, or reset it to start again"
        ),
        Error::State => "the call does not fit the session's state (music track after music frames, forced history after the first frame, a forced history whose first row is not the seed, a session in step_many or with_batch of another model or needing a larger StepBatch, or a session made by Session::new_batched called outside with_batch / step_many)".to_string(),
    }
}

fn setting_name(s: duolando_core::duolando::session::Setting) -> &'static str {
    use duolando_core::duolando::session::Setting::*;
    match s {
        Lookahead => "lookahead",
        EncFuture => "enc_future",
        DecFuture => "dec_future",
        Shift => "shift",
        MusicLookahead => "music_lookahead",
        LatPast => "lat_past",
        TopK => "top_k",
        PendingFrames => "pending_frames",
        MusicBuffer => "music_buffer_frames",
        Windows => "staggered (GPT caches needed)",
        Batch => "sessions in one step batch",
    }
}
