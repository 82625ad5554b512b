//! Every ControlNet counts in the device's room: under a memory budget that holds the model and
//! one ControlNet but not a second, the second is refused before it loads, in one error that
//! gives the figures and the way out (a Union model), and the first alone still loads.

use vkdiff_pipeline::images::ControlDepth;
use vkdiff_pipeline::{ControlNetSettings, ModelSettings, WorkflowModels};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::{Context, Dtype, Settings};
use vkdiff_testkit::fixture;

fn controlnet(name: &str, kind: ControlKind) -> ControlNetSettings {
    ControlNetSettings {
        model: fixture(name),
        controls: vec![kind],
        depth_mode: ControlDepth::Inverse,
        scale: 1.0,
        start: 0.0,
        end: 1.0,
    }
}

fn settings(controlnets: Vec<ControlNetSettings>) -> ModelSettings {
    ModelSettings {
        model: fixture("pipeline/tiny-sdxl"),
        vae: None,
        unet: None,
        precision: Dtype::F32,
        controlnets,
        ip_adapter: None,
        loras: Vec::new(),
        vae_tiling: Default::default(),
    }
}

fn budgeted(bytes: u64) -> Context {
    Context::new(&Default::default(), Settings { memory_budget: Some(bytes), ..vkdiff_testkit::settings() })
        .expect("a Vulkan device (apt-get install mesa-vulkan-drivers)")
}

/// Device bytes a load leaves in use, under a budget too large to matter.
fn live_after(models: &ModelSettings) -> u64 {
    let ctx = budgeted(1 << 40);
    let _loaded = WorkflowModels::load(&ctx, models, &mut |_| {}).unwrap();
    (1 << 40) - ctx.memory_room().free
}

#[test]
fn a_second_controlnet_that_does_not_fit_is_refused_before_it_loads() {
    let one = settings(vec![controlnet("workflow/controlnet", ControlKind::Depth)]);
    let two = settings(vec![
        controlnet("workflow/controlnet", ControlKind::Depth),
        controlnet("workflow/controlnet-small", ControlKind::Edges),
    ]);
    let (with_one, with_two) = (live_after(&one), live_after(&two));
    assert!(with_two > with_one, "the second ControlNet holds device memory: {with_one} and {with_two} bytes");
    // Room for the model and the first ControlNet, not for half the second's weights.
    let budget = with_one + (with_two - with_one) / 2;
    let mut log = Vec::new();
    let refused = WorkflowModels::load(&budgeted(budget), &two, &mut |line| log.push(line.to_string()));
    let message = refused.err().expect("the second ControlNet cannot fit").to_string();
    assert!(
        message.contains("controlnet-small")
            && message.contains("MiB are free by VKDIFF_MEMORY_BUDGET")
            && message.contains("ControlNet-Union"),
        "{message}"
    );
    assert!(!log.iter().any(|l| l.contains("controlnet-small")), "it began to load: {log:?}");
    WorkflowModels::load(&budgeted(budget), &one, &mut |_| {}).expect("the model and one ControlNet fit");
}
