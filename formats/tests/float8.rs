//! safetensors' 8-bit floats (F8_E4M3, F8_E5M2) widened as torch widens them: every byte of
//! each, written by torch 2.15.0 beside its own float32 (tools/make_fp8_fixtures.py).

use vkdiff_formats::{SafeTensors, SourceDtype};

#[test]
fn every_fp8_byte_reads_as_torch_reads_it() {
    let file = SafeTensors::open(&vkdiff_testkit::fixture("fp8/float8.safetensors")).unwrap();
    for (name, dtype) in [("e4m3", SourceDtype::F8E4M3), ("e5m2", SourceDtype::F8E5M2)] {
        assert_eq!(file.entries[name].dtype, dtype, "{name}");
        let (shape, got) = file.values(name).unwrap();
        let (_, want) = file.values(&format!("{name}_f32")).unwrap();
        assert_eq!(shape, [256]);
        for (byte, (g, w)) in got.iter().zip(&want).enumerate() {
            // NaNs by class (torch's payload is its own); every other value to the bit, -0 included.
            let same = if w.is_nan() { g.is_nan() } else { g.to_bits() == w.to_bits() };
            assert!(same, "{name} byte {byte:#04x}: {g} where torch reads {w}");
        }
    }
}
