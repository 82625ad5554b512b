//! conv2d's 3×3 convolutions of stride 1 as Winograd's F(2×2, 3×3) (the CPU family), against
//! conv.rs's f64 convolution.

use super::conv::{check_on, winograd, Case};
use vkdiff_runtime::ops::Padding;
use vkdiff_runtime::Dtype;
use vkdiff_testkit::*;

/// 3×3 convolutions of stride 1 as Winograd's F(2×2, 3×3) on the CPU family, beside the cases of
/// conv.rs's `all`: odd and even sizes (tiles past the output's edge), one-sided padding (a band of a
/// large image), none, a residual with ReLU; the 16 products run on the GEMM, in one band of
/// tiles and, under a binding limit that just holds the transformed filters (the planes of
/// min(Cin, Cout) tiles: fewer than each case has), in several.
#[test]
fn winograd_matches_the_reference_whole_and_in_bands_of_tiles() {
    let case = |b, h, w, cin, cout, pad, residual| Case {
        b,
        h,
        w,
        cin,
        cout,
        k: [3, 3],
        stride: 1,
        pad,
        accumulate: residual,
        relu: residual,
    };
    let band = Padding { top: 1, left: 1, bottom: 0, right: 1 };
    let cases = [
        case(1, 8, 8, 12, 8, Padding::same(1), false),
        case(1, 7, 10, 8, 4, band, false),
        case(2, 6, 5, 4, 12, Padding::same(0), true),
    ];
    for (seed, c) in cases.into_iter().enumerate() {
        for dtype in DTYPES {
            let ctx = winograd();
            let filters = (16 * c.cin * c.cout) as u64 * if dtype == Dtype::F16 { 2 } else { 4 };
            for limit in [ctx.choices().binding_limit, filters] {
                ctx.choose(|choices| choices.binding_limit = limit);
                let ran = check_on(&ctx, dtype, &c, 40 + seed as u64);
                assert!(
                    ran.iter().all(|v| v.kernel == "gemm_sg"),
                    "{:?}",
                    ran.iter().map(|v| v.kernel).collect::<Vec<_>>()
                );
            }
        }
    }
}
