// Element-wise kernels move four consecutive values per invocation as one vec4 (the runtime
// takes this variant where every count the kernel indexes by is a multiple of 4, and passes the
// counts in units of four); unit_1.wgsl is the one-value variant.
alias U = vec4<S>;

fn widen(u: U) -> vec4<f32> {
    return vec4<f32>(u);
}

fn narrow(v: vec4<f32>) -> U {
    return U(v);
}
