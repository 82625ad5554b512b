//! The CLIP text encoders and the VAE against transformers/diffusers on the tiny SDXL pipeline
//! (tools/make_pipeline_fixtures.py), from the diffusers folder and the single file.

use crate::forward::errors;
use std::path::PathBuf;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{nchw_to_nhwc, nhwc_to_nchw, AutoencoderKl, ClipTextModel, TextEncoderSlot};
use vkdiff_runtime::{listing_variants, Context, Dtype};
use vkdiff_testkit::fixture;
use vkdiff_testkit::{assert_network_kernels, ctx, ctx_with};

fn records() -> SafeTensors {
    SafeTensors::open(&fixture("pipeline").join("records.safetensors")).unwrap()
}

fn layouts() -> [PathBuf; 2] {
    [fixture("pipeline").join("tiny-sdxl"), fixture("pipeline").join("tiny-sdxl.safetensors")]
}

/// f32 differs from torch only in summation order (measured ~1e-6); f16 stores every activation
/// with 11 significant bits over a handful of layers.
fn tolerance(dtype: Dtype) -> f64 {
    match dtype {
        Dtype::F32 => 1e-4,
        Dtype::F16 => 1e-2,
    }
}

#[test]
fn text_encoders_match_transformers() {
    let rec = records();
    let cases = (0..).take_while(|i| rec.entries.contains_key(&format!("text.{i}.ids_1"))).count();
    assert!(cases >= 3, "fixture has {cases} text cases");
    for model in layouts() {
        for dtype in [Dtype::F32, Dtype::F16] {
            let te1 = ClipTextModel::load_sdxl(&ctx(), &model, TextEncoderSlot::ClipL, dtype).unwrap();
            let te2 = ClipTextModel::load_sdxl(&ctx(), &model, TextEncoderSlot::BigG, dtype).unwrap();
            for i in 0..cases {
                let ids = |n: usize| {
                    rec.values(&format!("text.{i}.ids_{n}")).unwrap().1.iter().map(|&v| v as u32).collect::<Vec<u32>>()
                };
                let ((e1, e2), ran) =
                    listing_variants(|| (te1.encode(&[ids(1)]).unwrap(), te2.encode(&[ids(2)]).unwrap()));
                // Heads of 64 values in both tiny encoders.
                assert_network_kernels(&ctx(), dtype, &ran, 64, &format!("text encoders {dtype:?} case {i}"));
                for (what, got, name) in [
                    ("hidden_1", &e1.penultimate, "hidden_1"),
                    ("hidden_2", &e2.penultimate, "hidden_2"),
                    ("pooled", e2.pooled.as_ref().unwrap(), "pooled"),
                ] {
                    let (_, want) = rec.values(&format!("text.{i}.{name}")).unwrap();
                    let (rel, _) = errors(got, &want);
                    assert!(
                        rel <= tolerance(dtype),
                        "{} {dtype:?} text case {i} {what}: relative L2 error {rel:.2e}",
                        model.display()
                    );
                }
                assert!(e1.pooled.is_none(), "CLIP-L's pooled output is not used by SDXL");
            }
        }
    }
}

fn decode(vae: &AutoencoderKl, latent: &(Vec<usize>, Vec<f32>)) -> Vec<f32> {
    let s = &latent.0;
    let (out, shape) =
        vae.decode(&nchw_to_nhwc(&latent.1, [s[0], s[1], s[2], s[3]]), [s[0], s[2], s[3], s[1]]).unwrap();
    nhwc_to_nchw(&out, shape)
}

#[test]
fn vae_decodes_and_encodes_like_diffusers() {
    let rec = records();
    let latent = rec.values("vae.latent").unwrap();
    let (is, image) = rec.values("vae.image").unwrap();
    for model in layouts() {
        // force_upcast: the VAE runs in f32 whatever the run precision.
        let vae = AutoencoderKl::load_sdxl(&ctx(), &model, Dtype::F16).unwrap();
        assert_eq!(vae.dtype(), Dtype::F32);
        let (rel, _) = errors(&decode(&vae, &latent), &rec.values("vae.decoded").unwrap().1);
        assert!(rel <= 1e-4, "{} decode: relative L2 error {rel:.2e}", model.display());
        let (mean, logvar) =
            vae.encode(&nchw_to_nhwc(&image, [is[0], is[1], is[2], is[3]]), [is[0], is[2], is[3], is[1]]).unwrap();
        let lat_shape = [is[0], vae.config().latent_channels, is[2] / 8, is[3] / 8];
        for (what, got) in [("encoded_mean", mean), ("encoded_logvar", logvar)] {
            let (rel, _) = errors(
                &nhwc_to_nchw(&got, [lat_shape[0], lat_shape[2], lat_shape[3], lat_shape[1]]),
                &rec.values(&format!("vae.{what}")).unwrap().1,
            );
            assert!(rel <= 1e-4, "{} {what}: relative L2 error {rel:.2e}", model.display());
        }
    }
}

#[test]
fn vae_decode_in_bands_equals_the_whole_decode() {
    // A binding limit far below the activations makes every conv, norm and upsample run in
    // bands; the result must be the same image, not a tiled approximation.
    let rec = records();
    let latent = rec.values("vae.latent").unwrap();
    let ctx: Context = ctx_with(ctx().choices().gemm_family);
    let vae = AutoencoderKl::load_sdxl(&ctx, &layouts()[0], Dtype::F32).unwrap();
    let whole = decode(&vae, &latent);
    ctx.choose(|c| c.binding_limit = 160 << 10);
    let banded = decode(&vae, &latent);
    let (rel, worst) = errors(&banded, &whole);
    assert!(rel <= 1e-6 && worst <= 1e-5, "banded decode differs: relative L2 {rel:.2e}, worst {worst:.2e} of RMS");
}

#[test]
fn a_text_encoder_saved_without_its_text_model_level_loads_the_same() {
    // transformers 5 saves CLIPTextModel as `embeddings.…`, `encoder.layers.…` (no `text_model.`).
    let source = fixture("pipeline").join("tiny-sdxl");
    let dir = vkdiff_testkit::scratch("no-text-model-level");
    std::fs::create_dir_all(dir.join("text_encoder")).unwrap();
    std::fs::copy(source.join("text_encoder/config.json"), dir.join("text_encoder/config.json")).unwrap();
    let mut parts = crate::malformed::read_parts(&source.join("text_encoder/model.safetensors"));
    parts.header = parts
        .header
        .into_iter()
        .map(|(k, v)| (k.strip_prefix("text_model.").map_or(k.clone(), String::from), v))
        .collect();
    assert!(parts.header.keys().any(|k| k.starts_with("encoder.layers.")));
    crate::malformed::write_parts(&dir.join("text_encoder/model.safetensors"), &parts);
    let ids = vec![vec![49406, 320, 1125, 539, 49407, 49407]];
    let encode = |path: &std::path::Path| {
        ClipTextModel::load_sdxl(&ctx(), path, TextEncoderSlot::ClipL, Dtype::F32)
            .unwrap()
            .encode(&ids)
            .unwrap()
            .penultimate
    };
    assert_eq!(encode(&dir), encode(&source));
}
