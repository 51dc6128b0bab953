//! Running lane loops on the widest vector instructions the CPU has.
//!
//! The batched forward model is a sequence of branch-free loops over many independent
//! problems (arc ends, occlusion problems, diffuse arcs, lobe nodes). Compiled for baseline
//! x86-64 they use two-lane SSE2; inside a function compiled for AVX-512 (or AVX2 with FMA)
//! the same loops use eight (or four) lanes. [`on_widest_lanes`] picks at run time
//! (`is_x86_feature_detected`, cached by std), so one binary runs everywhere.

/// Calls `f(fused)` from inside a function compiled for AVX-512 (else AVX2 and FMA) when the CPU
/// has it, so that the lane loops inlined into `f` are compiled for those instructions; on other
/// CPUs, calls it as it is. `fused` says whether fused multiply-add is available (it is wherever
/// a vector path is taken): callers pick their multiply-add with it.
///
/// Loops meant to benefit must be `#[inline(always)]` (or small enough to be inlined), so that
/// they are compiled inside the feature-enabled function.
#[inline(always)]
pub fn on_widest_lanes<R>(f: impl FnOnce(bool) -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,avx512dq,avx2,fma")]
        fn avx512<R>(f: impl FnOnce(bool) -> R) -> R {
            f(true)
        }
        #[target_feature(enable = "avx2,fma")]
        fn avx2<R>(f: impl FnOnce(bool) -> R) -> R {
            f(true)
        }
        if std::is_x86_feature_detected!("avx512f")
            && std::is_x86_feature_detected!("avx512dq")
            && std::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has the features the function is compiled for.
            return unsafe { avx512(f) };
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU has the features the function is compiled for.
            return unsafe { avx2(f) };
        }
    }
    f(false)
}
