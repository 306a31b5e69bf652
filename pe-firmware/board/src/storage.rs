//! The runtime's storage in a static: fixed-capacity vectors (const-initialised, so they
//! sit in `.bss` and the linker checks they fit the RAM), filled in place once at boot with
//! zero records and lent to the runtime.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};

use pe_firmware::runtime::Storage;

use crate::config::*;

static mut BUFFERS: MaybeUninit<BoardStorage> = MaybeUninit::zeroed();
static TAKEN: AtomicBool = AtomicBool::new(false);

/// The storage, filled to capacity; `None` if called twice (or a zero record fails to
/// decode, which would be a bug).
pub fn take() -> Option<Storage<'static, Scalar, Element>> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: TAKEN makes this the only place that ever creates a reference to BUFFERS, and
    // it does so at most once, so the `&'static mut` is unique. All zeros is a valid
    // BoardStorage: every field is a `heapless::Vec`, whose length (an integer) is then 0
    // and whose buffer is `MaybeUninit`.
    let b: &'static mut BoardStorage =
        unsafe { (*core::ptr::addr_of_mut!(BUFFERS)).assume_init_mut() };
    b.fill(&CAPACITIES)
}
