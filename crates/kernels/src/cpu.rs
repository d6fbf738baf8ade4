//! CPU feature detection and the dispatch between a portable build and an AVX2 + FMA build of the
//! same code.
//!
//! The hot loops of Sublevel (the polynomial kernels here, the Newton / active-set solvers of
//! `sublevel-query`) keep two builds: a portable one, and one compiled for AVX2 and FMA
//! (x86-64-v3) that runs three-operand and fused instructions. [`Avx2Fma`] is the proof that the
//! CPU runs the latter: it is constructed only after the run-time check
//! ([`Avx2Fma::detect`]) or inside code already compiled for those features, so every function
//! that takes one can run AVX2 + FMA code soundly. [`Avx2Fma::run`] compiles a closure's body for
//! AVX2 + FMA: the only `unsafe` call that crates above this one need, kept here.

/// Whether this CPU runs code compiled for AVX2 and FMA (x86-64-v3): the query solvers and the
/// polynomial kernels keep a copy compiled for them and pick it at run time (the check is a
/// cached flag after the first call). Always false off x86-64.
#[inline(always)]
pub fn cpu_has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Proof that the CPU runs AVX2 and FMA. Zero-sized: passing it costs nothing.
///
/// Its constructors are [`Avx2Fma::detect`] (a run-time check) and a constructor compiled with
/// those features (so callable only from code that itself runs only on such a CPU).
#[derive(Clone, Copy, Debug)]
pub struct Avx2Fma(());

impl Avx2Fma {
    /// The proof, when this CPU runs AVX2 and FMA ([`cpu_has_avx2_fma`]); `None` elsewhere.
    #[inline(always)]
    pub fn detect() -> Option<Self> {
        cpu_has_avx2_fma().then_some(Self(()))
    }

    /// The proof, inside code compiled for AVX2 and FMA: a safe call only from a function with
    /// those target features (the compiler checks it), which runs only on such a CPU.
    ///
    /// # Safety
    /// Called from a function without those target features (an `unsafe` call there), the CPU
    /// must run AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub fn enabled() -> Self {
        Self(())
    }

    /// The proof, for the lane types of [`crate::lanes`] whose values were made with one (a lane
    /// value reads its proof back, [`crate::lanes::Lane::cpu`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) fn proven() -> Self {
        Self(())
    }

    /// Runs `f` compiled for AVX2 and FMA: `f` is inlined into a function with those target
    /// features, and with it every `#[inline(always)]` function it calls, so a solver written once
    /// (generic over a `const FMA: bool` that selects fused arithmetic) is compiled whole for
    /// this CPU. Off x86-64 (where no proof exists) it is never reached.
    #[inline(always)]
    pub fn run<R>(self, f: impl FnOnce() -> R) -> R {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: `self` proves the CPU runs AVX2 and FMA, the only requirement of calling a
            // function compiled with those features.
            unsafe { run_avx2_fma(f) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            f()
        }
    }
}

/// `f()` compiled for AVX2 + FMA (see [`Avx2Fma::run`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_avx2_fma<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// Sets this thread's MXCSR DAZ and FTZ bits (x86-64; nothing elsewhere): subnormal inputs read as
/// zero and subnormal results flush to zero. For profiling only (`cold_profile`'s
/// `SUBLEVEL_FLUSH_SUBNORMALS=1`): the answers stay the same, and a difference in time shows that
/// some code path multiplies subnormal numbers, each a microcode assist of about a hundred cycles on
/// Intel cores. Never called by the library.
pub fn flush_subnormals() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: DAZ (bit 6) and FTZ (bit 15) change only how subnormal numbers are rounded; every
    // x86-64 CPU has MXCSR, and this thread's own arithmetic is all that reads it.
    #[allow(deprecated)]
    unsafe {
        use std::arch::x86_64::{_mm_getcsr, _mm_setcsr};
        _mm_setcsr(_mm_getcsr() | 0x8040);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_proof_exists_exactly_where_the_cpu_runs_avx2_and_fma() {
        assert_eq!(Avx2Fma::detect().is_some(), cpu_has_avx2_fma());
        if let Some(cpu) = Avx2Fma::detect() {
            // The closure runs (compiled for AVX2 + FMA) and returns its value: a fused
            // multiply-add of exactly representable numbers.
            assert_eq!(cpu.run(|| 3.0f64.mul_add(2.0, 1.0)), 7.0);
        }
    }
}
