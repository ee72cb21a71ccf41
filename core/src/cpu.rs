//! CPU state the library restores after third-party SIMD kernels.
//!
//! tract's x86-64 matrix kernels (AVX2 / AVX-512 assembly) return with the upper halves of the
//! vector registers still in use: they end without `vzeroupper`. The rest of the library is
//! compiled for baseline x86-64 (SSE instruction encodings), and SSE code running while that state
//! is dirty pays for it on every vector instruction: on the development machine (AMD EPYC,
//! AVX-512) the M3 per-face time fell from 905 to 569 µs once the state was cleared after each
//! network run, with the patch sampling and bilateral filter 2–3× faster than in a loop of their
//! own. Every tract run is therefore followed by [`clear_upper_vector_state`].

/// Clears the upper halves of the vector registers (`vzeroupper`) when the CPU has AVX; nothing
/// elsewhere (no other architecture has the penalty).
#[inline]
pub(crate) fn clear_upper_vector_state() {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        #[allow(unsafe_code)]
        // SAFETY: `vzeroupper` needs AVX, which the CPU was just checked to have; it changes no
        // register the compiler relies on across the call (the ABI treats the upper halves as
        // clobbered by any call).
        unsafe {
            std::arch::x86_64::_mm256_zeroupper();
        }
    }
}
