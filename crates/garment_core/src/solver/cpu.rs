//! What the CPU offers the numeric kernels (checked at run time, so one
//! build runs everywhere and a run on one machine is reproducible).

/// The CPU has AVX2 and FMA (x86-64).
#[inline]
pub fn has_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
