//! A template expanded from a seed: its choices drawn in reading order (a group, then the
//! choices inside the alternative it took) from splitmix64, each by its weight; wildcards a line
//! of their file, each line weighing 1; the category slots filled from the image's scene.

use super::{Node, PromptTemplate, Wildcards};
use crate::error::{Error, Result};
use vkdiff_render::coco::Category;
use vkdiff_render::rng::mix64;
use vkdiff_setting::Message;

/// The stream a template's choices draw from: the seed is XORed with this ("TEMPLATE" in ASCII,
/// unlike the dataset's per-image choices, which set one of the top byte's low bits) before
/// splitmix64 starts from it.
const STREAM: u64 = 0x5445_4D50_4C41_5445;

/// splitmix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number generators", 2014):
/// the state steps by the golden-ratio gamma, and each output is the state through the
/// finaliser [`splitmix64`].
struct SplitMix64(u64);

const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// splitmix64's output for the state `x`: its finaliser (the scenes' [`mix64`]) of `x + gamma`,
/// a bijection of u64 that scatters nearby inputs.
pub fn splitmix64(x: u64) -> u64 {
    mix64(x.wrapping_add(GAMMA))
}

impl SplitMix64 {
    fn new(seed: u64) -> SplitMix64 {
        SplitMix64(seed ^ STREAM)
    }

    /// The next number in [0, 1), from the top 53 bits of the next output.
    fn unit(&mut self) -> f64 {
        let out = splitmix64(self.0);
        self.0 = self.0.wrapping_add(GAMMA);
        (out >> 11) as f64 / (1u64 << 53) as f64
    }

    /// An index drawn with probability proportional to its weight (at least one is positive).
    fn weighted(&mut self, weights: &[f64]) -> usize {
        let total: f64 = weights.iter().sum();
        let mut below = self.unit() * total;
        let last = weights.iter().rposition(|&w| w > 0.0).unwrap_or(0);
        for (i, &w) in weights.iter().enumerate().take(last) {
            if below < w {
                return i;
            }
            below -= w;
        }
        last
    }
}

/// What fills `{category}` and `{categories}` for one image.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CategorySlots {
    /// The category with the most instances in the image, ties to the lowest id; empty where
    /// the image holds none.
    pub main: String,
    /// The names of the categories present, in id order, joined with ", "; empty where none.
    pub present: String,
}

impl CategorySlots {
    /// The slots of an image whose instances have the categories `instances` (ids, one per
    /// instance), named by `categories`.
    pub fn new(instances: impl IntoIterator<Item = u32>, categories: &[Category]) -> CategorySlots {
        let mut counts = std::collections::BTreeMap::<u32, usize>::new();
        for id in instances {
            *counts.entry(id).or_default() += 1;
        }
        let name = |id: u32| categories.iter().find(|c| c.id == id).map_or_else(|| id.to_string(), |c| c.name.clone());
        // max_by_key keeps the last maximum: over ids in descending order that is the lowest id.
        let main = counts.iter().rev().max_by_key(|(_, &n)| n).map_or(String::new(), |(&id, _)| name(id));
        let present = counts.keys().map(|&id| name(id)).collect::<Vec<_>>().join(", ");
        CategorySlots { main, present }
    }
}

/// One choice an expansion made.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chosen {
    /// Where: `prompt:COLUMN` for a group in the template, `FILE:LINE:COLUMN` for one in a
    /// wildcard file's line, `__name__` for a wildcard.
    pub at: String,
    /// The alternative taken, as written (without its weight), or the wildcard's line.
    pub choice: String,
}

/// A template's text for one image, and the choices that made it, in the order drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct Expansion {
    pub prompt: String,
    pub choices: Vec<Chosen>,
}

impl PromptTemplate {
    /// The template expanded from `seed`, its wildcards read from `wildcards` (loaded for it),
    /// its category slots filled from `slots`; a template with a slot and no slots (no scene)
    /// is refused.
    pub fn expand(&self, seed: u64, wildcards: &Wildcards, slots: Option<&CategorySlots>) -> Result<Expansion> {
        if !self.is_template() {
            return Ok(Expansion { prompt: self.text.clone(), choices: Vec::new() });
        }
        let mut run = Expander {
            rng: SplitMix64::new(seed),
            wildcards,
            slots,
            template: self,
            out: Expansion { prompt: String::new(), choices: Vec::new() },
        };
        run.nodes(&self.nodes)?;
        Ok(run.out)
    }
}

struct Expander<'a> {
    rng: SplitMix64,
    wildcards: &'a Wildcards,
    slots: Option<&'a CategorySlots>,
    template: &'a PromptTemplate,
    out: Expansion,
}

impl Expander<'_> {
    /// Expands `nodes`; the parser bounds the nesting of choices and [`Wildcards::load`] that of
    /// wildcards, so this recursion ends.
    fn nodes(&mut self, nodes: &[Node]) -> Result<()> {
        for node in nodes {
            match node {
                Node::Text(text) => self.out.prompt.push_str(text),
                Node::Group { at, alternatives } => {
                    let weights: Vec<f64> = alternatives.iter().map(|a| a.weight).collect();
                    let taken = &alternatives[self.rng.weighted(&weights)];
                    self.out.choices.push(Chosen { at: at.clone(), choice: taken.written.clone() });
                    self.nodes(&taken.nodes)?;
                }
                Node::Wildcard(name) => {
                    let lines = self.wildcards.lines(name, &self.template.text)?;
                    let (written, nodes) = &lines[self.rng.weighted(&vec![1.0; lines.len()])];
                    self.out.choices.push(Chosen { at: format!("__{name}__"), choice: written.clone() });
                    self.nodes(nodes)?;
                }
                Node::Category | Node::Categories => {
                    let slots = self.slots.ok_or_else(|| no_scene(&self.template.text))?;
                    self.out.prompt.push_str(if *node == Node::Category { &slots.main } else { &slots.present });
                }
            }
        }
        Ok(())
    }
}

/// The refusal of a category slot where there is no scene (`vkdiff gen`).
pub(super) fn no_scene(template: &str) -> Error {
    Error::Setting(Message::setting("prompt").then(format!(
        " \"{template}\": {{category}} and {{categories}} name the categories of a dataset image's scene; \
         vkdiff gen has no scene (write the category out)"
    )))
}
