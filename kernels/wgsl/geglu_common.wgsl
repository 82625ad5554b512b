// GEGLU's parameters, shared by the one-value (geglu.wgsl) and vec4 (geglu_v4.wgsl) kernels:
// x is [rows, 2F], out[r, f] = x[r, f] · GELU_erf(x[r, F + f]) (diffusers: value first, gate
// second); n and f count the kernel's units (values or vec4s).
struct Params {
    n: u32,
    f: u32,
    groups_x: u32,
}

var<immediate> p: Params;

// Where output unit i's value lies in x (its gate lies p.f further on).
fn value_at(i: u32) -> u32 {
    return (i / p.f) * 2u * p.f + i % p.f;
}
