//! What the kernels need to know of the CPU: its identity (CPUID on x86-64), which of the
//! x86-64 forms run ([`has_avx2_fma`], which also honours the portable path), the upper vector
//! state tract's x86-64 assembly leaves dirty, and the AVX2 byte loads and stores the pixel kernels
//! share. Every `std::arch` use of the library outside the kernels' own folders is here.

#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
use super::{KernelPath, kernel_path};

/// Whether the CPU's vendor string is AMD's (`None` where CPUID gives none): which kind of 3×3
/// layer products pays differs between vendors (`conv`).
#[cfg(target_arch = "x86_64")]
pub(crate) fn is_amd() -> Option<bool> {
    x86::cpu_id().map(|(vendor, _, _)| &vendor == b"AuthenticAMD")
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
    /// CPUID vendor string, family (base + extended, as the vendors define it) and AVX-512F.
    pub(crate) fn cpu_id() -> Option<([u8; 12], u32, bool)> {
        use std::arch::x86_64::__cpuid;
        #[allow(unused_unsafe, unsafe_code)]
        // SAFETY: CPUID exists on every x86-64 CPU; leaves 0 and 1 are always defined.
        let (l0, l1) = unsafe { (__cpuid(0), __cpuid(1)) };
        if l0.eax < 1 {
            return None;
        }
        let mut vendor = [0u8; 12];
        vendor[..4].copy_from_slice(&l0.ebx.to_le_bytes());
        vendor[4..8].copy_from_slice(&l0.edx.to_le_bytes());
        vendor[8..].copy_from_slice(&l0.ecx.to_le_bytes());
        let base = (l1.eax >> 8) & 0xf;
        let family = if base == 0xf {
            base + ((l1.eax >> 20) & 0xff)
        } else {
            base
        };
        Some((
            vendor,
            family,
            std::arch::is_x86_feature_detected!("avx512f"),
        ))
    }

    /// The CPUID brand string (leaves 0x8000_0002–4), trimmed; `None` where the CPU has none.
    pub(super) fn brand() -> Option<String> {
        use std::arch::x86_64::__cpuid;
        #[allow(unused_unsafe, unsafe_code)]
        // SAFETY: CPUID exists on every x86-64 CPU; leaf 0x8000_0000 is always defined and says
        // whether the brand leaves are.
        let top = unsafe { __cpuid(0x8000_0000) }.eax;
        if top < 0x8000_0004 {
            return None;
        }
        let mut bytes = Vec::with_capacity(48);
        for leaf in 0x8000_0002..=0x8000_0004u32 {
            #[allow(unused_unsafe, unsafe_code)]
            // SAFETY: the leaf is at most the highest extended leaf the CPU reported.
            let r = unsafe { __cpuid(leaf) };
            for word in [r.eax, r.ebx, r.ecx, r.edx] {
                bytes.extend_from_slice(&word.to_le_bytes());
            }
        }
        let brand = String::from_utf8_lossy(&bytes)
            .trim_matches(|c: char| c == '\0' || c.is_whitespace())
            .to_string();
        (!brand.is_empty()).then_some(brand)
    }
}

/// Whether the NEON forms run: on aarch64 unless [`KernelPath::Portable`] was asked for.
#[cfg(target_arch = "aarch64")]
#[inline]
pub(crate) fn neon() -> bool {
    kernel_path() == KernelPath::Native
}

/// The CPU this process runs on, in words, for benchmark reports: the CPUID brand string on
/// x86-64, `/proc/cpuinfo`'s model or implementer / part on Linux elsewhere, else the
/// architecture's name.
pub fn cpu_name() -> String {
    #[cfg(target_arch = "x86_64")]
    if let Some(brand) = x86::brand() {
        return brand;
    }
    if let Ok(info) = std::fs::read_to_string("/proc/cpuinfo") {
        let field = |key: &str| {
            info.lines()
                .filter_map(|l| l.split_once(':'))
                .find(|(k, _)| k.trim() == key)
                .map(|(_, v)| v.trim().to_string())
        };
        if let Some(model) = field("model name").or_else(|| field("Hardware")) {
            return model;
        }
        if let (Some(implementer), Some(part)) = (field("CPU implementer"), field("CPU part")) {
            return format!(
                "{} (implementer {implementer}, part {part})",
                std::env::consts::ARCH
            );
        }
    }
    std::env::consts::ARCH.to_string()
}

/// Whether the CPU has AVX2 and FMA and the native path runs: the hot pixel kernels then run a
/// copy of themselves compiled for them (the library is otherwise built for baseline x86-64).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && kernel_path() == KernelPath::Native
}

/// The x86-64 features beyond AVX2 + FMA that the native path's forms use, each `false` on the
/// portable path or where [`has_avx2_fma`] is (every form that uses them also uses AVX2 + FMA).
#[cfg(target_arch = "x86_64")]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Avx512 {
    /// AVX-512F.
    F,
    /// AVX-512F, BW and VL.
    BwVl,
    /// AVX-512F, VL and BF16.
    Bf16,
    /// AVX-512F, BW and VNNI.
    Vnni,
}

/// Whether the native path runs the AVX-512 forms that need `features`.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx512(features: Avx512) -> bool {
    use std::arch::is_x86_feature_detected as has;
    has_avx2_fma()
        && has!("avx512f")
        && match features {
            Avx512::F => true,
            Avx512::BwVl => has!("avx512bw") && has!("avx512vl"),
            Avx512::Bf16 => has!("avx512vl") && has!("avx512bf16"),
            Avx512::Vnni => has!("avx512bw") && has!("avx512vnni"),
        }
}

/// Which form a pixel kernel with AVX2 and AVX-512F forms beside its portable one runs (the
/// patch warps and the bilateral filter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PixelForm {
    /// Plain Rust: the reference.
    Portable,
    /// AVX2 + FMA.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512F, AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl PixelForm {
    /// The widest form this CPU runs on the process's kernel path (the portable one on aarch64
    /// and on the portable path).
    pub(crate) fn for_this_cpu() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if has_avx512(Avx512::F) {
                return PixelForm::Avx512;
            }
            if has_avx2_fma() {
                return PixelForm::Avx2;
            }
        }
        PixelForm::Portable
    }

    /// Every form this CPU runs on the process's kernel path (for the tests).
    #[cfg(test)]
    pub(crate) fn all() -> Vec<Self> {
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))]
        let mut forms = vec![PixelForm::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if has_avx2_fma() {
                forms.push(PixelForm::Avx2);
            }
            if has_avx512(Avx512::F) {
                forms.push(PixelForm::Avx512);
            }
        }
        forms
    }
}

/// Whether the CPU has FMA, on either path (x86-64's portable path runs the NEON forms' 128-bit
/// twins, which need it).
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_fma() -> bool {
    std::arch::is_x86_feature_detected!("fma")
}

/// For the tests of the AVX2 paths, which carry
/// `#[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]` (build.rs):
/// fails when they are run where those kernels do not (the portable path: test-all.sh's portable
/// pass leaves them out with `--skip`).
#[cfg(test)]
pub(crate) fn assert_avx2_fma_path() {
    #[cfg(target_arch = "x86_64")]
    let has = has_avx2_fma();
    #[cfg(not(target_arch = "x86_64"))]
    let has = false;
    assert!(
        has,
        "the AVX2 + FMA kernels do not run here (no such CPU, or MONOTRACK_KERNELS=portable)"
    );
}

/// Defines a method that runs `$body` — an `#[inline(always)]` method of the same signature —
/// either as compiled for baseline x86-64 or, where the CPU has AVX2 and FMA, through `$avx2`: a
/// copy of it compiled for those features, which the macro also defines. Rust never contracts
/// `a * b + c` into a fused multiply-add on its own, so the copy does the same operations on wider
/// vectors and gives the same results. Off x86-64 the method runs `$body`.
///
/// ```ignore
/// with_avx2_copy! {
///     /// Docs of the method.
///     pub fn apply / apply_avx2 (&mut self, src: &[u8], dst: &mut [u8]) => apply_body
/// }
/// ```
macro_rules! with_avx2_copy {
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident / $avx2:ident (&$s:ident $(, $arg:ident: $ty:ty)* $(,)?) $(-> $ret:ty)?
            => $body:ident
    ) => {
        $crate::kernels::cpu::with_avx2_copy!(@emit [$(#[$attr])*] $vis $name $avx2 $s [&$s]
            [$($arg: $ty),*] [$($ret)?] $body);
    };
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident / $avx2:ident (&mut $s:ident $(, $arg:ident: $ty:ty)* $(,)?) $(-> $ret:ty)?
            => $body:ident
    ) => {
        $crate::kernels::cpu::with_avx2_copy!(@emit [$(#[$attr])*] $vis $name $avx2 $s [&mut $s]
            [$($arg: $ty),*] [$($ret)?] $body);
    };
    (@emit [$($attr:tt)*] $vis:vis $name:ident $avx2:ident $s:ident [$($recv:tt)+]
        [$($arg:ident: $ty:ty),*] [$($ret:ty)?] $body:ident) => {
        $($attr)*
        $vis fn $name($($recv)+ $(, $arg: $ty)*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            if $crate::kernels::cpu::has_avx2_fma() {
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX2 and FMA, the features the copy is compiled for.
                return unsafe { $s.$avx2($($arg),*) };
            }
            $s.$body($($arg),*)
        }

        /// The body compiled for AVX2 + FMA (`cpu::with_avx2_copy`).
        // The copy repeats the method's arguments; clippy judges their number at the method.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        #[allow(clippy::too_many_arguments)]
        fn $avx2($($recv)+ $(, $arg: $ty)*) $(-> $ret)? {
            $s.$body($($arg),*)
        }
    };
}
pub(crate) use with_avx2_copy;

/// Byte loads and stores the hand-written AVX2 pixel kernels share (their unsafe pointer access in
/// one place, behind slices whose length is checked).
#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2 {
    use std::arch::x86_64::{
        __m128i, __m256i, _mm_loadl_epi64, _mm_packus_epi16, _mm_packus_epi32, _mm_storel_epi64,
        _mm256_castsi256_si128, _mm256_cvtepu8_epi32, _mm256_extracti128_si256,
    };

    /// The first eight bytes of `bytes`, zero-extended to eight i32 lanes.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) fn load_u8x8(bytes: &[u8]) -> __m256i {
        let bytes: &[u8; 8] = bytes[..8].try_into().expect("eight bytes");
        #[allow(unsafe_code)]
        // SAFETY: `bytes` holds the eight bytes read (unaligned loads are allowed).
        _mm256_cvtepu8_epi32(unsafe { _mm_loadl_epi64(bytes.as_ptr().cast::<__m128i>()) })
    }

    /// Eight i32 lanes into the first eight bytes of `dst`, saturated to 0..=255.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) fn store_u8x8(v: __m256i, dst: &mut [u8]) {
        let dst: &mut [u8; 8] = (&mut dst[..8]).try_into().expect("eight bytes");
        let words = _mm_packus_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
        #[allow(unsafe_code)]
        // SAFETY: `dst` holds the eight bytes written (unaligned stores are allowed).
        unsafe {
            _mm_storel_epi64(
                dst.as_mut_ptr().cast::<__m128i>(),
                _mm_packus_epi16(words, words),
            )
        };
    }
}

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

#[cfg(test)]
mod tests {
    #[test]
    fn the_cpu_has_a_name() {
        assert!(!super::cpu_name().is_empty());
    }
}
