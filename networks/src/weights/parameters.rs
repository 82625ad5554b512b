//! Where each loaded weight lives on the device, by its diffusers name, so that it can be edited
//! in place after loading (LoRA merges) without going back to the checkpoint.

use std::collections::HashMap;
use vkdiff_runtime::Tensor;

/// How a parameter's elements are laid out in its device tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamLayout {
    /// Row-major in PyTorch's own shape ([out, in] for a Linear weight, a vector for a bias).
    AsStored,
    /// A PyTorch conv weight [out, in, kh, kw] re-laid out as [out, kh, kw, in] for NHWC kernels.
    ConvOhwi,
}

/// One parameter: a view of exactly its elements (a part of a fused projection is a row range of
/// the fused tensor), its PyTorch shape, and its layout.
#[derive(Clone)]
pub struct Parameter {
    pub tensor: Tensor,
    pub torch_shape: Vec<usize>,
    pub layout: ParamLayout,
}

/// A network's parameters by diffusers name (`down_blocks.1.attentions.0.proj_in.weight`).
#[derive(Clone, Default)]
pub struct Parameters {
    by_name: HashMap<String, Parameter>,
    /// Prefixes of modules the checkpoint has but the network never runs (CLIP-L's last layer
    /// under SDXL's penultimate-layer conditioning): edits aimed there change nothing.
    not_run: Vec<String>,
}

impl Parameters {
    pub(crate) fn insert(&mut self, name: String, parameter: Parameter) {
        self.by_name.insert(name, parameter);
    }

    pub(crate) fn mark_not_run(&mut self, prefix: String) {
        self.not_run.push(prefix);
    }

    /// Whether `name` belongs to a module the network skips.
    pub fn is_not_run(&self, name: &str) -> bool {
        self.not_run.iter().any(|p| name.starts_with(p.as_str()))
    }

    pub fn get(&self, name: &str) -> Option<&Parameter> {
        self.by_name.get(name)
    }

    /// Every name, sorted.
    pub fn names(&self) -> Vec<&str> {
        let mut names: Vec<&str> = self.by_name.keys().map(String::as_str).collect();
        names.sort_unstable();
        names
    }
}
