//! The float type the rasterizer is generic over: `f32` for speed, `f64` for gradient checks
//! against finite differences (the same code path runs in both).

use num_traits::Float;

/// A float usable by the rasterizer kernels.
pub trait Real: Float + Default + Send + Sync + std::fmt::Debug + std::iter::Sum + 'static {
    /// `e^x` for the blending kernel. For `f32` a branch-free polynomial that vectorises
    /// (relative error ≈ 2 ulp); for `f64` the exact library function.
    fn exp_blend<M: MulAdd>(self) -> Self;

    /// A constant (or any `f64`) in this precision; a plain `as` cast, so it folds at compile time.
    fn c(x: f64) -> Self;

    fn to_f64_lossy(self) -> f64 {
        self.to_f64().unwrap_or(f64::NAN)
    }
}

impl Real for f32 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x as f32
    }

    #[inline(always)]
    fn exp_blend<M: MulAdd>(self) -> Self {
        exp_f32::<M>(self)
    }
}

impl Real for f64 {
    #[inline(always)]
    fn c(x: f64) -> Self {
        x
    }

    #[inline(always)]
    fn exp_blend<M: MulAdd>(self) -> Self {
        self.exp()
    }
}

/// How kernels evaluate `a·b + c`: [`Fused`] (one rounding, an FMA instruction) in code compiled
/// for FMA-capable CPUs, [`Unfused`] (multiply, then add) otherwise — `mul_add` without the
/// instruction would be a slow library call.
pub trait MulAdd: Copy + Send + Sync + 'static {
    fn madd<F: Real>(a: F, b: F, c: F) -> F;
}

#[derive(Clone, Copy, Debug)]
pub struct Fused;

#[derive(Clone, Copy, Debug)]
pub struct Unfused;

impl MulAdd for Fused {
    #[inline(always)]
    fn madd<F: Real>(a: F, b: F, c: F) -> F {
        a.mul_add(b, c)
    }
}

impl MulAdd for Unfused {
    #[inline(always)]
    fn madd<F: Real>(a: F, b: F, c: F) -> F {
        a * b + c
    }
}

/// `e^x` in `f32` without a library call, so loops that use it auto-vectorise.
///
/// Range reduction `x = n ln 2 + r`, `|r| ≤ ln 2 / 2`, with `ln 2` split in two parts
/// (Cody–Waite), a degree-6 Taylor polynomial for `e^r` (truncation error < 1.3e-7 relative)
/// and `2^n` built from the exponent bits. Inputs are clamped to `[-87, 88]`, where the result is a
/// normal float.
#[inline(always)]
pub fn exp_f32<M: MulAdd>(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Adding and subtracting 1.5·2^23 rounds to the nearest integer without a library call.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let n = M::madd(x, LOG2E, ROUND) - ROUND;
    let r = M::madd(n, -LN2_LO, M::madd(n, -LN2_HI, x));
    // Estrin's scheme: the same polynomial with a short dependency chain.
    let r2 = r * r;
    let r4 = r2 * r2;
    let p01 = 1.0 + r;
    let p23 = M::madd(r, 1.0 / 6.0, 0.5);
    let p45 = M::madd(r, 1.0 / 120.0, 1.0 / 24.0);
    let p = M::madd(r4, M::madd(r2, 1.0 / 720.0, p45), M::madd(r2, p23, p01));
    // 2^n from the exponent bits, without a float→int conversion (which would not vectorise):
    // n + 127 + 1.5·2^23 holds n + 127 in its low mantissa bits; shifting by 23 moves them into
    // the exponent field and drops the rest.
    let scale = f32::from_bits((n + (ROUND + 127.0)).to_bits() << 23);
    p * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_exp_matches_std_exp() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x < 88.0 {
            let a = exp_f32::<Unfused>(x) as f64;
            let fused = exp_f32::<Fused>(x) as f64;
            let b = (x as f64).exp();
            worst = worst.max(((a - b) / b).abs()).max(((fused - b) / b).abs());
            x += 0.001_7;
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
        assert_eq!(exp_f32::<Unfused>(0.0), 1.0);
    }
}
