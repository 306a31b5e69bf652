//! Loading: an image into a board's storage through the image codec
//! ([`crate::image::read_image`]), then the runtime's own indexes (exchange ranges, the
//! external-force stages, this board's contact slot, the step program).

use link_proto::{FRAME_LEN_MAX, FRAME_RX_LEN, VALUES_PER_FRAME_MAX};

use super::contact::ContactState;
use super::exchange::{Exchange, LISTS_MAX};
use super::storage::SmallTables;
use super::{
    global, LinkStats, Program, Runtime, RuntimeConfig, Storage, WireReal, ROUNDS_PER_AXIS_MAX,
};
use crate::image::{read_image, ElementRecord, Feature, ImageError, ImageReader, STAGES};
use crate::physics::CentralDifference;

impl<'a, T: WireReal, E: ElementRecord<T>> Runtime<'a, T, E> {
    /// Checks and loads `image` for board `board` into `st`. An image that needs more than
    /// `st` holds is [`ImageError::Capacity`], naming the section.
    pub fn load(
        image: &[u8],
        board: [u8; 3],
        mut st: Storage<'a, T, E>,
        config: RuntimeConfig,
    ) -> Result<Self, ImageError> {
        // A build without a part: what the image needs of it, before anything is read into
        // storage (whose tables such a build does not hold). A whole build reads it once.
        if Feature::ALL.iter().any(|f| !f.built()) {
            let needs = ImageReader::new(image, Some(board))?.header;
            for feature in Feature::ALL {
                if let (false, Some(count)) = (feature.built(), needs.uses(feature)) {
                    return Err(ImageError::Unsupported { feature, count });
                }
            }
        }
        let mut exchange = Exchange::<T>::new();
        let mut contact = ContactState::new();
        let header = {
            let mut parts = st.image_parts(SmallTables {
                lists: &mut exchange.lists[..],
                pairs: &mut contact.pairs[..],
                tools: &mut contact.tools[..],
                contact_boards: &mut contact.boards[..],
            });
            read_image(image, Some(board), &mut parts)
        }
        .map_err(|e| match e {
            // The small tables are the runtime's: name their limits as capacities.
            ImageError::Capacity {
                what: "exchange lists",
                count,
                ..
            } => ImageError::Capacity {
                what: "exchange rounds per axis",
                count,
                max: ROUNDS_PER_AXIS_MAX as u32,
            },
            e => e,
        })?;
        let c = header.counts;
        // The frame buffers live in the storage (a runtime on the stack stays small).
        for (len, max) in [
            (st.tx.len(), FRAME_LEN_MAX),
            (st.rx.len(), FRAME_RX_LEN),
            (st.scratch.len(), VALUES_PER_FRAME_MAX),
        ] {
            if len < max {
                return Err(ImageError::Capacity {
                    what: "frame buffers",
                    count: max as u32,
                    max: len as u32,
                });
            }
        }
        for &n in &c.rounds {
            if n as usize > ROUNDS_PER_AXIS_MAX {
                return Err(ImageError::Capacity {
                    what: "exchange rounds per axis",
                    count: n as u32,
                    max: ROUNDS_PER_AXIS_MAX as u32,
                });
            }
        }
        debug_assert!(c.exchange_lists() <= LISTS_MAX);
        exchange.index(&c.rounds);
        let (nn, nc) = (c.nodes as usize, c.contact_nodes as usize);
        // The update leaves the forces zero for the next step; the first starts from here.
        for u in [&mut st.u, &mut st.du, &mut st.force] {
            u.iter_mut().take(nn).for_each(|x| *x = [T::ZERO; 3]);
        }
        clear_contact(&mut st, nc)?;
        let address = link_proto::Machine::address(board.map(usize::from)).unwrap_or(u8::MAX);
        let n_boards = c.contact_boards as usize;
        contact.slot = contact.boards[..n_boards]
            .iter()
            .position(|&b| b == address);
        contact.owns_nodes = st.contact.places.iter().take(nc).any(|p| p.owned);
        let has_contact = c.tools > 0 || c.pairs > 0;
        let has_graphics = header.uses(Feature::Graphics).is_some();
        Ok(Runtime {
            header,
            program: Program::new(&c.rounds, &c.late_rounds, has_contact, has_graphics),
            pc: 0,
            waiting_since: None,
            exchange,
            cd: CentralDifference::new(header.params.dt_s, header.params.damping_per_s),
            step: 0,
            config,
            port: global::GlobalPort {
                address,
                msg_id: 0,
                stats: Default::default(),
            },
            contact,
            graphics_cursor: 0,
            hello: super::hello::Hello::new(header.board, header.machine, c.rounds),
            stats: LinkStats::default(),
            external_stages: stage_ranges(&c.external),
            reaction_prescribed: [0.0; 3],
            reaction_fixed: [0.0; 3],
            kinetic_energy: 0.0,
            st,
        })
    }
}

/// Each stage's range in the external-force records (grouped by stage).
fn stage_ranges(counts: &[u16; STAGES]) -> [(u32, u32); STAGES] {
    let mut end = 0;
    counts.map(|n| {
        end += n as u32;
        (end - n as u32, end)
    })
}

/// Clears the contact buffers.
fn clear_contact<T, E>(st: &mut Storage<'_, T, E>, nc: usize) -> Result<(), ImageError> {
    let cs = &mut st.contact;
    for (what, len) in [
        ("contact nodes", cs.at_check.len()),
        ("contact nodes", cs.force.len()),
        ("contact nodes", cs.at_step.len()),
        ("contact nodes", cs.remote.len()),
    ] {
        if nc > len {
            return Err(ImageError::Capacity {
                what,
                count: nc as u32,
                max: len as u32,
            });
        }
    }
    cs.force[..nc].fill([0.0; 3]);
    cs.at_check[..nc].fill([0.0; 3]);
    cs.at_step[..nc].fill(None);
    cs.remote[..nc].fill([(0, [0.0; 3]); 2]);
    Ok(())
}
