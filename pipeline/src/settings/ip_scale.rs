//! How strongly an IP-Adapter's image tokens steer each cross-attention, as diffusers'
//! `set_ip_adapter_scale` takes it: one number for every layer, or per block, where the blocks
//! not named get 0 (InstantStyle's style-only adapter: `{"up": {"block_0": [0.0, 1.0, 0.0]}}`,
//! here `up.0.1=1`).

use crate::error::{Error, Result};
use std::fmt;
use vkdiff_networks::CrossAttention;
use vkdiff_setting::Message;

/// A part of the UNet: `mid`, `down.I`/`up.I` (every attention of block I), or
/// `down.I.J`/`up.I.J` (its J-th `Transformer2DModel`).
#[derive(Clone, Debug, PartialEq)]
pub struct IpBlock {
    text: String,
    /// The diffusers module path every cross-attention inside starts with, with its dot.
    prefix: String,
}

impl IpBlock {
    fn parse(text: &str) -> Result<IpBlock> {
        let bad = || {
            Error::Setting(Message::setting("ip_scale").then(format!(
                " {text}: name a block as mid, down.I, up.I, down.I.J or up.I.J (diffusers' down/up block_I, \
                attention J)"
            )))
        };
        let parts: Vec<&str> = text.split('.').collect();
        let index = |s: &str| s.parse::<usize>().map_err(|_| bad());
        let prefix = match parts[..] {
            ["mid"] => "mid_block.".to_string(),
            [side @ ("down" | "up"), block] => format!("{side}_blocks.{}.", index(block)?),
            [side @ ("down" | "up"), block, attention] => {
                format!("{side}_blocks.{}.attentions.{}.", index(block)?, index(attention)?)
            }
            _ => return Err(bad()),
        };
        Ok(IpBlock { text: text.to_string(), prefix })
    }
}

/// InstantStyle's blocks of SDXL: the style lives in `up_blocks.0.attentions.1`, the
/// composition in `down_blocks.2.attentions.1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IpMode {
    Style,
    Composition,
    StyleAndComposition,
}

impl IpMode {
    fn blocks(self) -> &'static [&'static str] {
        match self {
            IpMode::Style => &["up.0.1"],
            IpMode::Composition => &["down.2.1"],
            IpMode::StyleAndComposition => &["down.2.1", "up.0.1"],
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum IpScale {
    /// Every cross-attention.
    All(f32),
    /// The named blocks, later entries winning where they overlap; every other layer 0.
    Blocks(Vec<(IpBlock, f32)>),
}

impl IpScale {
    /// From `--ip-scale` values (none; one number; or BLOCK=SCALE entries) and `--ip-mode`,
    /// which gives its blocks the number (default 1).
    pub fn parse(values: &[String], mode: Option<IpMode>) -> Result<IpScale> {
        let number = |v: &str| -> Result<f32> {
            match v.trim().parse::<f32>() {
                Ok(s) if s.is_finite() => Ok(s),
                _ => Err(Error::Setting(
                    Message::setting("ip_scale").then(format!(" {v} is not a number (or BLOCK=SCALE)")),
                )),
            }
        };
        let single = match values {
            [] => Some(1.0),
            [v] if !v.contains('=') => Some(number(v)?),
            _ => None,
        };
        match (single, mode) {
            (Some(s), None) => Ok(IpScale::All(s)),
            (Some(s), Some(mode)) => {
                Ok(IpScale::Blocks(mode.blocks().iter().map(|b| Ok((IpBlock::parse(b)?, s))).collect::<Result<_>>()?))
            }
            (None, Some(_)) => Err(Error::Setting(
                Message::setting("ip_mode").then(" gives the blocks; with it, ").and("ip_scale").then(" is one number"),
            )),
            (None, None) => {
                let entries = values.iter().map(|v| {
                    let (block, scale) = v.split_once('=').ok_or_else(|| {
                        Error::Setting(
                            Message::setting("ip_scale")
                                .then(format!(" {v}: give one number, or BLOCK=SCALE entries only")),
                        )
                    })?;
                    Ok((IpBlock::parse(block.trim())?, number(scale)?))
                });
                Ok(IpScale::Blocks(entries.collect::<Result<_>>()?))
            }
        }
    }

    /// The scale of every cross-attention of `crosses` ([`vkdiff_networks::UNet::cross_attentions`]);
    /// a named block the UNet has no cross-attention in is an error, as in diffusers.
    pub fn per_layer(&self, crosses: &[CrossAttention]) -> Result<Vec<f32>> {
        let blocks = match self {
            IpScale::All(s) if !s.is_finite() => {
                return Err(Error::Setting(Message::setting("ip_scale").then(format!(" {s} is not a number"))))
            }
            IpScale::All(s) => return Ok(vec![*s; crosses.len()]),
            IpScale::Blocks(blocks) => blocks,
        };
        let inside = |block: &IpBlock, cross: &CrossAttention| format!("{}.", cross.name).starts_with(&block.prefix);
        if let Some((block, _)) = blocks.iter().find(|(b, _)| !crosses.iter().any(|c| inside(b, c))) {
            return Err(Error::Setting(
                Message::setting("ip_scale").then(format!(" {}: this UNet has no cross-attention there", block.text)),
            ));
        }
        Ok(crosses.iter().map(|c| blocks.iter().rev().find(|(b, _)| inside(b, c)).map_or(0.0, |(_, s)| *s)).collect())
    }
}

impl fmt::Display for IpScale {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IpScale::All(s) => write!(f, "{s}"),
            IpScale::Blocks(blocks) => {
                let entries: Vec<String> = blocks.iter().map(|(b, s)| format!("{}={s}", b.text)).collect();
                f.write_str(&entries.join(" "))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SDXL's cross-attentions by block: down 1 and 2 (2 attentions of 2 and 10 blocks), up 0
    /// and 1 (3 attentions), mid (10 blocks).
    fn sdxl() -> Vec<CrossAttention> {
        let mut names = Vec::new();
        for (side, block, attentions, depth) in
            [("down", 1, 2, 2), ("down", 2, 2, 10), ("up", 0, 3, 10), ("up", 1, 3, 2), ("mid", 0, 1, 10)]
        {
            for j in 0..attentions {
                for t in 0..depth {
                    let root = if side == "mid" { "mid_block".to_string() } else { format!("{side}_blocks.{block}") };
                    names.push(CrossAttention {
                        channels: 0,
                        name: format!("{root}.attentions.{j}.transformer_blocks.{t}.attn2"),
                    });
                }
            }
        }
        names
    }

    fn at(crosses: &[CrossAttention], scales: &[f32], prefix: &str) -> Vec<f32> {
        crosses.iter().zip(scales).filter(|(c, _)| c.name.starts_with(prefix)).map(|(_, s)| *s).collect()
    }

    #[test]
    fn style_mode_is_instantstyles_up_block_0_attention_1() {
        let crosses = sdxl();
        let scales = IpScale::parse(&["0.8".into()], Some(IpMode::Style)).unwrap().per_layer(&crosses).unwrap();
        assert_eq!(at(&crosses, &scales, "up_blocks.0.attentions.1."), vec![0.8; 10]);
        assert_eq!(scales.iter().filter(|&&s| s != 0.0).count(), 10, "every other layer is off");
        let explicit = IpScale::parse(&["up.0.1=0.8".into()], None).unwrap().per_layer(&crosses).unwrap();
        assert_eq!(scales, explicit);
    }

    #[test]
    fn blocks_whole_or_by_attention_and_later_entries_win() {
        let crosses = sdxl();
        let scale = IpScale::parse(&["down.2=0.5".into(), "down.2.1=1".into(), "mid=0.25".into()], None).unwrap();
        let scales = scale.per_layer(&crosses).unwrap();
        assert_eq!(at(&crosses, &scales, "down_blocks.2.attentions.0."), vec![0.5; 10]);
        assert_eq!(at(&crosses, &scales, "down_blocks.2.attentions.1."), vec![1.0; 10]);
        assert_eq!(at(&crosses, &scales, "mid_block."), vec![0.25; 10]);
        assert_eq!(at(&crosses, &scales, "up_blocks."), vec![0.0; 36]);
        assert_eq!(scale.to_string(), "down.2=0.5 down.2.1=1 mid=0.25");
        assert_eq!(IpScale::parse(&[], None).unwrap().per_layer(&crosses).unwrap(), vec![1.0; crosses.len()]);
    }

    #[test]
    fn blocks_the_unet_lacks_and_malformed_entries_are_refused() {
        let crosses = sdxl();
        let err = IpScale::parse(&["down.0=1".into()], None).unwrap().per_layer(&crosses).unwrap_err().to_string();
        assert!(err.contains("ip_scale down.0") && err.contains("no cross-attention"), "{err}");
        for bad in ["side.1=1", "up.x=1", "up.0.1.2=1", "up.0=high"] {
            assert!(IpScale::parse(&[bad.into()], None).is_err(), "{bad}");
        }
        assert!(IpScale::parse(&["up.0=1".into()], Some(IpMode::Style)).is_err());
        assert!(IpScale::parse(&["0.5".into(), "up.0=1".into()], None).is_err());
    }
}
