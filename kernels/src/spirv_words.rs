// Walks SPIR-V words; included by build.rs (the build's rewrites) and by the crate (the
// rewrites made at pipeline creation).

/// The instructions of a module, after its header.
fn instructions(words: &[u32]) -> Result<Vec<&[u32]>, String> {
    let (mut out, mut at) = (Vec::new(), 5);
    while at < words.len() {
        let count = (words[at] >> 16) as usize;
        out.push(words.get(at..at + count).filter(|_| count > 0).ok_or("truncated SPIR-V instruction")?);
        at += count;
    }
    Ok(out)
}
