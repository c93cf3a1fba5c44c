//! The one place this crate asks which CPU it runs on. Every SIMD kernel is chosen at run
//! time from these answers (the standard library caches the `cpuid` result), and every
//! kernel has a portable twin that gives the same bytes, so a CPU without them is slower,
//! never different.

/// AVX2: the sgm and census kernels.
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

/// AVX2 and POPCNT: the block matchers' kernels.
pub fn avx2_popcnt() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx2() && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
