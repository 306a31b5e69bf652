//! The runtime's storage in statics: fixed-capacity vectors (const-initialised, so they sit
//! in `.bss` and the linker checks they fit the RAM), filled once at boot with zero records
//! and lent to the runtime as slices.

use core::sync::atomic::{AtomicBool, Ordering};

use heapless::Vec;
use pe_firmware::image::{LoadRecord, NodeRecord, PathPoint, RecvEntry};
use pe_firmware::physics::{MaterialLaw, Real};
use pe_firmware::runtime::Storage;
use serde::de::DeserializeOwned;

use crate::config::*;

pub struct Buffers {
    laws: Vec<MaterialLaw<Scalar>, MATERIALS>,
    elements: Vec<Element, ELEMENTS>,
    nodes: Vec<NodeRecord<Scalar>, NODES>,
    ext_stage: Vec<u8, NODES>,
    u: Vec<[Scalar; 3], NODES>,
    u_prev: Vec<[Scalar; 3], NODES>,
    force: Vec<[Scalar; 3], NODES>,
    sends: Vec<u16, EXCHANGE>,
    recvs: Vec<RecvEntry, EXCHANGE>,
    path_points: Vec<PathPoint, PATH_POINTS>,
    loads: Vec<LoadRecord, LOADS>,
}

impl Buffers {
    const fn new() -> Self {
        Buffers {
            laws: Vec::new(),
            elements: Vec::new(),
            nodes: Vec::new(),
            ext_stage: Vec::new(),
            u: Vec::new(),
            u_prev: Vec::new(),
            force: Vec::new(),
            sends: Vec::new(),
            recvs: Vec::new(),
            path_points: Vec::new(),
            loads: Vec::new(),
        }
    }
}

static mut BUFFERS: Buffers = Buffers::new();
static TAKEN: AtomicBool = AtomicBool::new(false);

/// A record decoded from zero bytes: all numbers zero, every enum its first variant. Any
/// valid value would do; the loader overwrites what the image uses.
fn zero<R: DeserializeOwned>() -> Option<R> {
    const ZEROS: [u8; 2048] = [0; 2048];
    postcard::take_from_bytes::<R>(&ZEROS).ok().map(|(r, _)| r)
}

fn fill<T: Clone, const N: usize>(v: &mut Vec<T, N>, value: Option<T>) -> Option<()> {
    v.clear();
    v.resize(N, value?).ok()
}

/// The storage, filled to capacity; `None` if called twice (or a zero record fails to
/// decode, which would be a bug).
pub fn take() -> Option<Storage<'static, Scalar, Element>> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: TAKEN makes this the only place that ever creates a reference to BUFFERS, and
    // it does so at most once, so the `&'static mut` is unique.
    let b: &'static mut Buffers = unsafe { &mut *core::ptr::addr_of_mut!(BUFFERS) };
    let z3 = Some([Scalar::ZERO; 3]);
    fill(&mut b.laws, zero())?;
    fill(&mut b.elements, zero())?;
    fill(&mut b.nodes, zero())?;
    fill(&mut b.ext_stage, Some(0))?;
    fill(&mut b.u, z3)?;
    fill(&mut b.u_prev, z3)?;
    fill(&mut b.force, z3)?;
    fill(&mut b.sends, Some(0))?;
    fill(&mut b.recvs, zero())?;
    fill(&mut b.path_points, zero())?;
    fill(&mut b.loads, zero())?;
    Some(Storage {
        laws: &mut b.laws,
        elements: &mut b.elements,
        nodes: &mut b.nodes,
        ext_stage: &mut b.ext_stage,
        u: &mut b.u,
        u_prev: &mut b.u_prev,
        force: &mut b.force,
        sends: &mut b.sends,
        recvs: &mut b.recvs,
        path_points: &mut b.path_points,
        loads: &mut b.loads,
    })
}

static mut CONTACT: ContactStatic = ContactStatic::EMPTY;
static CONTACT_TAKEN: AtomicBool = AtomicBool::new(false);

/// The contact and graphics storage; `None` if called twice.
pub fn take_contact() -> Option<pe_firmware::runtime::ContactStorage<'static>> {
    if CONTACT_TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: CONTACT_TAKEN makes this the only place that ever creates a reference to
    // CONTACT, at most once, so the `&'static mut` is unique.
    let c: &'static mut ContactStatic = unsafe { &mut *core::ptr::addr_of_mut!(CONTACT) };
    Some(c.storage())
}
