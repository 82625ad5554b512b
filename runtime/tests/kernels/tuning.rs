//! `VKDIFF_TUNE=1` (`Context::set_tuning`): a linear layer, a convolution and an attention, each
//! recorded twice on a tuning context. Each shape is timed once, on exactly the distinct kernels
//! the settings reach (found here by recording the op under each setting on a context that does
//! not tune), takes the one it reports, and computes what the context that does not tune does.

use std::collections::BTreeSet;
use vkdiff_runtime::ops::{attention, conv2d, linear, AttentionLayout, ConvParams};
use vkdiff_runtime::{variant_label, Choices, Context, Dtype, MatrixTile, ProbeChoice, Recorder, Tensor};
use vkdiff_testkit::*;

/// The op under test on its inputs and output.
type Op<'a> = &'a dyn Fn(&mut Recorder, &[Tensor], &Tensor) -> vkdiff_runtime::Result<()>;

/// What a recording of `op` dispatched, as the tuner names a candidate.
fn kernels_of(ctx: &Context, op: Op, inputs: &[Tensor], out: &Tensor) -> String {
    let ran = ctx.run_listing(|rec| op(rec, inputs, out)).unwrap();
    ran.iter().map(|v| variant_label(v)).collect::<Vec<_>>().join(" + ")
}

/// An op's case: its name as the tuner reports it, its inputs' shapes, its output's, whether the
/// matrix units' tile applies, and its probe's setting.
struct Case {
    what: &'static str,
    inputs: Vec<Vec<usize>>,
    out: Vec<usize>,
    tiles: bool,
    probe: fn(&mut Choices, ProbeChoice),
}

/// Every distinct kernel list `op` records under the settings tuning may choose between, on
/// `plain` (which does not tune; its settings are left as found).
fn reachable(plain: &Context, op: Op, (inputs, out): (&[Tensor], &Tensor), case: &Case) -> BTreeSet<String> {
    // A tile set by VKDIFF_MATRIX_TILE is the tuner's too.
    let set = plain.choices().matrix_tile;
    let open = case.tiles && set == MatrixTile::Auto;
    let every = [MatrixTile::Auto, MatrixTile::Eight, MatrixTile::EightTall, MatrixTile::EightWide];
    let tiles: &[MatrixTile] = if open { &every } else { &[set] };
    let mut found = BTreeSet::new();
    for &tile in tiles {
        for choice in [ProbeChoice::Auto, ProbeChoice::Matrix2] {
            plain.choose(|c| c.matrix_tile = tile);
            plain.choose(|c| (case.probe)(c, choice));
            found.insert(kernels_of(plain, op, inputs, out));
        }
    }
    plain.choose(|c| c.matrix_tile = set);
    plain.choose(|c| (case.probe)(c, ProbeChoice::Auto));
    found
}

/// Runs `op` twice on `tuned` and once on `plain` on the same values, and checks the tuner's
/// bookkeeping and result.
fn check(tuned: &Context, plain: &Context, op: Op, case: Case) {
    let what = case.what;
    let on = |ctx: &Context| -> Vec<Tensor> {
        let values = |i: usize, shape: &[usize]| stored(&random(shape.iter().product(), 10 + i as u64), Dtype::F16);
        case.inputs.iter().enumerate().map(|(i, s)| ctx.upload(s, Dtype::F16, &values(i, s)).unwrap()).collect()
    };
    let (tuned_in, plain_in) = (on(tuned), on(plain));
    let (out, want) = (tuned.zeros(&case.out, Dtype::F16).unwrap(), plain.zeros(&case.out, Dtype::F16).unwrap());
    let reach = reachable(plain, op, (&plain_in, &want), &case);
    kernels_of(plain, op, &plain_in, &want);
    let before = tuned.tuned_shapes().len();
    let first = kernels_of(tuned, op, &tuned_in, &out);
    let shapes = tuned.tuned_shapes();
    assert_eq!(kernels_of(tuned, op, &tuned_in, &out), first, "{what}: a shape keeps its kernels");
    assert_eq!(tuned.tuned_shapes(), shapes, "{what}: timed once");
    if reach.len() == 1 {
        assert_eq!(shapes.len(), before, "{what}: one kernel ({reach:?}) is nothing to tune");
        assert_eq!(reach.first(), Some(&first), "{what}");
    } else {
        assert_eq!(shapes.len(), before + 1, "{what}: {shapes:?}");
        let shape = shapes.iter().find(|s| s.op.starts_with(what)).unwrap_or_else(|| panic!("{what}: {shapes:?}"));
        let timed: BTreeSet<String> = shape.timed.iter().map(|(k, _)| k.clone()).collect();
        assert_eq!(timed, reach, "{what}: every distinct kernel timed, each once");
        assert!(shape.timed.iter().all(|(_, ms)| *ms > 0.0), "{what}: {shape:?}");
        assert_eq!(shape.winner().0, first, "{what}: the op takes the kernels the tuner chose");
    }
    let want: Vec<f64> = want.download().unwrap().into_iter().map(f64::from).collect();
    assert_close(what, &out.download().unwrap(), &want, 2e-3, 4.0 * storage_rtol(Dtype::F16));
}

#[test]
fn tuning_times_each_shapes_kernels_once_and_takes_the_one_it_reports() {
    let (tuned, plain) = (private_ctx(), private_ctx());
    tuned.set_tuning(true).unwrap();
    assert!(tuned.tuning() && !plain.tuning());
    let lin: Op = &|rec, t, out| linear(rec, &t[0], &t[1], Some(&t[2]), out);
    let case = |what, inputs: &[&[usize]], out: &[usize], tiles, probe| Case {
        what,
        inputs: inputs.iter().map(|s| s.to_vec()).collect(),
        out: out.to_vec(),
        tiles,
        probe,
    };
    check(
        &tuned,
        &plain,
        lin,
        case("linear 64×64×64", &[&[64, 64], &[64, 64], &[64]], &[64, 64], true, |c, p| c.linear = p),
    );
    let conv: Op = &|rec, t, out| conv2d(rec, &t[0], &t[1], None, out, &ConvParams::new(1, 1));
    let conv_case =
        case("conv2d 3×3 8×8×32 → 32", &[&[1, 8, 8, 32], &[32, 3, 3, 32]], &[1, 8, 8, 32], true, |c, p| {
            c.conv = p
        });
    check(&tuned, &plain, conv, conv_case);
    let l = AttentionLayout::dense(1, 2, 64, 64, 64);
    let attend: Op = &|rec, t, out| attention(rec, &t[0], &t[1], &t[2], out, &l, 0.125);
    let qkv: &[&[usize]] = &[&[1, 64, 128], &[1, 64, 128], &[1, 64, 128]];
    check(&tuned, &plain, attend, case("attention 64×64 tokens", qkv, &[1, 64, 128], false, |c, p| c.attention = p));
    let summary = tuned.tuning_summary().unwrap();
    let shapes = format!("VKDIFF_TUNE: {} shapes had kernels to choose between; ", tuned.tuned_shapes().len());
    assert!(summary.starts_with(&shapes), "{summary}");
    assert_eq!(plain.tuning_summary(), None);
}
