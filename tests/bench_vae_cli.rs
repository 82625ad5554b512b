//! `vkdiff bench vae` as a user runs it: SDXL's real VAE (random weights) at a tiny size.

mod cli;

use cli::vkdiff;

#[test]
fn bench_vae_decodes_whole_and_in_tiles_in_f16() {
    // f16 is the fp16-fix VAE's config; at 64² its mid-block attends over 64 tokens with one
    // head of 512, which runs as products on f32 copies.
    let result =
        vkdiff(&["bench", "vae", "--size", "64", "--tile", "32", "--precision", "f16", "--samples", "2", "--json"]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let stdout = String::from_utf8_lossy(&result.stdout);
    let row: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or("")).expect("one JSON line");
    assert_eq!(row["precision"], "f16", "{row}");
    assert_eq!(row["size"], 64, "{row}");
    assert_eq!(row["tiled"]["tile"], 32, "{row}");
    assert!(row["reference"].is_null(), "no --reference-device, no reference: {row}");
    let activations = |decode: &str| row[decode]["activations_mib"].as_f64().unwrap();
    for decode in ["whole", "tiled"] {
        assert!(row[decode]["seconds"].as_f64().unwrap() > 0.0, "{row}");
        assert!(activations(decode) > 0.0 && activations(decode) <= row[decode]["estimate_mib"].as_f64().unwrap());
    }
    // The second decode of each kind recorded anew, on the first one's buffers.
    for decode in ["whole", "tiled"] {
        let host = &row[decode]["host"];
        assert_eq!(host["fresh_buffers"], 0, "{row}");
        assert!(host["reused_buffers"].as_u64().unwrap() > 0 && host["recording_ms"].as_f64().unwrap() > 0.0, "{row}");
    }
    // Four 32-px tiles each hold a quarter of the activations of the whole 64² decode.
    assert!(activations("tiled") < activations("whole"), "{row}");
    // f16 weights: half of the f32 VAE's 319 MiB.
    assert!((row["weights_mib"].as_f64().unwrap() - 159.6).abs() < 1.0, "{row}");
}

#[test]
fn bench_vae_times_a_given_vae_at_the_precision_its_config_allows() {
    let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/vae_swap/tiny-vae");
    let row = |vae: &std::path::Path| {
        let args = ["bench", "vae", "--size", "64", "--tile", "32", "--precision", "f16", "--json", "--vae"];
        let result = vkdiff(&[&args[..], &[vae.to_str().unwrap()]].concat());
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        let stdout = String::from_utf8_lossy(&result.stdout).into_owned();
        serde_json::from_str::<serde_json::Value>(stdout.lines().last().unwrap_or("")).expect("one JSON line")
    };
    // Its config.json says force_upcast: false: the tiny VAE's weights in f16, 2.7 MiB.
    let given = row(&fixtures);
    assert_eq!(given["precision"], "f16", "{given}");
    assert!((given["weights_mib"].as_f64().unwrap() - 2.67).abs() < 0.1, "{given}");
    // The same file with no config beside it is SDXL's, which forces f32.
    let alone = cli::scratch("bench-vae-alone").join("vae.safetensors");
    std::fs::copy(fixtures.join("sdxl_vae.safetensors"), &alone).unwrap();
    let forced = row(&alone);
    assert!(forced["precision"] == "f32" && forced["weights_mib"].as_f64().unwrap() > 5.0, "{forced}");
}
