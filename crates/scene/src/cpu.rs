//! What the CPU can run, asked in one place by the kernels that have AVX2 builds (the
//! rasterizer's tiles, SSIM, Semi-Global Matching, the surface MLP) and by the benchmark.
//! `std`'s detection caches its answer, so asking is cheap.

/// Whether the CPU has AVX2.
pub fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the CPU has AVX2 and FMA.
pub fn avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx2() && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the CPU has AVX-512 (foundation and vector-length extensions) besides AVX2 and FMA:
/// 32 vector registers and mask registers for the same 8-wide loops.
pub fn avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx2_fma()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A raw pointer that may cross threads, for parallel loops whose tasks write disjoint
/// elements of one buffer (each user states why in a SAFETY note where it writes).
#[derive(Clone, Copy, Debug)]
pub struct SharedMut<T>(pub *mut T);

// SAFETY: the pointer is only dereferenced by users that guarantee disjoint writes.
unsafe impl<T> Send for SharedMut<T> {}
// SAFETY: as above.
unsafe impl<T> Sync for SharedMut<T> {}

impl<T> SharedMut<T> {
    pub fn get(self) -> *mut T {
        self.0
    }
}
