//! Intermediate values of one step, named after the authors' modules, for
//! tests against their stage goldens (`stages_step0.safetensors`): a
//! `probe(Probe, values)` callback sees each as it is computed. Layouts
//! (batch dropped): net stages (rows, width); flow modules (C, H);
//! coupling `s` / `t` (cc, H); `input_encoder` (H, dhid); `Cond`
//! (cond_len, dhid); `FlowOut` (H, C).

/// Which transformer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Net {
    /// `net_input_<mod>` of input `i`.
    Input(u8),
    /// `net_output_<out>`.
    CrossModal,
    /// `flows.channels.<k>.nn.transformer` (k: the coupling's module index).
    Coupling(u32),
}

/// A stage of a `BasicTransformerModel`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// `encoder`: a discrete input's embedding row.
    Encoder,
    Encoder1,
    PosEncoder,
    /// `transformer_encoder.layers.<i>`.
    Layer(u32),
    Decoder,
}

/// One probed value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Probe {
    Net {
        net: Net,
        stage: Stage,
    },
    /// `flows.channels.<k>`: x after module k in the reverse pass.
    FlowModule(u32),
    /// `flows.channels.<k>.nn.s` (after the weight-normed rescale of tanh) / `.nn.t`.
    CouplingS(u32),
    CouplingT(u32),
    /// `flows.channels.<k>.input_encoder`.
    InputEncoder(u32),
    /// The flow's conditioning rows.
    Cond,
    /// The flow's sample (H, C).
    FlowOut,
}

/// A probe that looks at nothing.
pub fn none(_: Probe, _: &[f32]) {}
