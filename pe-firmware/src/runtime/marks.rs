//! Cost marks: with the `cost-marks` feature, calls of [`cost_mark`] bracket the contact
//! evaluation of every step, so that QEMU's insncount plugin (`mark=` the address of
//! `pe_cost_mark`, whose mangled symbol holds that name: the crate forbids `no_mangle`)
//! counts the instructions between them on each board of an emulated array
//! (`scripts/contact-cost.sh`: the contact cost of a board of a partition, which a 1x1x1
//! bench cannot see). Without the feature a mark is nothing, so the firmware measured by
//! `scripts/board-cost.sh` and flashed on a board has none.
//!
//! Marks, in the order every step passes them: 0 before `evaluate_contact`; inside it 2
//! after the positions, 3 after the check step's candidate search (nothing on other steps),
//! 4 after the travel check, 5 after the tool tests; 1 after the pair tests, at its end. A
//! board that owns no contact node passes 2 to 5 at once (it skips the evaluation), so
//! every step gives the plugin six marks.

/// The marker the plugin watches (never inlined, never removed).
#[cfg(feature = "cost-marks")]
#[inline(never)]
pub fn pe_cost_mark(id: u32) {
    core::hint::black_box(id);
}

/// Mark `id` (see the module doc).
#[inline(always)]
pub(super) fn cost_mark(id: u32) {
    #[cfg(feature = "cost-marks")]
    pe_cost_mark(id);
    #[cfg(not(feature = "cost-marks"))]
    let _ = id;
}
