//! InceptionV3's layers as torch-fidelity's `FeatureExtractorInceptionV3` declares them, by module
//! name: one table that both the loader and the reproducible test weights walk.

use vkdiff_runtime::ops::{Pool, PoolOp};

/// A `BasicConv2d`'s convolution: channels, [height, width] kernel, stride, [y, x] padding.
#[derive(Clone, Copy, Debug)]
pub struct ConvSpec {
    pub cin: usize,
    pub cout: usize,
    pub kernel: [usize; 2],
    pub stride: usize,
    pub pad: [usize; 2],
}

fn conv(cin: usize, cout: usize, kernel: [usize; 2], stride: usize, pad: [usize; 2]) -> ConvSpec {
    ConvSpec { cin, cout, kernel, stride, pad }
}

fn square(cin: usize, cout: usize, k: usize, stride: usize, pad: usize) -> ConvSpec {
    conv(cin, cout, [k, k], stride, [pad, pad])
}

/// One branch: pooling, then convolutions in a chain, then (InceptionE) two side by side.
pub struct BranchSpec {
    pub pool: Option<Pool>,
    pub chain: Vec<(String, ConvSpec)>,
    pub split: Vec<(String, ConvSpec)>,
}

pub enum Stage {
    Conv(ConvSpec),
    Pool(Pool),
    /// Branches whose outputs are concatenated along channels, in order.
    Block(Vec<BranchSpec>),
}

const MAX_3X3_S2: Pool = Pool { op: PoolOp::Max, window: [3, 3], stride: 2, pad: 0 };
/// TensorFlow's average pool leaves the padding out of the mean.
const AVG_3X3_SAME: Pool = Pool { op: PoolOp::Average, window: [3, 3], stride: 1, pad: 1 };
/// Mixed_7c pools by maximum where the paper's Inception averages (the 2015 graph does so).
const MAX_3X3_SAME: Pool = Pool { op: PoolOp::Max, window: [3, 3], stride: 1, pad: 1 };

fn branch(pool: Option<Pool>, chain: &[(&str, ConvSpec)], split: &[(&str, ConvSpec)]) -> BranchSpec {
    let own = |list: &[(&str, ConvSpec)]| list.iter().map(|(n, s)| (n.to_string(), *s)).collect();
    BranchSpec { pool, chain: own(chain), split: own(split) }
}

fn inception_a(cin: usize, pool_features: usize) -> Stage {
    Stage::Block(vec![
        branch(None, &[("branch1x1", square(cin, 64, 1, 1, 0))], &[]),
        branch(None, &[("branch5x5_1", square(cin, 48, 1, 1, 0)), ("branch5x5_2", square(48, 64, 5, 1, 2))], &[]),
        branch(
            None,
            &[
                ("branch3x3dbl_1", square(cin, 64, 1, 1, 0)),
                ("branch3x3dbl_2", square(64, 96, 3, 1, 1)),
                ("branch3x3dbl_3", square(96, 96, 3, 1, 1)),
            ],
            &[],
        ),
        branch(Some(AVG_3X3_SAME), &[("branch_pool", square(cin, pool_features, 1, 1, 0))], &[]),
    ])
}

fn inception_b(cin: usize) -> Stage {
    Stage::Block(vec![
        branch(None, &[("branch3x3", square(cin, 384, 3, 2, 0))], &[]),
        branch(
            None,
            &[
                ("branch3x3dbl_1", square(cin, 64, 1, 1, 0)),
                ("branch3x3dbl_2", square(64, 96, 3, 1, 1)),
                ("branch3x3dbl_3", square(96, 96, 3, 2, 0)),
            ],
            &[],
        ),
        branch(Some(MAX_3X3_S2), &[], &[]),
    ])
}

fn inception_c(cin: usize, c7: usize) -> Stage {
    let (row, col) = ([1, 7], [7, 1]);
    Stage::Block(vec![
        branch(None, &[("branch1x1", square(cin, 192, 1, 1, 0))], &[]),
        branch(
            None,
            &[
                ("branch7x7_1", square(cin, c7, 1, 1, 0)),
                ("branch7x7_2", conv(c7, c7, row, 1, [0, 3])),
                ("branch7x7_3", conv(c7, 192, col, 1, [3, 0])),
            ],
            &[],
        ),
        branch(
            None,
            &[
                ("branch7x7dbl_1", square(cin, c7, 1, 1, 0)),
                ("branch7x7dbl_2", conv(c7, c7, col, 1, [3, 0])),
                ("branch7x7dbl_3", conv(c7, c7, row, 1, [0, 3])),
                ("branch7x7dbl_4", conv(c7, c7, col, 1, [3, 0])),
                ("branch7x7dbl_5", conv(c7, 192, row, 1, [0, 3])),
            ],
            &[],
        ),
        branch(Some(AVG_3X3_SAME), &[("branch_pool", square(cin, 192, 1, 1, 0))], &[]),
    ])
}

fn inception_d(cin: usize) -> Stage {
    Stage::Block(vec![
        branch(None, &[("branch3x3_1", square(cin, 192, 1, 1, 0)), ("branch3x3_2", square(192, 320, 3, 2, 0))], &[]),
        branch(
            None,
            &[
                ("branch7x7x3_1", square(cin, 192, 1, 1, 0)),
                ("branch7x7x3_2", conv(192, 192, [1, 7], 1, [0, 3])),
                ("branch7x7x3_3", conv(192, 192, [7, 1], 1, [3, 0])),
                ("branch7x7x3_4", square(192, 192, 3, 2, 0)),
            ],
            &[],
        ),
        branch(Some(MAX_3X3_S2), &[], &[]),
    ])
}

fn inception_e(cin: usize, pool: Pool) -> Stage {
    let pair = |a: &'static str, b: &'static str| {
        [(a, conv(384, 384, [1, 3], 1, [0, 1])), (b, conv(384, 384, [3, 1], 1, [1, 0]))]
    };
    Stage::Block(vec![
        branch(None, &[("branch1x1", square(cin, 320, 1, 1, 0))], &[]),
        branch(None, &[("branch3x3_1", square(cin, 384, 1, 1, 0))], &pair("branch3x3_2a", "branch3x3_2b")),
        branch(
            None,
            &[("branch3x3dbl_1", square(cin, 448, 1, 1, 0)), ("branch3x3dbl_2", square(448, 384, 3, 1, 1))],
            &pair("branch3x3dbl_3a", "branch3x3dbl_3b"),
        ),
        branch(Some(pool), &[("branch_pool", square(cin, 192, 1, 1, 0))], &[]),
    ])
}

/// The network from the 299² input to Mixed_7c (2048 channels at 8²), by module name.
pub fn architecture() -> Vec<(String, Stage)> {
    let stages = vec![
        ("Conv2d_1a_3x3", Stage::Conv(square(3, 32, 3, 2, 0))),
        ("Conv2d_2a_3x3", Stage::Conv(square(32, 32, 3, 1, 0))),
        ("Conv2d_2b_3x3", Stage::Conv(square(32, 64, 3, 1, 1))),
        ("MaxPool_1", Stage::Pool(MAX_3X3_S2)),
        ("Conv2d_3b_1x1", Stage::Conv(square(64, 80, 1, 1, 0))),
        ("Conv2d_4a_3x3", Stage::Conv(square(80, 192, 3, 1, 0))),
        ("MaxPool_2", Stage::Pool(MAX_3X3_S2)),
        ("Mixed_5b", inception_a(192, 32)),
        ("Mixed_5c", inception_a(256, 64)),
        ("Mixed_5d", inception_a(288, 64)),
        ("Mixed_6a", inception_b(288)),
        ("Mixed_6b", inception_c(768, 128)),
        ("Mixed_6c", inception_c(768, 160)),
        ("Mixed_6d", inception_c(768, 160)),
        ("Mixed_6e", inception_c(768, 192)),
        ("Mixed_7a", inception_d(768)),
        ("Mixed_7b", inception_e(1280, AVG_3X3_SAME)),
        ("Mixed_7c", inception_e(2048, MAX_3X3_SAME)),
    ];
    stages.into_iter().map(|(n, s)| (n.to_string(), s)).collect()
}

/// Every `BasicConv2d` of the network by full module name, in order.
pub fn basic_convs() -> Vec<(String, ConvSpec)> {
    let mut out = Vec::new();
    for (name, stage) in architecture() {
        match stage {
            Stage::Conv(spec) => out.push((name, spec)),
            Stage::Pool(_) => {}
            Stage::Block(branches) => {
                for b in branches {
                    out.extend(b.chain.into_iter().chain(b.split).map(|(n, s)| (format!("{name}.{n}"), s)));
                }
            }
        }
    }
    out
}
