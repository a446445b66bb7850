//! Bailando (Siyao et al., CVPR 2022): a solo dancer to music. The
//! choreographic memory is two VQ-VAEs (up and down half of the SMPL
//! body; the down half also decodes the root velocity); the actor GPT
//! ([`gpt`]) is the cross-conditional transformer over three streams
//! (music, up tokens, down tokens) built from the shared blocks
//! (`nn::streams`). [`exact`] reproduces the authors' `AC.eval()` (greedy)
//! token for token. Weights: [`model`] (names from [`schema`], config
//! [`config`]). [`session`] is S mode: a streaming dancer on the same
//! engine (shared GPT cache, window schedule and streaming decoders).

pub mod config;
pub mod exact;
pub mod gpt;
pub mod model;
pub mod schema;
pub mod session;
