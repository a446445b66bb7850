//! The shared building blocks of every family (DESIGN.md §7 "One runtime
//! for three families"): weight views and binding by name, tensor names,
//! the pre-LN transformer block, conv stacks and their streaming form, the
//! VQ-VAE config and quantiser, the sampler, and the fixed-capacity rings
//! and K/V stores of streaming sessions. Nothing here knows a family.

pub mod bind;
pub mod block;
pub mod conv_stack;
pub mod encoder_layer;
pub mod gpt_cache;
pub mod kv_store;
pub mod names;
pub mod quantizer;
pub mod ring;
pub mod sampler;
pub mod stream_conv;
pub mod streams;
pub mod vq_config;
pub mod vq_decoder;
pub mod vq_encoder;
pub mod weights;
pub mod window;
