//! The CPU's wide vector instructions (AVX2, 256-bit registers) for the solvers' hottest kernels,
//! chosen at run time: the binary stays portable (the baseline x86-64 build uses 128-bit SSE2),
//! and where the CPU has AVX2 the kernels that [`enabled`] gates run a copy of themselves
//! compiled for it (`#[target_feature]`).
//!
//! Both copies compute the same numbers to the bit: Rust never fuses a multiplication and an
//! addition on its own (and FMA is not enabled) nor reorders floating-point operations, so only
//! the width of the instructions differs, never a rounding. `tests/wide_vectors.rs` checks it on
//! every scenario; [`set_enabled`] exists for that check and for timing the difference.

use std::sync::atomic::{AtomicU8, Ordering};

const UNKNOWN: u8 = 0;
const OFF: u8 = 1;
const ON: u8 = 2;

static STATE: AtomicU8 = AtomicU8::new(UNKNOWN);

/// Whether this CPU runs AVX2.
pub fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the gated kernels run their AVX2 copies: wherever the CPU has AVX2, unless
/// [`set_enabled`] forbade them.
#[inline]
pub fn enabled() -> bool {
    match STATE.load(Ordering::Relaxed) {
        ON => true,
        OFF => false,
        _ => {
            let on = available();
            STATE.store(if on { ON } else { OFF }, Ordering::Relaxed);
            on
        }
    }
}

/// Allows (the default where available) or forbids the AVX2 copies, for the whole process.
/// Allowing them on a CPU without AVX2 keeps the portable kernels.
pub fn set_enabled(on: bool) {
    let state = if on && available() { ON } else { OFF };
    STATE.store(state, Ordering::Relaxed);
}
