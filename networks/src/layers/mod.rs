//! The layers networks are built of (diffusers' and transformers' module names): linear,
//! convolution and norms, attention with IP-Adapter hooks, resnets, transformer blocks, and the
//! NCHW ↔ NHWC layout changes at a network's edges.

pub(crate) mod attention;
pub(crate) mod biased_attention;
mod layout;
pub(crate) mod nn;
pub(crate) mod resnet;
pub(crate) mod transformer_2d;

pub use layout::{nchw_to_nhwc, nhwc_to_nchw};
