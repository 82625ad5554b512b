//! `torch.randn` on a CPU generator, bit for bit (torch 2.x on x86-64 with AVX2): MT19937, torch's
//! uniforms, the double-precision Box–Muller of tensors under 16 elements (with its cached second
//! value) and the float32 Cephes Box–Muller of the AVX2 kernel for larger ones.

/// `torch.Generator("cpu")`: the MT19937 engine plus the cached normal of the small-tensor path.
pub struct TorchCpuRng {
    mt: Mt19937,
    cached_normal: Option<f64>,
}

impl TorchCpuRng {
    /// `torch.Generator("cpu").manual_seed(seed)`; only the low 32 bits of the seed reach the engine.
    pub fn new(seed: u64) -> TorchCpuRng {
        TorchCpuRng { mt: Mt19937::new(seed as u32), cached_normal: None }
    }

    /// `torch.randn(n, dtype=float32, generator=g)`; consecutive calls continue the stream as torch's do.
    pub fn randn(&mut self, n: usize) -> Vec<f32> {
        if n < 16 {
            return (0..n).map(|_| self.normal_f64() as f32).collect();
        }
        let mut out: Vec<f32> = (0..n).map(|_| self.uniform_f32()).collect();
        out.chunks_exact_mut(16).for_each(box_muller_16);
        if !n.is_multiple_of(16) {
            // torch redraws 16 fresh uniforms for the last 16 outputs; the leftover ones are dropped.
            let mut tail = [0.0f32; 16];
            tail.iter_mut().for_each(|u| *u = self.uniform_f32());
            box_muller_16(&mut tail);
            out[n - 16..].copy_from_slice(&tail);
        }
        out
    }

    fn uniform_f32(&mut self) -> f32 {
        (self.mt.next_u32() & 0xFF_FFFF) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    fn uniform_f64(&mut self) -> f64 {
        let bits = (u64::from(self.mt.next_u32()) << 32) | u64::from(self.mt.next_u32());
        (bits & ((1u64 << 53) - 1)) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// torch's `normal_distribution<double>`: one Box–Muller pair, the sine half kept for the next call.
    fn normal_f64(&mut self) -> f64 {
        let z = match self.cached_normal.take() {
            Some(z) => z,
            None => {
                let u1 = self.uniform_f64();
                let u2 = self.uniform_f64();
                let r = (-2.0 * (-u2).ln_1p()).sqrt();
                let theta = 2.0 * std::f64::consts::PI * u1;
                self.cached_normal = Some(r * theta.sin());
                r * theta.cos()
            }
        };
        // `z · std + mean` in torch (1 and 0): only turns −0.0 into +0.0.
        z + 0.0
    }
}

/// The AVX2 kernel on one chunk: uniforms `a = u[j]`, `b = u[j + 8]` become `r·cos θ` and `r·sin θ`.
fn box_muller_16(u: &mut [f32]) {
    for j in 0..8 {
        let radius = (-2.0 * log_f32(1.0 - u[j])).sqrt();
        let (sin, cos) = sincos_f32(6.283_185_5 * u[j + 8]);
        // `fma(z, std, mean)` with std 1, mean 0: only turns −0.0 into +0.0.
        u[j] = radius * cos + 0.0;
        u[j + 8] = radius * sin + 0.0;
    }
}

/// Cephes `log256_ps` for a normal positive `x`, with the fused multiply-adds the compiled kernel has.
fn log_f32(x: f32) -> f32 {
    const SQRT_HALF: f32 = 0.707_106_77;
    const POLY: [f32; 8] = [
        -1.151_461e-1,
        1.167_699_84e-1,
        -1.242_014_1e-1,
        1.424_932_3e-1,
        -1.666_805_8e-1,
        2.000_071_4e-1,
        -2.499_999_4e-1,
        3.333_333e-1,
    ];
    let bits = x.to_bits();
    let mut e = ((bits >> 23) as i32 - 127) as f32 + 1.0;
    let m = f32::from_bits((bits & 0x807F_FFFF) | 0x3F00_0000);
    let t = if m < SQRT_HALF {
        e -= 1.0;
        (m - 1.0) + m
    } else {
        m - 1.0
    };
    let z = t * t;
    let mut y = 7.037_683_6e-2f32;
    for p in POLY {
        y = y.mul_add(t, p);
    }
    y *= t;
    // ln 2 enters in two parts, 0.693359375 − 2.12194440e-4, for precision.
    y = y.mul_add(z, e * -2.121_944_4e-4);
    y = (-z).mul_add(0.5, y);
    e.mul_add(0.693_359_4, t + y)
}

/// Cephes `sincos256_ps` (sine, cosine) for `x ≥ 0`, with the compiled kernel's fused multiply-adds.
fn sincos_f32(x: f32) -> (f32, f32) {
    let j = (((x * 1.273_239_5) as i32) + 1) & !1;
    let yj = j as f32;
    let mut r = yj.mul_add(-0.785_156_25, x);
    r = yj.mul_add(-2.418_756_5e-4, r);
    r = yj.mul_add(-3.774_895e-8, r);
    let z = r * r;
    let mut cos_poly = 2.443_315_7e-5f32.mul_add(z, -1.388_731_6e-3);
    cos_poly = cos_poly.mul_add(z, 4.166_664_6e-2);
    cos_poly *= z;
    cos_poly = cos_poly.mul_add(z, -(0.5 * z)) + 1.0;
    let mut sin_poly = (-1.951_529_6e-4f32).mul_add(z, 8.332_161e-3);
    sin_poly = sin_poly.mul_add(z, -1.666_665_5e-1);
    sin_poly *= z;
    sin_poly = sin_poly.mul_add(r, r);
    let (sin, cos) = if j & 2 == 0 { (sin_poly, cos_poly) } else { (cos_poly, sin_poly) };
    let sin = if j & 4 != 0 { -sin } else { sin };
    let cos = if !(j - 2) & 4 != 0 { -cos } else { cos };
    (sin, cos)
}

/// The reference 32-bit Mersenne Twister (same outputs as `std::mt19937`).
struct Mt19937 {
    state: [u32; 624],
    next: usize,
}

impl Mt19937 {
    fn new(seed: u32) -> Mt19937 {
        let mut state = [0u32; 624];
        state[0] = seed;
        for i in 1..624 {
            state[i] = 1_812_433_253u32.wrapping_mul(state[i - 1] ^ (state[i - 1] >> 30)).wrapping_add(i as u32);
        }
        Mt19937 { state, next: 624 }
    }

    fn next_u32(&mut self) -> u32 {
        if self.next == 624 {
            self.twist();
        }
        let mut y = self.state[self.next];
        self.next += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9D2C_5680;
        y ^= (y << 15) & 0xEFC6_0000;
        y ^ (y >> 18)
    }

    fn twist(&mut self) {
        for i in 0..624 {
            let y = (self.state[i] & 0x8000_0000) | (self.state[(i + 1) % 624] & 0x7FFF_FFFF);
            let mag = if y & 1 == 0 { 0 } else { 0x9908_B0DF };
            self.state[i] = self.state[(i + 397) % 624] ^ (y >> 1) ^ mag;
        }
        self.next = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn engine_matches_the_reference_outputs() {
        let mut mt = Mt19937::new(0);
        let first: Vec<u32> = (0..4).map(|_| mt.next_u32()).collect();
        assert_eq!(first, [2357136044, 2546248239, 3071714933, 3626093760]);
        let mut mt = Mt19937::new(42);
        assert_eq!([mt.next_u32(), mt.next_u32()], [1608637542, 3421126067]);
    }

    #[test]
    fn seeds_differing_by_two_to_the_32_give_one_stream() {
        assert_eq!(TorchCpuRng::new(5).randn(40), TorchCpuRng::new((1 << 32) + 5).randn(40));
    }

    #[test]
    fn small_tensors_use_double_box_muller() {
        let got = TorchCpuRng::new(0).randn(4);
        let want = [1.540_996_1f32, -0.293_428_9, -2.178_789_4, 0.568_431_26];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-7, "{got:?}");
        }
    }

    #[test]
    fn latent_sized_draw_matches_the_reference_values() {
        let got = TorchCpuRng::new(0).randn(4 * 128 * 128);
        assert_eq!(got[0].to_bits(), 0xBF90_1B85);
        let sum: f64 = got.iter().map(|&v| f64::from(v)).sum();
        assert!((sum + 243.911_985).abs() < 1e-5, "{sum}");
        let got = TorchCpuRng::new(42).randn(4 * 128 * 128);
        assert_eq!(got[0].to_bits(), 0x3FF6_A529);
        assert!((got[9] - 1.648_723).abs() < 1e-6);
    }
}
