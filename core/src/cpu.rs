//! How the library runs on the CPU around third-party SIMD kernels (tract's).
//!
//! - **Kernel choice.** On CPUs that execute 512-bit vector instructions as two 256-bit halves
//!   (AMD Zen 4), tract's AVX-512 matrix kernels are slower than its AVX2 + FMA ones: on the
//!   development machine (AMD EPYC, family 0x19, model 0x11) each M3 network took 6–19 % less time
//!   and the detector 15 % less with AVX-512 taken out of tract's instruction set (measured with
//!   the `TRACT_CPU_ISA` knob: `time_nets` level 1 179 → 152 µs, the face zone 115 → 93 µs;
//!   criterion `m3_per_face` 754 / 839 → 700 / 690 µs, `detect_640x480` 4.06 → 3.46 ms).
//!   [`select_tract_kernels`] does that once per process, before the first network is planned;
//!   every other CPU keeps tract's own choice, and the `TRACT_CPU_ISA` environment variable, when
//!   set, overrides both (tract's knob priority).
//! - **Vector state.** tract's x86-64 matrix kernels (AVX2 / AVX-512 assembly) return with the
//!   upper halves of the vector registers still in use: they end without `vzeroupper`. The rest of
//!   the library is compiled for baseline x86-64 (SSE instruction encodings), and SSE code running
//!   while that state is dirty pays for it on every vector instruction: on the development machine
//!   the M3 per-face time fell from 905 to 569 µs once the state was cleared after each network
//!   run, with the patch sampling and bilateral filter 2–3× faster than in a loop of their own.
//!   Every tract run is therefore followed by `clear_upper_vector_state`.

use std::sync::Once;

/// The `TRACT_CPU_ISA` edit that [`select_tract_kernels`] installs on a CPU, from its CPUID vendor
/// string and family (base + extended); `None` keeps tract's choice.
///
/// AMD family 0x19 is Zen 3 / Zen 4: only Zen 4 has AVX-512, and it splits 512-bit operations into
/// two 256-bit halves. Zen 5 (0x1A) and Intel run them at full width on their server and desktop
/// parts and are left alone (not measured here).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn isa_edit(vendor: &[u8; 12], family: u32, has_avx512f: bool) -> Option<&'static str> {
    (has_avx512f && vendor == b"AuthenticAMD" && family == 0x19).then_some("-avx512f")
}

/// Picks tract's kernels for this CPU (see the module notes): on AMD Zen 4 its AVX-512 kernels are
/// taken out of the instruction set it dispatches to. Call before the first tract network is
/// planned (tract probes the CPU once per process); the library's model loaders
/// (`landmarks::M3`, `detect::FaceDetector`) call it themselves, so only code that plans tract
/// networks on its own (the timing examples) needs to. Idempotent and cheap after the first call.
pub fn select_tract_kernels() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        #[cfg(target_arch = "x86_64")]
        if let Some(edit) = x86::cpu_id().and_then(|(v, f, avx512)| isa_edit(&v, f, avx512)) {
            // A refusal (another component of the process set the knob differently) leaves that
            // setting: the kernels differ in speed and in float rounding only.
            let _ = tract_core::knobs::set_config_global("TRACT_CPU_ISA", edit);
        }
    });
}

/// Whether the CPU's vendor string is AMD's (`None` where CPUID gives none): which kind of 3×3
/// layer products pays differs between vendors (`conv`).
#[cfg(target_arch = "x86_64")]
pub(crate) fn is_amd() -> Option<bool> {
    x86::cpu_id().map(|(vendor, _, _)| &vendor == b"AuthenticAMD")
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    /// CPUID vendor string, family (base + extended, as the vendors define it) and AVX-512F.
    pub(super) fn cpu_id() -> Option<([u8; 12], u32, bool)> {
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

/// Which forms of the library's own kernels run: each kernel has a portable form (plain Rust,
/// the reference its tests hold every other form to) and per-ISA forms (NEON on aarch64, where it
/// is baseline; AVX2 / AVX-512 on x86-64, chosen at run time from the CPU's features).
///
/// `MONOTRACK_KERNELS=portable` in the environment makes every CPU run the portable forms, which
/// on x86-64 are exactly the choices an aarch64 phone makes between this library's kernels (each
/// NEON form gives its portable twin's bits), so the phone's path can be timed and tested on a
/// development machine. tract's matrix kernels stay its own per-ISA ones on every CPU (NEON
/// assembly on phones). Read once per process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KernelPath {
    /// The fastest forms this CPU has (NEON on aarch64, AVX2 / AVX-512 on x86-64).
    Native,
    /// The portable forms only (`MONOTRACK_KERNELS=portable`).
    Portable,
}

impl KernelPath {
    /// `"native"` or `"portable"`, as the CLI's JSON writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            KernelPath::Native => "native",
            KernelPath::Portable => "portable",
        }
    }
}

/// The kernel path of this process (see [`KernelPath`]).
pub fn kernel_path() -> KernelPath {
    static PATH: std::sync::OnceLock<KernelPath> = std::sync::OnceLock::new();
    *PATH.get_or_init(|| kernel_path_from(std::env::var("MONOTRACK_KERNELS").ok().as_deref()))
}

/// [`kernel_path`]'s reading of the `MONOTRACK_KERNELS` value.
fn kernel_path_from(value: Option<&str>) -> KernelPath {
    match value.map(str::trim) {
        Some(v) if v.eq_ignore_ascii_case("portable") => KernelPath::Portable,
        _ => KernelPath::Native,
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
        $crate::cpu::with_avx2_copy!(@emit [$(#[$attr])*] $vis $name $avx2 $s [&$s]
            [$($arg: $ty),*] [$($ret)?] $body);
    };
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident / $avx2:ident (&mut $s:ident $(, $arg:ident: $ty:ty)* $(,)?) $(-> $ret:ty)?
            => $body:ident
    ) => {
        $crate::cpu::with_avx2_copy!(@emit [$(#[$attr])*] $vis $name $avx2 $s [&mut $s]
            [$($arg: $ty),*] [$($ret)?] $body);
    };
    (@emit [$($attr:tt)*] $vis:vis $name:ident $avx2:ident $s:ident [$($recv:tt)+]
        [$($arg:ident: $ty:ty),*] [$($ret:ty)?] $body:ident) => {
        $($attr)*
        $vis fn $name($($recv)+ $(, $arg: $ty)*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            if $crate::cpu::has_avx2_fma() {
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
    use super::*;

    #[test]
    fn only_portable_in_the_environment_selects_the_portable_path() {
        assert_eq!(kernel_path_from(None), KernelPath::Native);
        assert_eq!(kernel_path_from(Some("native")), KernelPath::Native);
        assert_eq!(kernel_path_from(Some("")), KernelPath::Native);
        assert_eq!(kernel_path_from(Some(" Portable ")), KernelPath::Portable);
        assert_eq!(KernelPath::Portable.as_str(), "portable");
        assert!(!cpu_name().is_empty());
    }

    #[test]
    fn only_amd_zen4_with_avx512_loses_tracts_avx512_kernels() {
        assert_eq!(isa_edit(b"AuthenticAMD", 0x19, true), Some("-avx512f"));
        // Zen 3 (same family, no AVX-512), Zen 5, Intel: tract's own choice.
        assert_eq!(isa_edit(b"AuthenticAMD", 0x19, false), None);
        assert_eq!(isa_edit(b"AuthenticAMD", 0x1a, true), None);
        assert_eq!(isa_edit(b"GenuineIntel", 0x6, true), None);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_cpu_id_reads_a_vendor_and_family_and_the_edit_reaches_tract() {
        let (vendor, family, avx512) = x86::cpu_id().expect("CPUID leaf 1");
        assert!(vendor.iter().all(|b| b.is_ascii_graphic()), "{vendor:?}");
        assert!(family >= 6, "family {family:#x}");
        select_tract_kernels();
        use tract_core::tract_linalg::isa::{Isa, native};
        if std::env::var_os("TRACT_CPU_ISA").is_some() {
            return; // the environment overrides the library's choice
        }
        let expected = avx512 && isa_edit(&vendor, family, avx512).is_none();
        assert_eq!(native().has(Isa::X86_64Avx512f), expected, "{:?}", native());
    }
}
