//! Which kernel forms this process runs, chosen once: [`KernelPath`] plus, for measurements, a
//! named form of one kernel. The choice comes from [`select`] (the CLI's `--kernels`, a test
//! harness) or else from the `MONOTRACK_KERNELS` environment variable, read here and nowhere else;
//! once a kernel has run, the choice is fixed for the process (kernels keep plans and buffers laid
//! out for the form they picked).

use crate::error::{Error, Result};
use std::sync::OnceLock;

/// Which forms of the library's own kernels run: each kernel has a portable form (plain Rust,
/// the reference its tests hold every other form to) and per-ISA forms (NEON on aarch64, where it
/// is baseline; AVX2 / AVX-512 on x86-64, chosen at run time from the CPU's features).
///
/// [`KernelPath::Portable`] makes every CPU run the portable forms, which on x86-64 are exactly
/// the choices an aarch64 phone makes between this library's kernels (each NEON form gives its
/// portable twin's bits), so the phone's path can be timed and tested on a development machine.
/// tract's matrix kernels stay its own per-ISA ones on every CPU (NEON assembly on phones).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KernelPath {
    /// The fastest forms this CPU has (NEON on aarch64, AVX2 / AVX-512 on x86-64).
    Native,
    /// The portable forms only: the phone's choices on any CPU.
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

/// The whole kernel choice: the path and, optionally, the form one kernel must run where the CPU
/// has it (to time the forms against each other on one machine).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelChoice {
    /// Native or portable.
    pub path: KernelPath,
    /// The networks' 3×3 product form on x86-64's native path: `f32x4` (the phone's 128-bit form),
    /// `avx2`, `bf16` or `vnni` (`None`: the CPU's default). A form the CPU lacks is
    /// ignored.
    pub conv: Option<String>,
    /// The Lucas–Kanade windows' form on x86-64's native path: `avx2` or `avx512`, or `portable`
    /// on any path (`None`: the widest the CPU has). A form the CPU lacks is ignored.
    pub flow: Option<String>,
}

impl KernelChoice {
    /// The native path with every kernel's default form.
    pub const NATIVE: KernelChoice = KernelChoice {
        path: KernelPath::Native,
        conv: None,
        flow: None,
    };

    /// Reads a choice written as `native` or `portable`, optionally followed by `,conv=FORM` and
    /// `,flow=FORM` (for example `native,conv=avx2`; a form alone keeps the native path). An empty
    /// string is the native path.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for a path, kernel or form it does not know.
    pub fn parse(spec: &str) -> Result<Self> {
        let mut choice = KernelChoice::NATIVE;
        let bad = |what: &str| {
            Error::InvalidConfig(format!(
                "kernel choice {spec:?}: {what} (expected native|portable[,conv=f32x4|avx2|bf16|vnni][,flow=portable|avx2|avx512])"
            ))
        };
        for (i, part) in spec.split(',').map(str::trim).enumerate() {
            match (i, part.split_once('=')) {
                (0, None) if part.is_empty() || part.eq_ignore_ascii_case("native") => {}
                (0, None) if part.eq_ignore_ascii_case("portable") => {
                    choice.path = KernelPath::Portable;
                }
                (_, Some(("conv", form))) if ["f32x4", "avx2", "bf16", "vnni"].contains(&form) => {
                    choice.conv = Some(form.to_string());
                }
                (_, Some(("flow", form))) if ["portable", "avx2", "avx512"].contains(&form) => {
                    choice.flow = Some(form.to_string());
                }
                _ => return Err(bad(&format!("unknown part {part:?}"))),
            }
        }
        Ok(choice)
    }
}

impl std::fmt::Display for KernelChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.path.as_str())?;
        if let Some(conv) = &self.conv {
            write!(f, ",conv={conv}")?;
        }
        if let Some(flow) = &self.flow {
            write!(f, ",flow={flow}")?;
        }
        Ok(())
    }
}

static CHOICE: OnceLock<KernelChoice> = OnceLock::new();

/// Fixes the process's kernel choice. Call before the first tracker, detector or network is made;
/// choosing again what was chosen is fine.
///
/// # Errors
/// [`Error::InvalidConfig`] when another choice is already fixed (by an earlier call, or by a
/// kernel that ran and read the environment).
pub fn select(choice: KernelChoice) -> Result<()> {
    let fixed = CHOICE.get_or_init(|| choice.clone());
    if *fixed == choice {
        Ok(())
    } else {
        Err(Error::InvalidConfig(format!(
            "kernel choice {choice} asked for after {fixed} was fixed for this process"
        )))
    }
}

/// The process's kernel choice: the one [`select`] fixed, else `MONOTRACK_KERNELS` from the
/// environment (an unreadable value is the native path, since a kernel cannot fail here).
pub fn choice() -> &'static KernelChoice {
    CHOICE.get_or_init(|| {
        std::env::var("MONOTRACK_KERNELS")
            .ok()
            .and_then(|v| KernelChoice::parse(&v).ok())
            .unwrap_or(KernelChoice::NATIVE)
    })
}

/// The kernel path of this process (see [`KernelPath`]).
pub fn kernel_path() -> KernelPath {
    choice().path
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_choice_reads_its_path_and_forms_and_refuses_what_it_does_not_know() {
        assert_eq!(KernelChoice::parse("").unwrap(), KernelChoice::NATIVE);
        assert_eq!(KernelChoice::parse("native").unwrap(), KernelChoice::NATIVE);
        let portable = KernelChoice::parse(" Portable ").unwrap();
        assert_eq!(portable.path, KernelPath::Portable);
        let forms = KernelChoice::parse("native,conv=avx2,flow=portable").unwrap();
        assert_eq!(forms.conv.as_deref(), Some("avx2"));
        assert_eq!(forms.flow.as_deref(), Some("portable"));
        assert_eq!(forms.to_string(), "native,conv=avx2,flow=portable");
        assert_eq!(KernelChoice::parse(&forms.to_string()).unwrap(), forms);
        // A form alone keeps the native path.
        let alone = KernelChoice::parse("conv=bf16").unwrap();
        assert_eq!(
            (alone.path, alone.conv.as_deref()),
            (KernelPath::Native, Some("bf16"))
        );
        for bad in [
            "fast",
            "native,conv=maddubs",
            "portable,tile=8",
            "native,portable",
        ] {
            assert!(
                matches!(KernelChoice::parse(bad), Err(Error::InvalidConfig(_))),
                "{bad}"
            );
        }
        assert_eq!(KernelPath::Portable.as_str(), "portable");
    }

    #[test]
    fn the_process_choice_is_fixed_once() {
        let current = choice().clone();
        assert!(select(current.clone()).is_ok());
        let other = KernelChoice {
            path: match current.path {
                KernelPath::Native => KernelPath::Portable,
                KernelPath::Portable => KernelPath::Native,
            },
            ..current.clone()
        };
        assert!(matches!(select(other), Err(Error::InvalidConfig(_))));
        assert_eq!(choice(), &current);
    }
}
