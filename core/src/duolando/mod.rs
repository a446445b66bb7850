//! Duolando (Siyao et al., ICLR 2024): the follower GPT that dances with a
//! leader to music. Data flow (R mode, docs/ARCHITECTURE.md): [`motion`]
//! normalisation -> [`vq_encoder`] (leader tokens) -> per step [`gpt`]
//! ([`lat`] + [`coordinated_attention`] over the shared blocks) -> the
//! sampler -> [`vq_decoder`] -> [`motion`] de-normalisation; orchestrated
//! by [`exact`]; streaming in [`session`]. Weights: [`model`] (names from
//! [`schema`], config [`config`] checked by [`validate`]).

pub mod config;
pub mod coordinated_attention;
pub mod exact;
pub mod gpt;
pub mod lat;
pub mod model;
pub mod motion;
pub mod presets;
pub mod schema;
pub mod session;
pub mod validate;
pub mod vq_decoder;
pub mod vq_encoder;
