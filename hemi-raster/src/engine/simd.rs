//! Which instruction sets the engine's code is compiled for, and the only
//! way to run it on one.
//!
//! Each path is one list of CPU features. A macro turns each list into
//! both halves of the contract: the `#[target_feature]` attributes of the
//! function that compiles the work for the path, and the run-time test
//! that every one of those features is present. A [`SimdToken`] holds a
//! path that test passed on; its field is private, so detection
//! ([`SimdToken::detect`], [`SimdToken::available`]) is the only way to make
//! one, and [`SimdToken::run`] is the only code that enters a
//! `#[target_feature]` function. The public [`Simd`] stays a plain choice
//! that anyone can name.
//!
//! The work itself ([`Kernel::run`]) is written once, as plain fixed-width
//! loops that the compiler vectorizes, and always inlined into each path's
//! function, so that it is compiled with that path's features. Rust never
//! fuses a multiply and an add on its own and never reorders float
//! arithmetic, so every path computes the same numbers; the tests hold the
//! masks to that bit for bit.

use shadow_core::{Error, Result};

use crate::config::Simd;

/// Work compiled once per SIMD path. Implementations must mark `run`
/// `#[inline(always)]` and keep closures and iterator adaptors out of
/// their hot loops: those could be compiled apart from the path's
/// function, for the baseline instruction set.
pub(crate) trait Kernel {
    type Output;
    fn run(self) -> Self::Output;
}

/// Declares each x86-64 path from one feature list: a module with the list,
/// its detection and the `#[target_feature]` function that runs a
/// [`Kernel`] with exactly those features.
macro_rules! x86_paths {
    ($($(#[$doc:meta])* $module:ident: [$($feature:tt),+ $(,)?];)+) => {
        $(
            $(#[$doc])*
            #[cfg(target_arch = "x86_64")]
            mod $module {
                use super::Kernel;

                /// The features the path is compiled with and detected by.
                #[cfg(test)]
                pub(super) const FEATURES: &[&str] = &[$($feature),+];

                /// Whether the running CPU has every feature of the path.
                pub(super) fn detected() -> bool {
                    true $(&& std::arch::is_x86_feature_detected!($feature))+
                }

                /// Runs `kernel` compiled with the path's features.
                ///
                /// # Safety
                /// The running CPU must have every one of them:
                /// [`detected`] returned true.
                $(#[target_feature(enable = $feature)])+
                pub(super) unsafe fn run<K: Kernel>(kernel: K) -> K::Output {
                    kernel.run()
                }
            }
        )+
    };
}

x86_paths! {
    /// AVX2 and FMA, with the bit instructions the compiled code may use
    /// (a virtual machine can hide BMI from an AVX2 CPU, so they are
    /// detected too).
    avx2: ["avx2", "fma", "bmi1", "bmi2", "popcnt"];
    /// AVX-512 F/BW/DQ/VL, with everything of the AVX2 path.
    avx512: [
        "avx512f", "avx512bw", "avx512dq", "avx512vl", "avx2", "fma", "bmi1", "bmi2", "popcnt",
    ];
}

/// A SIMD path the running CPU was found to support. Only detection makes
/// one (the field is private), so holding one is the proof that
/// [`SimdToken::run`] needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SimdToken {
    path: Path,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Path {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl SimdToken {
    /// Every path this CPU runs, narrowest first: the portable one, then
    /// each x86-64 path whose every feature is detected.
    pub(crate) fn available() -> Vec<SimdToken> {
        let mut paths = vec![Path::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            if avx2::detected() {
                paths.push(Path::Avx2);
            }
            if avx512::detected() {
                paths.push(Path::Avx512);
            }
        }
        paths.into_iter().map(|path| SimdToken { path }).collect()
    }

    /// The path `choice` names on this CPU: [`Simd::Auto`] is the widest
    /// available; an explicit path the CPU lacks is an error naming it.
    pub(crate) fn detect(choice: Simd) -> Result<SimdToken> {
        let available = SimdToken::available();
        let widest = *available.last().expect("the portable path is always there");
        match choice {
            Simd::Auto => Ok(widest),
            choice => available
                .iter()
                .copied()
                .find(|token| token.simd() == choice)
                .ok_or_else(|| {
                    let paths: Vec<Simd> = available.iter().map(|t| t.simd()).collect();
                    Error::config(
                        "hemi-raster",
                        format!(
                            "the {choice:?} path was asked for, but this CPU only runs {paths:?}"
                        ),
                    )
                }),
        }
    }

    /// The path, as the user names it.
    pub(crate) fn simd(self) -> Simd {
        match self.path {
            Path::Portable => Simd::Portable,
            #[cfg(target_arch = "x86_64")]
            Path::Avx2 => Simd::Avx2,
            #[cfg(target_arch = "x86_64")]
            Path::Avx512 => Simd::Avx512,
        }
    }

    /// Runs `kernel` compiled for this path.
    #[inline]
    pub(crate) fn run<K: Kernel>(self, kernel: K) -> K::Output {
        match self.path {
            Path::Portable => kernel.run(),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: a token holds `Path::Avx2` only if `avx2::detected()`
            // found every feature `avx2::run` is compiled with.
            Path::Avx2 => unsafe { avx2::run(kernel) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: a token holds `Path::Avx512` only if
            // `avx512::detected()` found every feature `avx512::run` is
            // compiled with.
            Path::Avx512 => unsafe { avx512::run(kernel) },
        }
    }
}

impl Simd {
    /// The path this CPU can run: `Auto` becomes the widest available; an
    /// explicit path the CPU lacks is an error naming it.
    pub fn resolve(self) -> Result<Simd> {
        SimdToken::detect(self).map(SimdToken::simd)
    }

    /// The paths this CPU runs, narrowest first.
    pub fn available() -> Vec<Simd> {
        SimdToken::available()
            .into_iter()
            .map(SimdToken::simd)
            .collect()
    }
}

/// Asks for the cache lines of `value`; reads nothing and never faults.
#[inline(always)]
pub(crate) fn prefetch<T>(value: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = value.as_ptr().cast::<i8>();
        for offset in (0..size_of_val(value)).step_by(64) {
            // SAFETY: a prefetch is a hint: it reads nothing and never
            // faults, whatever the address; SSE, which it needs, is part of
            // the x86-64 baseline.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_resolve_to_what_the_cpu_has() {
        let available = Simd::available();
        assert_eq!(available[0], Simd::Portable);
        assert_eq!(Simd::Auto.resolve().unwrap(), *available.last().unwrap());
        assert_eq!(Simd::Portable.resolve().unwrap(), Simd::Portable);
        for s in [Simd::Avx2, Simd::Avx512] {
            assert_eq!(s.resolve().is_ok(), available.contains(&s));
        }
        let e = SimdToken::available();
        assert_eq!(e.len(), available.len());
    }

    /// The wider path's list holds the narrower one's, so that a CPU
    /// detected for AVX-512 is detected for AVX2 too.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn feature_lists_nest() {
        for f in avx2::FEATURES {
            assert!(avx512::FEATURES.contains(f), "{f}");
        }
        if avx512::detected() {
            assert!(avx2::detected());
        }
    }
}
