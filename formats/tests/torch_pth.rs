//! `TorchPth` against checkpoints torch itself wrote: tests/fixtures/pth/, made by tools/make_pth_fixtures.py
//! with torch 2.15.0+cu132; expected.safetensors holds each float tensor as torch reads it, converted to f32.

use vkdiff_formats::{Error, SafeTensors, TorchPth};
use vkdiff_testkit::fixture;

/// The dict of zip.pth, zip-proto4.pth and legacy.pth: names and shapes.
const DICT: &[(&str, &[usize])] = &[
    ("base", &[4, 6]),
    ("bf16", &[5]),
    ("broadcast", &[3, 4]),
    ("column", &[4]),
    ("double", &[2, 2]),
    ("empty", &[0, 3]),
    ("half", &[2, 3]),
    ("param", &[2]),
    ("rows", &[2, 6]),
    ("scalar", &[]),
    ("transposed", &[5, 4]),
    ("weight", &[3, 4]),
];

/// module.pth: `Sequential(Conv2d(3, 4, 3), BatchNorm2d(4)).state_dict()`, but for the int64 counter.
const MODULE: &[(&str, &[usize])] = &[
    ("0.bias", &[4]),
    ("0.weight", &[4, 3, 3, 3]),
    ("1.bias", &[4]),
    ("1.running_mean", &[4]),
    ("1.running_var", &[4]),
    ("1.weight", &[4]),
];

fn assert_matches_torch(file: &str, tensors: &[(&str, &[usize])]) {
    let pth = TorchPth::open(&fixture("pth").join(file)).unwrap();
    let expected = SafeTensors::open(&fixture("pth").join("expected.safetensors")).unwrap();
    for &(name, shape) in tensors {
        assert_eq!(pth.shape(name).as_deref(), Some(shape), "{file}: {name}");
        let (got_shape, got) = pth.values(name).unwrap();
        let (want_shape, want) = expected.values(name).unwrap();
        assert_eq!(got_shape, want_shape, "{file}: {name}");
        assert_eq!(
            got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            "{file}: {name}"
        );
    }
}

#[test]
fn dicts_in_every_format_read_as_torch_wrote_them() {
    for file in ["zip.pth", "zip-proto4.pth", "legacy.pth"] {
        assert_eq!(
            TorchPth::open(&fixture("pth").join(file)).unwrap().names(),
            DICT.iter().map(|(n, _)| n.to_string()).collect::<Vec<_>>(),
            "{file}"
        );
        assert_matches_torch(file, DICT);
    }
}

#[test]
fn a_module_state_dict_reads_and_its_int64_counter_is_refused() {
    assert_matches_torch("module.pth", MODULE);
    let pth = TorchPth::open(&fixture("pth").join("module.pth")).unwrap();
    assert_eq!(pth.names().len(), MODULE.len() + 1);
    assert_eq!(pth.shape("1.num_batches_tracked"), Some(vec![]));
    let err = pth.values("1.num_batches_tracked").unwrap_err();
    assert!(matches!(err, Error::Tensor(_)) && err.to_string().contains("int64"), "{err}");
}

#[test]
fn a_missing_tensor_is_a_checkpoint_error() {
    let pth = TorchPth::open(&fixture("pth").join("zip.pth")).unwrap();
    assert_eq!(pth.shape("nope"), None);
    let err = pth.values("nope").unwrap_err();
    assert!(matches!(err, Error::Tensor(_)) && err.to_string().contains("`nope`"), "{err}");
}

#[test]
fn other_files_are_refused_naming_the_file() {
    let err = TorchPth::open(&fixture("pth").join("expected.safetensors")).err().unwrap();
    assert!(matches!(err, Error::Format { .. }) && err.to_string().contains("expected.safetensors"), "{err}");
    assert!(matches!(TorchPth::open(&fixture("pth").join("absent.pth")), Err(Error::Io { .. })));
}
