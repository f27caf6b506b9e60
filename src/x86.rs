//! What the hand-vectorised kernels ask of an x86-64 processor, checked once per process,
//! and the two builds of the widest of them.
//!
//! The kernels are written once, in eight-lane AVX2 and FMA intrinsics. Where the
//! processor also has AVX-512F and AVX-512VL, [`with_wide_registers`] runs the same code
//! compiled with them: the same instructions on the same eight lanes, so the same results
//! bit for bit, but with 32 vector registers instead of 16. A kernel whose working set is
//! wider than 16 registers then spills less: the height-field march (sixteen taps, their
//! weights and two groups of lanes), the slices of the fitted depth (a Legendre
//! recurrence per lane group) and a relight's chunk of pixels (a pixel's two to five
//! transfer vectors dotted with three colour channels of light); the gain is timed in
//! docs/performance-log.md.

/// Whether the processor has AVX2 (once per process): the lanes that need no FMA.
pub static AVX2: std::sync::LazyLock<bool> = std::sync::LazyLock::new(|| is_x86_feature_detected!("avx2"));

/// Whether the processor has AVX2 and FMA (once per process): what every hand-vectorised
/// kernel but [`AVX2`]'s needs.
pub static AVX2_FMA: std::sync::LazyLock<bool> =
    std::sync::LazyLock::new(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"));

/// Whether the processor has AVX-512F and AVX-512VL, besides the AVX2 and FMA every caller
/// checks (once per process).
pub static WIDE_REGISTERS: std::sync::LazyLock<bool> =
    std::sync::LazyLock::new(|| is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl"));

/// Defines `unsafe fn $name`, compiled for AVX2 and FMA, and `unsafe fn $wide`, the same
/// body compiled for AVX-512F and AVX-512VL as well (module doc). The body's helpers are
/// `#[target_feature(enable = "avx2,fma")] #[inline]`, so each build inlines them with its
/// own registers.
macro_rules! with_wide_registers {
    ($(#[$meta:meta])* $vis:vis unsafe fn $name:ident / $wide:ident $($rest:tt)*) => {
        $(#[$meta])*
        #[target_feature(enable = "avx2,fma")]
        $vis unsafe fn $name $($rest)*

        $(#[$meta])*
        #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
        $vis unsafe fn $wide $($rest)*
    };
}
pub(crate) use with_wide_registers;
