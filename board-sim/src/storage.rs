//! Each board's storage on the host: the firmware's one storage owner
//! ([`pe_firmware::runtime::StorageBuf`]) over growable vectors, sized exactly for an image
//! or as the firmware of a board profile sizes it.

use pe_firmware::image::{ElementRecord, ImageError, ImageReader};
use pe_firmware::runtime::{Capacities, Runtime, RuntimeConfig, Shelf, StorageBuf, WireReal};

/// Growable vectors: board-sim's storage, sized when a board is loaded.
pub struct VecShelf;

impl Shelf for VecShelf {
    type Of<R: Copy, const N: usize> = Vec<R>;
    fn empty<R: Copy, const N: usize>() -> Vec<R> {
        Vec::new()
    }
    fn fill<R: Copy, const N: usize>(v: &mut Vec<R>, len: usize, value: R) -> bool {
        v.clear();
        v.resize(len, value);
        true
    }
}

/// One board's storage on the host (capacities chosen at run time).
pub(crate) type HostStorage<T, E> = StorageBuf<VecShelf, T, E, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0>;

/// How board-sim sizes each board's storage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StorageSizing {
    /// Exactly what each image needs (with room for the contact search).
    Exact,
    /// As the firmware of this profile does ([`Capacities::for_board`]): an image the board
    /// would refuse is refused here, with the same message.
    Board(pe_firmware::profile::BoardProfile),
}

impl StorageSizing {
    pub(crate) fn capacities<
        T: pe_firmware::physics::Real,
        E: pe_firmware::image::ElementRecord<T>,
    >(
        &self,
        image: &[u8],
    ) -> Result<Capacities, ImageError> {
        Ok(match self {
            StorageSizing::Exact => {
                Capacities::exact(&ImageReader::new(image, None)?.header.counts)
            }
            StorageSizing::Board(p) => Capacities::for_board::<T, E>(p),
        })
    }
}

/// Loads `image` for `board` into storage sized by `sizing`, as a board-sim worker does,
/// and drops it: what board-sim says of an image before running it.
pub fn load_check(image: &[u8], board: [u8; 3], sizing: StorageSizing) -> Result<(), ImageError> {
    fn typed<T: WireReal, E: ElementRecord<T>>(
        image: &[u8],
        board: [u8; 3],
        sizing: StorageSizing,
    ) -> Result<(), ImageError> {
        let mut buf = HostStorage::<T, E>::empty();
        let st = buf
            .fill(&sizing.capacities::<T, E>(image)?)
            .ok_or(ImageError::Malformed {
                record: "zero record (storage)",
            })?;
        Runtime::load(image, board, st, RuntimeConfig::default()).map(|_| ())
    }
    let h = ImageReader::new(image, Some(board))?.header;
    pe_firmware::with_element_types!(h.precision, h.integration, |T, E| {
        typed::<T, E>(image, board, sizing)
    })
}
