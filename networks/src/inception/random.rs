//! Reproducible random InceptionV3 weights of the real architecture, which
//! `tools/make_fid_fixtures.py` draws bit for bit in numpy: the network is held to torch-fidelity
//! at full size without committing a 95 MB file. Convolutions are He-uniform and batch norms near
//! the identity, so activations keep their scale through the 94 layers.

use crate::error::{Error, Result};
use crate::inception::architecture::basic_convs;
use crate::inception::inception_v3::TensorSource;
use std::collections::HashMap;

pub struct RandomInception {
    tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
}

impl RandomInception {
    pub fn new() -> RandomInception {
        let mut tensors = HashMap::new();
        for (name, s) in basic_convs() {
            let [kh, kw] = s.kernel;
            let fan_in = s.cin * kh * kw;
            let bound = (6.0 / fan_in as f64).sqrt() as f32;
            let mut put = |suffix: &str, shape: Vec<usize>, f: &dyn Fn(f32) -> f32| {
                let key = format!("{name}.{suffix}");
                let values = uniform(&key, shape.iter().product()).into_iter().map(f).collect();
                tensors.insert(key, (shape, values));
            };
            put("conv.weight", vec![s.cout, s.cin, kh, kw], &|u| (2.0 * u - 1.0) * bound);
            put("bn.weight", vec![s.cout], &|u| 1.0 + 0.1 * (2.0 * u - 1.0));
            put("bn.bias", vec![s.cout], &|u| 0.1 * (2.0 * u - 1.0));
            put("bn.running_mean", vec![s.cout], &|u| 0.1 * (2.0 * u - 1.0));
            put("bn.running_var", vec![s.cout], &|u| 0.5 + u);
        }
        RandomInception { tensors }
    }
}

impl RandomInception {
    /// Every tensor, sorted by name (to write as a weights file).
    pub fn tensors(&self) -> Vec<(&str, &[usize], &[f32])> {
        let mut all: Vec<_> = self.tensors.iter().map(|(n, (s, v))| (n.as_str(), s.as_slice(), v.as_slice())).collect();
        all.sort_by_key(|t| t.0);
        all
    }
}

impl Default for RandomInception {
    fn default() -> Self {
        Self::new()
    }
}

impl TensorSource for RandomInception {
    fn values(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
        self.tensors
            .get(name)
            .cloned()
            .ok_or_else(|| Error::Checkpoint(format!("tensor `{name}` is not an InceptionV3 weight")))
    }
}

/// Element i of the tensor `name`: the top 24 bits of splitmix64(fnv1a64(name) + i), in [0, 1).
fn uniform(name: &str, n: usize) -> Vec<f32> {
    let key = name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
    (0..n as u64).map(|i| (splitmix64(key.wrapping_add(i)) >> 40) as f32 / (1u64 << 24) as f32).collect()
}

fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
