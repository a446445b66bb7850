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
        duolando_core::family::Family::Transflower => "a solo dancer's pose features from music and a motion seed, sampled by a normalizing flow",
    }
}

/// One sentence describing why a Transflower model could not be bound.
pub fn describe_transflower_model(e: &duolando_core::transflower::model::ModelError) -> String {
    use duolando_core::transflower::model::{ModelError, ValueProblem};
    match e {
        ModelError::Config(c) => format!(
            "the Transflower config is not supported: {}",
            describe_transflower_config(c)
        ),
        ModelError::Bind(b) => describe_bind(b),
        ModelError::Value { name, problem } => format!(
            "flow weight `{}` {}",
            name.as_str(),
            match problem {
                ValueProblem::NonFinite => "holds NaN or infinity",
                ValueProblem::NotPermutation =>
                    "is not a permutation matrix (0/1, one 1 per row and column)",
                ValueProblem::SignNotUnit => "holds a value other than +1 or -1",
                ValueProblem::Zero => "holds a zero the flow divides by",
                ValueProblem::NegativeVariance => "holds a negative variance",
            }
        ),
    }
}

/// The authors' option (hparams.yaml key) behind a Transflower config field.
fn transflower_field(f: duolando_core::transflower::config::Field) -> String {
    use duolando_core::transflower::config::Field::*;
    match f {
        Inputs => "input_modalities (count)".into(),
        InputDim(i) => format!("dins[{i}]"),
        InputLength(i) => format!("input_lengths[{i}]"),
        InputTokens(i) => format!("input_num_tokens[{i}]"),
        Output => "output_modalities".into(),
        Channels => "douts".into(),
        OutputLength => "output_lengths".into(),
        CondLen => "conditioning_seq_lens".into(),
        Dhid => "dhid".into(),
        Nhead => "nhead".into(),
        Nlayers => "nlayers".into(),
        FlowSteps => "scales (flow steps)".into(),
        DhidFlow => "dhid_flow".into(),
        HeadsFlow => "num_heads_flow".into(),
        CouplingLayers => "num_glow_coupling_blocks".into(),
        StudentTDf => "flow_dist_param".into(),
    }
}

/// One sentence describing a refused Transflower config, naming the
/// authors' option (tools/reference/transflower/README.md, "Options that
/// change the computation").
pub fn describe_transflower_config(e: &duolando_core::transflower::config::ConfigError) -> String {
    use duolando_core::transflower::config::{ConfigError as C, Unsupported as U};
    match *e {
        C::Zero { field } => format!("`{}` is 0", transflower_field(field)),
        C::TooLarge { field, value, max } => format!("`{}` = {value} is above the engine's cap of {max}", transflower_field(field)),
        C::TooSmall { field, value, min } => format!("`{}` = {value} is below {min}", transflower_field(field)),
        C::NotDivisible { field, value, divisor } => format!("`{}` = {value} is not a multiple of {divisor} (the head count)", transflower_field(field)),
        C::Mismatch { field, value, expected } => format!(
            "`{}` = {value}, expected {expected}{}",
            transflower_field(field),
            if field == duolando_core::transflower::config::Field::CondLen { " (cond_concat_dims: True puts the conditioning rows beside the output frames)" } else { "" }
        ),
        C::BadName { input } => format!("the name of input {input} is not a modality name ([A-Za-z0-9_], 1 to 32 bytes)"),
        C::DuplicateName { input, previous } => format!("inputs {previous} and {input} have the same modality name"),
        C::UnusedInput { input } => format!("input slot {input} is past the input count but not empty"),
        C::Unsupported(u) => match u {
            U::NotTransflower => "`model` is not `transflower` (another model of the authors' repository)".into(),
            U::Residual => "`residual: True` (a mean network added to the flow sample) is not implemented".into(),
            U::MultiLevelScales { levels } => format!("`scales` with {levels} levels (squeeze/unsqueeze between levels) is not implemented; one level [[n, 0]] is"),
            U::CheckerboardScales => "`scales` with a checkerboard part ([[n, s]], s > 0) is not implemented".into(),
            U::MixtureCouplings { components } => format!("`num_mixture_components: {components}` (mixture-of-logistics couplings) is not implemented; 0 is"),
            U::ConvCouplingNets => "`use_transformer_nn: False` (convolutional coupling nets) is not implemented".into(),
            U::UseXTransformers => "`use_x_transformers: True` is not implemented".into(),
            U::UseRotaryPosEmb => "`use_rotary_pos_emb: True` is not implemented".into(),
            U::UsePosEmbInputs => "`use_pos_emb_inputs: True` is not implemented".into(),
            U::UseRelPosEmbOutput => "`use_rel_pos_emb_output: True` is not implemented".into(),
            U::UseRelPosEmbCoupling => "`use_rel_pos_emb_coupling: True` is not implemented".into(),
            U::NormLayer => "`glow_norm_layer` is not batchnorm, actnorm or None".into(),
            U::FlowDist => "`flow_dist` is not normal or studentT".into(),
            U::SeveralOutputs => "several `output_modalities` (or `douts` / `output_lengths` lists) are not implemented; one is".into(),
            U::OutputNotAnInput => "the output modality is not one of `input_modalities` (nothing to feed back)".into(),
            U::InputTimeOffsets => "`input_time_offsets` other than 0 are not implemented".into(),
            U::WindowType { input } => format!("input {input}: `input_types` d needs `input_fix_length_types` single and the reverse (the output modality must be continuous)"),
            U::OutputWidth => "`douts` differs from the output modality's `dins`".into(),
            U::ListLength => "a per-input list (`dins`, `input_lengths`, `input_types`, ...) has another length than `input_modalities`".into(),
        },
    }
}

/// The buffer a Transflower input error is about, in words naming the
/// model's modalities (`core::transflower::exact::buffer_of`).
fn transflower_buffer(
    b: Buffer,
    cfg: &duolando_core::transflower::config::TransflowerConfig,
) -> String {
    match b {
        Buffer::SeedFrames => format!("the motion seed `{}`", cfg.output_input().name.as_str()),
        Buffer::Tokens => "the style label".into(),
        Buffer::Features => {
            let names: Vec<&str> = cfg
                .inputs()
                .iter()
                .enumerate()
                .filter(|(i, c)| *i != cfg.output as usize && !c.is_discrete())
                .map(|(_, c)| c.name.as_str())
                .collect();
            format!(
                "the input features ({}) or the replayed noise",
                names.join(", ")
            )
        }
        other => buffer_name(other).to_string(),
    }
}

/// One sentence describing a core error of a Transflower run.
pub fn describe_transflower(
    e: &Error,
    cfg: &duolando_core::transflower::config::TransflowerConfig,
) -> String {
    match *e {
        Error::TooShort { buffer, frames, min } => format!("{} has {frames} rows, at least {min} needed", transflower_buffer(buffer, cfg)),
        Error::Ragged { buffer, len, row } => format!("{} has {len} values, not a whole number of rows of {row}", transflower_buffer(buffer, cfg)),
        Error::Length { buffer, len, expected } => format!("{} has {len} values, {expected} expected", transflower_buffer(buffer, cfg)),
        Error::NonFinite { buffer, index } => format!("{} contains NaN or infinity at flat index {index}", transflower_buffer(buffer, cfg)),
        Error::OutOfRange { buffer, index } => format!(
            "{} holds a value above {:e} in magnitude at flat index {index} (input policy, docs/ROBUSTNESS.md)",
            transflower_buffer(buffer, cfg),
            duolando_core::input::limit_of(buffer)
        ),
        Error::Token { token, vocab, stream } => format!(
            "style label {token} of input `{}` is outside its {vocab} labels",
            cfg.inputs().get(stream as usize).map_or("?", |c| c.name.as_str())
        ),
        Error::Backlog { buffer: Buffer::Output, held, capacity } => format!(
            "the session is full ({held} of {capacity} frames made and not pulled): pull frames before the next step"
        ),
        Error::Backlog { buffer, held, capacity } => format!(
            "the session is full ({} would hold {held} rows, at most {capacity}: the window plus input_buffer_rows): pull frames (each moves the window one row on) before pushing more",
            transflower_buffer(buffer, cfg)
        ),
        _ => describe(e),
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
        Temperature => "temperature_milli",
        PendingFrames => "pending_frames",
        MusicBuffer => "music_buffer_frames",
        Windows => "staggered (GPT caches needed)",
        Batch => "sessions in one step batch",
        Refresh => "refresh",
    }
}
