/// `words` (a kernel's SPIR-V) with each subgroup shuffle from a constant lane, which is how naga
/// writes WGSL's `subgroupBroadcast`, written as the broadcast it is, and the capability a
/// broadcast needs. Mesa's lavapipe after 22 builds a shuffle as one `vpermd` at 8 lanes of 32
/// bits and as a loop over the lanes at 16, which ran Mesa 26.1's 16-lane products at about a
/// third of the speed the broadcast's extract and splat reach (docs/benchmark-log.md,
/// 2026-12-06); Mesa 22 has it the other way round (its shuffle from a constant lane is one
/// vector shuffle).
pub fn constant_broadcasts(words: &[u32]) -> Vec<u32> {
    const OP_CAPABILITY: u32 = 17;
    const OP_CONSTANT: u32 = 43;
    const OP_BROADCAST: u32 = 337;
    const OP_SHUFFLE: u32 = 345;
    const GROUP_NON_UNIFORM_BALLOT: u32 = 64;
    // A malformed module is the driver's to refuse, as it stands.
    let Ok(insts) = instructions(words) else { return words.to_vec() };
    let op = |inst: &[u32]| inst[0] & 0xffff;
    let constants: std::collections::HashSet<u32> =
        insts.iter().filter(|i| op(i) == OP_CONSTANT && i.len() > 2).map(|i| i[2]).collect();
    // OpGroupNonUniformShuffle: result type, result, scope, value, lane.
    let from_constant_lane = |inst: &[u32]| op(inst) == OP_SHUFFLE && inst.len() == 6 && constants.contains(&inst[5]);
    if !insts.iter().any(|i| from_constant_lane(i)) {
        return words.to_vec();
    }
    let ballot = insts.iter().any(|i| op(i) == OP_CAPABILITY && i.get(1) == Some(&GROUP_NON_UNIFORM_BALLOT));
    let mut out = words[..5].to_vec();
    for (n, inst) in insts.iter().enumerate() {
        if from_constant_lane(inst) {
            out.push((inst[0] & 0xffff_0000) | OP_BROADCAST);
            out.extend_from_slice(&inst[1..]);
        } else {
            out.extend_from_slice(inst);
        }
        let last_capability = op(inst) == OP_CAPABILITY && insts.get(n + 1).is_none_or(|next| op(next) != OP_CAPABILITY);
        if last_capability && !ballot {
            out.extend([(2 << 16) | OP_CAPABILITY, GROUP_NON_UNIFORM_BALLOT]);
        }
    }
    out
}

#[cfg(test)]
mod broadcast_tests {
    use super::*;

    /// Opcodes of a module's instructions, in order, and the capabilities it declares.
    fn opcodes(words: &[u32]) -> (Vec<u32>, Vec<u32>) {
        let insts = instructions(words).unwrap();
        let caps = insts.iter().filter(|i| i[0] & 0xffff == 17).map(|i| i[1]).collect();
        (insts.iter().map(|i| i[0] & 0xffff).collect(), caps)
    }

    #[test]
    fn shuffles_from_constant_lanes_become_broadcasts_and_nothing_else_moves() {
        let variant = variants("gemm_sg", Dtype::F32).find(|v| v.param("SG") == Some(16)).expect("a 16-lane GEMM");
        let before = variant.words();
        let after = constant_broadcasts(&before);
        let ((ops_before, caps_before), (ops_after, caps_after)) = (opcodes(&before), opcodes(&after));
        let count = |ops: &[u32], op: u32| ops.iter().filter(|&&o| o == op).count();
        assert!(count(&ops_before, 345) > 0 && count(&ops_before, 337) == 0, "naga writes broadcasts as shuffles");
        assert_eq!(count(&ops_after, 345), 0, "every lane the GEMM broadcasts from is a constant");
        assert_eq!(count(&ops_after, 337), count(&ops_before, 345));
        assert!(!caps_before.contains(&64) && caps_after.contains(&64), "{caps_after:?}");
        assert_eq!(after.len(), before.len() + 2, "one capability added, every instruction kept at its length");
        // Without the added capability, only the shuffles' first words differ, by their opcode.
        let cap_end = 5 + 2 * caps_before.len();
        let kept: Vec<u32> = after[..cap_end].iter().chain(&after[cap_end + 2..]).copied().collect();
        let renamed: Vec<u32> =
            before.iter().map(|&w| if w & 0xffff == 345 && w >> 16 == 6 { (w & 0xffff_0000) | 337 } else { w }).collect();
        assert_eq!(kept, renamed);
        assert_eq!(constant_broadcasts(&after), after, "a second pass changes nothing");
    }

    #[test]
    fn a_truncated_module_is_left_to_the_driver() {
        let mut words = variants("gemm_sg", Dtype::F32).find(|v| v.param("SG") == Some(16)).expect("a 16-lane GEMM").words();
        words.push((10 << 16) | 43); // an OpConstant of ten words, its last nine missing
        assert_eq!(constant_broadcasts(&words), words);
    }

    #[test]
    fn kernels_without_shuffles_are_unchanged() {
        let variant = variants("gemm_tiled", Dtype::F32).next().expect("a tiled GEMM");
        assert_eq!(constant_broadcasts(&variant.words()), variant.words());
    }
}
