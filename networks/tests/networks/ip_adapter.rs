//! The CLIP vision encoder and the IP-Adapter image projections against transformers/diffusers
//! on tiny random models (tools/make_workflow_fixtures.py), and the adapter loader's errors.

use crate::errors::assert_one_line;
use crate::forward::errors;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_formats::{write_safetensors_f32, SafeTensors};
use vkdiff_networks::unet_checkpoint;
use vkdiff_networks::{ClipVisionModelWithProjection, ImageFeature, IpAdapter, IpAdapterKind, UNet};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::{ctx, random};
use vkdiff_testkit::{fixture, scratch};

/// records.safetensors and records.json of the workflow fixture.
fn records() -> (SafeTensors, Value) {
    let json = std::fs::read_to_string(fixture("workflow").join("records.json")).unwrap();
    (SafeTensors::open(&fixture("workflow").join("records.safetensors")).unwrap(), serde_json::from_str(&json).unwrap())
}

/// f32 differs from torch in summation order and transcendental functions only (measured
/// relative L2 errors ≤ 1e-6 through the 3-layer encoder and the 4-layer resampler); f16 stores
/// weights and every activation with 11 significant bits (measured ≤ 1e-3).
fn tolerance(dtype: Dtype) -> f64 {
    match dtype {
        Dtype::F32 => 1e-5,
        Dtype::F16 => 1e-2,
    }
}

fn check(what: &str, dtype: Dtype, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{what}: {} values, reference has {}", got.len(), want.len());
    let (rel, worst) = errors(got, want);
    eprintln!("{what} {dtype:?}: relative L2 error {rel:.2e}, worst {worst:.2e} RMS");
    assert!(
        rel < tolerance(dtype) && worst < 20.0 * tolerance(dtype),
        "{what} {dtype:?}: relative L2 error {rel:.2e}, worst {worst:.2e} RMS"
    );
}

fn tiny_unet(dtype: Dtype) -> UNet {
    let (config, ckpt) = unet_checkpoint(&ctx(), &fixture("pipeline").join("tiny-sdxl/unet"), dtype).unwrap();
    UNet::load(&config, &ckpt).unwrap()
}

/// A plain adapter of random weights for `unet`, keyed as h94's files are; `edit` may change
/// the tensors before they are written.
fn synthetic_plain(unet: &UNet, path: &Path, edit: impl FnOnce(&mut BTreeMap<String, (Vec<usize>, Vec<f32>)>)) {
    let d = unet.config().cross_attention_dim;
    let mut t = BTreeMap::new();
    let mut put = |name: String, shape: Vec<usize>| {
        let n = shape.iter().product();
        let seed = t.len() as u64 + 1;
        t.insert(name, (shape, random(n, seed)));
    };
    put("image_proj.proj.weight".into(), vec![4 * d, 32]);
    put("image_proj.proj.bias".into(), vec![4 * d]);
    put("image_proj.norm.weight".into(), vec![d]);
    put("image_proj.norm.bias".into(), vec![d]);
    for (k, &c) in unet.cross_attention_channels().iter().enumerate() {
        put(format!("ip_adapter.{}.to_k_ip.weight", 2 * k + 1), vec![c, d]);
        put(format!("ip_adapter.{}.to_v_ip.weight", 2 * k + 1), vec![c, d]);
    }
    edit(&mut t);
    let list: Vec<(&str, &[usize], &[f32])> =
        t.iter().map(|(k, (s, v))| (k.as_str(), s.as_slice(), v.as_slice())).collect();
    write_safetensors_f32(path, &list, &BTreeMap::new()).unwrap();
}

fn load_error(path: &Path, unet: &UNet) -> String {
    match IpAdapter::load(&ctx(), path, unet, Dtype::F32) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => e.to_string(),
    }
}

/// LayerNorm(reshape(W·e + b)) on the host, in f64.
fn plain_reference(w: &[f32], b: &[f32], gamma: &[f32], beta: &[f32], e: &[f32], d: usize) -> Vec<f32> {
    let k = e.len();
    let y: Vec<f64> =
        (0..b.len()).map(|o| b[o] as f64 + (0..k).map(|i| w[o * k + i] as f64 * e[i] as f64).sum::<f64>()).collect();
    y.chunks(d)
        .flat_map(|t| {
            let mean = t.iter().sum::<f64>() / d as f64;
            let var = t.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d as f64;
            t.iter()
                .enumerate()
                .map(move |(i, v)| ((v - mean) / (var + 1e-5).sqrt() * gamma[i] as f64 + beta[i] as f64) as f32)
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn ip_adapter_synthetic_plain_projection_and_unet_input() {
    let unet = tiny_unet(Dtype::F32);
    let path = scratch("ip-adapter-plain").join("ip-adapter.safetensors");
    synthetic_plain(&unet, &path, |_| {});
    let adapter = IpAdapter::load(&ctx(), &path, &unet, Dtype::F32).unwrap();
    assert_eq!(adapter.kind(), IpAdapterKind::Plain);
    assert_eq!(adapter.num_tokens(), 4);
    let file = vkdiff_formats::SafeTensors::open(&path).unwrap();
    let v = |n: &str| file.values(n).unwrap().1;
    let d = unet.config().cross_attention_dim;
    let embeds = random(2 * 32, 99);
    let got = adapter.image_tokens(&embeds, &[2, 32]).unwrap();
    let want: Vec<f32> = embeds
        .chunks(32)
        .flat_map(|e| {
            plain_reference(
                &v("image_proj.proj.weight"),
                &v("image_proj.proj.bias"),
                &v("image_proj.norm.weight"),
                &v("image_proj.norm.bias"),
                e,
                d,
            )
        })
        .collect();
    let (rel, _) = errors(&got, &want);
    eprintln!("synthetic plain projection f32: relative L2 error {rel:.2e}");
    assert!(rel < 1e-5, "relative L2 error {rel:.2e}");
    let layers = unet.cross_attention_channels().len();
    let input = adapter.unet_input(&got, 2, vec![0.7; layers]).unwrap();
    assert_eq!(input.tokens.shape(), [2, 4, d]);
    assert_eq!(input.layers.len(), layers);
    assert!(adapter.unet_input(&got, 2, vec![0.7; layers + 1]).is_err(), "a scale per layer");
    assert!(adapter.image_tokens(&embeds, &[2, 31]).is_err());
}

#[test]
fn ip_adapter_bin_files_ask_for_safetensors() {
    let unet = tiny_unet(Dtype::F32);
    let path = scratch("ip-adapter-bin").join("ip-adapter_sdxl.bin");
    std::fs::write(&path, b"PK\x03\x04 not really a zip").unwrap();
    assert_one_line(&load_error(&path, &unet), &["ip-adapter_sdxl.bin", "safetensors"]);
}

#[test]
fn ip_adapter_for_another_unet_is_named() {
    let unet = tiny_unet(Dtype::F32);
    let n = unet.cross_attention_channels().len();
    let dir = scratch("ip-adapter-mismatch");
    // One cross-attention too few.
    let path = dir.join("missing.safetensors");
    synthetic_plain(&unet, &path, |t| {
        t.retain(|k, _| !k.starts_with(&format!("ip_adapter.{}.", 2 * n - 1)));
    });
    assert_one_line(
        &load_error(&path, &unet),
        &["missing.safetensors", "another UNet", &format!("{n} cross-attentions")],
    );
    // Wrong width of one layer.
    let path = dir.join("width.safetensors");
    synthetic_plain(&unet, &path, |t| {
        let d = unet.config().cross_attention_dim;
        t.insert("ip_adapter.3.to_v_ip.weight".into(), (vec![8, d], vec![0.0; 8 * d]));
    });
    assert_one_line(&load_error(&path, &unet), &["width.safetensors", "ip_adapter.3.to_v_ip.weight", "another UNet"]);
    // Not an IP-Adapter projection vkdiff knows.
    let path = dir.join("full.safetensors");
    synthetic_plain(&unet, &path, |t| {
        let w = t.remove("image_proj.proj.weight").unwrap();
        t.insert("image_proj.proj.0.weight".into(), w);
    });
    assert_one_line(&load_error(&path, &unet), &["full.safetensors", "not supported"]);
}

/// The encoder's outputs for the style images (one at a time and batched) and for all-zero
/// pixels, against transformers' `image_embeds` and `hidden_states[-2]`.
#[test]
fn ip_adapter_image_encoder_matches_transformers() {
    let (rec, meta) = records();
    let cases = meta["image_encoder"]["tensors"].as_object().expect("records.json image_encoder.tensors");
    let value = |name: &Value| rec.values(name.as_str().unwrap()).unwrap();
    for dtype in [Dtype::F32, Dtype::F16] {
        let encoder =
            ClipVisionModelWithProjection::load_folder(&ctx(), &fixture("workflow").join("image_encoder"), dtype)
                .unwrap();
        let s = encoder.config().image_size;
        let both = [ImageFeature::ImageEmbeds, ImageFeature::Penultimate];
        let (mut batch_pixels, mut batch_embeds, mut batch_hidden) = (Vec::new(), Vec::new(), Vec::new());
        for (case, names) in cases {
            let pixels = match names.get("pixel_values") {
                Some(n) => value(n).1,
                None => vec![0.0; 3 * s * s],
            };
            let out = encoder.encode(&pixels, 1, &both).unwrap();
            let (embeds, hidden) = (value(&names["image_embeds"]).1, value(&names["hidden_m2"]).1);
            check(&format!("{case} image_embeds"), dtype, out.image_embeds.as_ref().unwrap(), &embeds);
            check(&format!("{case} hidden_states[-2]"), dtype, out.penultimate.as_ref().unwrap(), &hidden);
            // Asked for the penultimate states alone, the last layer is skipped: same values.
            let alone = encoder.encode(&pixels, 1, &[ImageFeature::Penultimate]).unwrap();
            assert!(alone.image_embeds.is_none());
            assert_eq!(alone.penultimate, out.penultimate, "{case}: penultimate alone differs");
            batch_pixels.extend(pixels);
            batch_embeds.extend(embeds);
            batch_hidden.extend(hidden);
        }
        let out = encoder.encode(&batch_pixels, cases.len(), &both).unwrap();
        check("batched image_embeds", dtype, out.image_embeds.as_ref().unwrap(), &batch_embeds);
        check("batched hidden_states[-2]", dtype, out.penultimate.as_ref().unwrap(), &batch_hidden);
        let (_, shape) = out.get(ImageFeature::Penultimate).unwrap();
        assert_eq!(shape, [cases.len(), encoder.config().tokens(), encoder.config().hidden_size]);
    }
}

/// The plain and Plus projections of the recorded encoder outputs against diffusers'
/// `encoder_hid_proj`, and the chain encoder → projection from pixels.
#[test]
fn ip_adapter_projections_match_diffusers() {
    let (rec, meta) = records();
    let clip = &meta["image_encoder"]["tensors"];
    let value = |name: &Value| rec.values(name.as_str().unwrap()).unwrap();
    for dtype in [Dtype::F32, Dtype::F16] {
        let unet = tiny_unet(dtype);
        let hidden: Vec<u64> =
            meta["ip_adapter_layers"].as_array().unwrap().iter().map(|l| l["hidden"].as_u64().unwrap()).collect();
        let channels: Vec<u64> = unet.cross_attention_channels().iter().map(|&c| c as u64).collect();
        assert_eq!(channels, hidden, "cross-attention channels in diffusers' processor order");
        let encoder =
            ClipVisionModelWithProjection::load_folder(&ctx(), &fixture("workflow").join("image_encoder"), dtype)
                .unwrap();
        for (file, kind, section) in [
            ("ip-adapter_tiny.safetensors", IpAdapterKind::Plain, "plain"),
            ("ip-adapter-plus_tiny.safetensors", IpAdapterKind::Plus, "plus"),
        ] {
            let adapter = IpAdapter::load(&ctx(), &fixture("workflow").join(file), &unet, dtype).unwrap();
            assert_eq!(adapter.kind(), kind);
            let feature = kind.feature();
            let key = if feature == ImageFeature::ImageEmbeds { "image_embeds" } else { "hidden_m2" };
            let tokens = &meta["ip_projection"][section];
            for case in ["style-1", "style-2", "negative"] {
                let source = if case == "negative" { "zeros" } else { case };
                let (shape, features) = value(&clip[source][key]);
                // Plain adapters' negative is the projection of zero embeddings, Plus' that of the
                // encoder's output for zero pixels.
                let features = if case == "negative" && kind == IpAdapterKind::Plain {
                    vec![0.0; features.len()]
                } else {
                    features
                };
                let got = adapter.image_tokens(&features, &shape).unwrap();
                let want = value(&tokens[case]).1;
                check(&format!("{section} {case} tokens"), dtype, &got, &want);
                if case != "negative" {
                    let px = value(&clip[case]["pixel_values"]).1;
                    let enc = encoder.encode(&px, 1, &[feature]).unwrap();
                    let (f, s) = enc.get(feature).unwrap();
                    check(
                        &format!("{section} {case} pixels -> tokens"),
                        dtype,
                        &adapter.image_tokens(f, &s).unwrap(),
                        &want,
                    );
                }
            }
            if kind == IpAdapterKind::Plain {
                // Two images for one adapter: 2 × 4 tokens for one batch item.
                let mut embeds = value(&clip["style-1"]["image_embeds"]).1;
                embeds.extend(value(&clip["style-2"]["image_embeds"]).1);
                let e = embeds.len() / 2;
                let two = adapter.image_tokens(&embeds, &[2, e]).unwrap();
                check("plain two-image tokens", dtype, &two, &value(&tokens["two"]).1);
                let negative = adapter.image_tokens(&vec![0.0; 2 * e], &[2, e]).unwrap();
                check("plain two-image negative tokens", dtype, &negative, &value(&tokens["two_negative"]).1);
                let mut both = negative.clone();
                both.extend(&two);
                let input = adapter.unet_input(&both, 2, vec![0.6; unet.cross_attention_channels().len()]).unwrap();
                assert_eq!(input.tokens.shape(), [2, 8, unet.config().cross_attention_dim]);
            }
        }
    }
}

#[test]
fn the_config_names_the_cross_attentions_the_unet_builds() {
    for path in [
        fixture("pipeline").join("tiny-sdxl/unet"),
        fixture("unet").join("sdxl3/unet"),
        fixture("unet").join("heads/unet"),
    ] {
        let (config, ckpt) = unet_checkpoint(&ctx(), &path, Dtype::F16).unwrap();
        let unet = UNet::load(&config, &ckpt).unwrap();
        assert_eq!(config.cross_attentions().unwrap(), unet.cross_attentions(), "{}", path.display());
        for c in unet.cross_attentions() {
            assert!(
                unet.parameters().get(&format!("{}.to_q.weight", c.name)).is_some(),
                "{} is not a module of the UNet",
                c.name
            );
        }
    }
}

#[test]
fn an_image_encoder_with_head_size_10_matches_transformers() {
    let dir = fixture("compat");
    let meta: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("records.json")).unwrap()).unwrap();
    let rec = SafeTensors::open(&dir.join("records.safetensors")).unwrap();
    let names = &meta["image_encoder_head10"];
    let value = |key: &str| rec.values(names["tensors"][key].as_str().unwrap()).unwrap().1;
    for dtype in [Dtype::F32, Dtype::F16] {
        let encoder =
            ClipVisionModelWithProjection::load_folder(&ctx(), &dir.join(names["folder"].as_str().unwrap()), dtype)
                .unwrap();
        assert_eq!(encoder.config().hidden_size / encoder.config().num_attention_heads, 10);
        let out =
            encoder.encode(&value("pixel_values"), 2, &[ImageFeature::ImageEmbeds, ImageFeature::Penultimate]).unwrap();
        check("head-10 image_embeds", dtype, out.image_embeds.as_ref().unwrap(), &value("image_embeds"));
        check("head-10 hidden_states[-2]", dtype, out.penultimate.as_ref().unwrap(), &value("hidden_m2"));
    }
}
