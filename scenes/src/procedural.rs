//! The built-in source: procedural mushroom beds, scene k drawn from its seed.

use crate::{SceneInfo, SceneSource, SourceFrame};
use serde_json::{json, Map, Value};
use vkdiff_render::coco::{mushroom_category, Category};
use vkdiff_render::scene::{Scene, SceneConfig};

/// Mushroom beds drawn by `vkdiff scene`'s generator, as many as asked.
#[derive(Clone, Debug)]
pub struct ProceduralBed {
    config: SceneConfig,
}

impl ProceduralBed {
    /// The bed `config` describes, its settings checked.
    pub fn new(config: SceneConfig) -> crate::Result<ProceduralBed> {
        config.validate()?;
        Ok(ProceduralBed { config })
    }
}

impl SceneSource for ProceduralBed {
    fn available(&self) -> Option<u64> {
        None
    }

    fn scene(&self, _k: u64) -> SceneInfo<'_> {
        SceneInfo { width: self.config.width, height: self.config.height, name: None, prompt: None }
    }

    fn frame(&self, _k: u64, seed: u64) -> crate::Result<SourceFrame> {
        Ok(SourceFrame { frame: Scene::build(seed, &self.config)?.render(), shaded: None })
    }

    fn categories(&self) -> Vec<Category> {
        vec![mushroom_category()]
    }

    fn settings(&self) -> Map<String, Value> {
        let c = &self.config;
        Map::from_iter([
            ("width".to_string(), json!(c.width)),
            ("height".to_string(), json!(c.height)),
            ("density".to_string(), json!(c.bed.density)),
            ("clumping".to_string(), json!(c.bed.clumping.clustered_fraction)),
        ])
    }
}
