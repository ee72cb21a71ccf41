//! How the engine runs tract around its own kernels.
//!
//! - **tract's kernel choice.** On CPUs that execute 512-bit vector instructions as two 256-bit
//!   halves (AMD Zen 4), tract's AVX-512 matrix kernels are slower than its AVX2 + FMA ones
//!   (`BENCHMARKS.md`), so [`select_tract_kernels`] takes AVX-512 out of tract's instruction set
//!   there, once per process, before the first network is planned; every other CPU keeps tract's
//!   own choice, and the `TRACT_CPU_ISA` environment variable, when set, overrides both (tract's
//!   knob priority).
//! - **Vector state.** tract's x86-64 matrix kernels (AVX2 / AVX-512 assembly) return with the
//!   upper halves of the vector registers still in use: they end without `vzeroupper`. The rest of
//!   the library is compiled for baseline x86-64 (SSE instruction encodings), and SSE code running
//!   while that state is dirty pays for it on every vector instruction, so every tract run is
//!   followed by [`clear_upper_vector_state`].
//!
//! tract runs single-threaded unless its `multithread-mm` feature is enabled and an executor is
//! installed; the core enables neither, so each network runs on the calling thread.

use std::sync::Once;

pub(crate) use crate::kernels::cpu::clear_upper_vector_state;

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
        if let Some(edit) =
            crate::kernels::cpu::x86::cpu_id().and_then(|(v, f, avx512)| isa_edit(&v, f, avx512))
        {
            // A refusal (another component of the process set the knob differently) leaves that
            // setting: the kernels differ in speed and in float rounding only.
            let _ = tract_core::knobs::set_config_global("TRACT_CPU_ISA", edit);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let (vendor, family, avx512) = crate::kernels::cpu::x86::cpu_id().expect("CPUID leaf 1");
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
