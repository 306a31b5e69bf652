//! Loaded sections outside RAM's `.data` that the start-up code does not initialise
//! (`memory.x`: `.links` and `.rtt` in SRAM1-3): copied from their load image in flash, as
//! cortex-m-rt does for `.data`.

/// Copies the words `[start, end)` from `load`.
///
/// # Safety
/// `start..end` and `load` are a section's bounds and load address from the linker
/// (word-aligned, not overlapping), and nothing reads or references the section yet.
#[cfg(not(feature = "qemu"))]
pub(crate) unsafe fn copy_from_flash(start: *mut u32, end: *mut u32, load: *const u32) {
    let words = (end as usize - start as usize) / 4;
    // SAFETY: the caller's.
    unsafe { core::ptr::copy_nonoverlapping(load, start, words) };
}
