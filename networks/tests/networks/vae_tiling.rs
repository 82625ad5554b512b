//! The tiled VAE decode against diffusers' `enable_tiling` on the tiny SDXL VAE
//! (tools/make_vae_tiling_fixtures.py): the config's tile and a smaller one, batch 2.

use crate::forward::errors;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{nchw_to_nhwc, nhwc_to_nchw, AutoencoderKl, VaeTiling};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::{ctx, fixture};

#[test]
fn tiled_decode_matches_diffusers_enable_tiling() {
    let rec = SafeTensors::open(&fixture("pipeline").join("vae_tiling.safetensors")).unwrap();
    let (s, latent) = rec.values("latent").unwrap();
    let vae = AutoencoderKl::load_sdxl(&ctx(), &fixture("pipeline").join("tiny-sdxl"), Dtype::F32).unwrap();
    assert_eq!(vae.config().tile_sample_size(), 64, "diffusers' default tile is the config's sample_size");
    let nhwc = nchw_to_nhwc(&latent, [s[0], s[1], s[2], s[3]]);
    let shape = [s[0], s[2], s[3], s[1]];
    let (whole, _) = vae.decode(&nhwc, shape).unwrap();
    for tile in [64, 32] {
        let tiling = VaeTiling { tile };
        assert!(vae.config().tiles(tiling, s[2], s[3]));
        let (out, out_shape) = vae.decode_tiled(&nhwc, shape, tiling).unwrap();
        let got = nhwc_to_nchw(&out, out_shape);
        let (want_shape, want) = rec.values(&format!("tiled_{tile}")).unwrap();
        assert_eq!([out_shape[0], out_shape[3], out_shape[1], out_shape[2]].to_vec(), want_shape);
        let (rel, worst) = errors(&got, &want);
        assert!(rel <= 1e-4, "tile {tile}: relative L2 error {rel:.2e} (worst {worst:.2e} of RMS)");
        // The tiles' own statistics: not the whole decode (the test would hold nothing otherwise).
        let (apart, _) = errors(&nhwc_to_nchw(&whole, out_shape), &want);
        assert!(apart > 1e-2, "tile {tile}: the tiled decode should differ from the whole one ({apart:.2e})");
    }
    // A latent within one tile decodes whole, as diffusers does.
    let one_tile = VaeTiling { tile: 128 };
    assert!(!vae.config().tiles(one_tile, s[2], s[3]));
    assert_eq!(vae.decode_tiled(&nhwc, shape, one_tile).unwrap().0, whole);
    let err = vae.decode_tiled(&nhwc, shape, VaeTiling { tile: 40 }).unwrap_err().to_string();
    assert!(err.contains("multiple of 32 pixels"), "{err}");
}
