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

/// The CPU the calling thread runs on (it may be moved right after), where
/// the CPU tells it cheaply: x86-64 with RDTSCP, whose auxiliary register
/// Linux sets to the CPU's number (and the NUMA node's, above bit 12).
/// `None` elsewhere.
#[inline]
pub fn current_cpu() -> Option<u32> {
    #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
    {
        if has_rdtscp() {
            let mut aux = 0u32;
            // SAFETY: the CPU has RDTSCP (checked just above).
            unsafe { core::arch::x86_64::__rdtscp(&mut aux) };
            return Some(aux & 0xfff);
        }
    }
    None
}

/// The CPU has RDTSCP (CPUID 8000_0001h, EDX bit 27), asked once.
#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn has_rdtscp() -> bool {
    static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *HAS.get_or_init(|| {
        use core::arch::x86_64::{__cpuid, __get_cpuid_max};
        __get_cpuid_max(0x8000_0000).0 >= 0x8000_0001 && __cpuid(0x8000_0001).edx & (1 << 27) != 0
    })
}
