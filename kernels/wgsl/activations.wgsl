// Scalar activation functions in f32, as PyTorch defines them.
fn silu(x: f32) -> f32 {
    return x / (1.0 + exp(-x));
}

// erf in f32: its Taylor series near 0 (where 1 - erfc loses relative accuracy), and elsewhere
// the classic Chebyshev fit of erfc with fractional error below 1.2e-7.
fn erf_approx(x: f32) -> f32 {
    let a = abs(x);
    if a < 0.5 {
        let z = x * x;
        return x * (1.128379167 + z * (-0.3761263890 + z * (0.1128379167 + z * (-0.02686617064 + z * (0.005223977625 - z * 0.0008548327)))));
    }
    let t = 1.0 / (1.0 + 0.5 * a);
    let y = t * exp(-a * a - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (-0.18628806
        + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))));
    return sign(x) * (1.0 - y);
}

fn gelu_erf(x: f32) -> f32 {
    return 0.5 * x * (1.0 + erf_approx(x * 0.70710678118654752));
}

fn gelu_tanh(x: f32) -> f32 {
    let u = 0.79788456080286536 * (x + 0.044715 * x * x * x);
    // tanh via exp, clamped so large |u| cannot overflow.
    let e = exp(-2.0 * abs(clamp(u, -15.0, 15.0)));
    return 0.5 * x * (1.0 + sign(u) * (1.0 - e) / (1.0 + e));
}

fn quick_gelu(x: f32) -> f32 {
    return x / (1.0 + exp(-1.702 * x));
}
