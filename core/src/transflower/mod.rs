//! Transflower (Valle-Pérez et al., SIGGRAPH Asia 2021): probabilistic
//! autoregressive dance from music. Each input modality (motion, audio
//! features, a style label) has its own transformer ([`encoders`]); their
//! rows, stacked, go through a cross-modal transformer ([`cross_modal`])
//! whose first rows condition a normalizing flow ([`flow`]: norm, LU 1x1
//! conv, affine couplings with transformer nets) that maps a base sample
//! ([`base`]: Gaussian or Student-t) to the next motion frames.
//! [`exact`] is R mode: the authors' generation loop with the base
//! samples replayed or drawn. Weights: [`model`] (names from [`schema`],
//! config [`config`] from the authors' options [`hparams`]). Stage values
//! for tests: [`probe`].

pub mod base;
pub mod config;
pub mod cross_modal;
pub mod encoders;
pub mod exact;
pub mod flow;
pub mod hparams;
pub mod model;
pub mod probe;
pub mod schema;
pub mod session;
pub mod transformer;
