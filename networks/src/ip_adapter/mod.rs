//! h94's IP-Adapter (plain and plus): image features projected to tokens that the UNet's
//! cross-attentions attend to beside the text.

mod adapter;
mod resampler;

pub use adapter::{IpAdapter, IpAdapterKind};
