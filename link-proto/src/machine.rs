//! The board array: its size, board coordinates and indices, the board across each face,
//! and the global-network address of a board. The one home of these facts: the compiler,
//! the runtime, board-sim, the QEMU harness and `pe flash` all ask a [`Machine`].
//!
//! A board is named by its coordinates `[x, y, z]` in the array (`0 ≤ x < X`, ...). Its
//! *index* in an `X×Y×Z` machine is `x + X (y + Y z)` (x fastest): the order of images,
//! manifests and reports. Its *address* on the global network is its index in the
//! [`Machine::ADDRESSES`] array (`GRID_DIM`³ boards), the same for a board whatever the
//! machine's size, so an address fits the packets' one-byte fields.
//!
//! Nothing here panics: every lookup that can fall outside the array returns `Option`.

use core::fmt;

use crate::limits::GRID_DIM;
use crate::link::Face;
use crate::packet::BoardId;

/// Board coordinates `[x, y, z]` in the array.
pub type Coords = [usize; 3];

/// An `X×Y×Z` board array, every board linked to its face neighbours inside it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Machine {
    dims: [usize; 3],
}

impl Machine {
    /// Most boards along one axis.
    pub const AXIS_MAX: usize = 16;

    /// The address space of the global network: a board's address is its index here.
    pub const ADDRESSES: Machine = Machine {
        dims: [GRID_DIM; 3],
    };

    /// A machine of `dims` boards, or `None` when an axis is 0 or over [`Machine::AXIS_MAX`].
    pub const fn new(dims: [usize; 3]) -> Option<Machine> {
        let mut a = 0;
        while a < 3 {
            if dims[a] == 0 || dims[a] > Self::AXIS_MAX {
                return None;
            }
            a += 1;
        }
        Some(Machine { dims })
    }

    /// Boards along each axis.
    pub const fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Number of boards.
    pub const fn count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Whether `c` names a board of this machine.
    pub const fn contains(&self, c: Coords) -> bool {
        c[0] < self.dims[0] && c[1] < self.dims[1] && c[2] < self.dims[2]
    }

    /// The index of the board at `c` (x fastest), or `None` outside the machine.
    pub const fn index_of(&self, c: Coords) -> Option<usize> {
        if self.contains(c) {
            Some(self.index(c))
        } else {
            None
        }
    }

    /// The index of the board at `c` (x fastest); `c` must be inside the machine
    /// (outside, the value names no board: use [`Machine::index_of`] for outside data).
    pub const fn index(&self, c: Coords) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// The coordinates of board `i` (`i < count()`; past it, coordinates outside the
    /// machine in z).
    pub const fn coords(&self, i: usize) -> Coords {
        [
            i % self.dims[0],
            (i / self.dims[0]) % self.dims[1],
            i / (self.dims[0] * self.dims[1]),
        ]
    }

    /// The coordinates of board `i`, or `None` when `i ≥ count()`.
    pub const fn coords_of(&self, i: usize) -> Option<Coords> {
        if i < self.count() {
            Some(self.coords(i))
        } else {
            None
        }
    }

    /// The board across `face` of the board at `c`, or `None` at the machine's edge.
    pub const fn neighbour(&self, c: Coords, face: Face) -> Option<Coords> {
        match across(c, face) {
            Some(n) if self.contains(n) => Some(n),
            _ => None,
        }
    }

    /// The faces of the board at `c` that link to a neighbour, in [`Face::ALL`] order.
    pub fn linked_faces(&self, c: Coords) -> impl Iterator<Item = Face> + '_ {
        Face::ALL
            .into_iter()
            .filter(move |&f| self.neighbour(c, f).is_some())
    }

    /// Every board's coordinates, in index order.
    pub fn boards(&self) -> impl Iterator<Item = Coords> + '_ {
        (0..self.count()).map(|i| self.coords(i))
    }

    /// The global-network address of the board at `c`, or `None` when `c` lies outside
    /// the address space ([`Machine::ADDRESSES`]).
    pub const fn address(c: Coords) -> Option<BoardId> {
        match Self::ADDRESSES.index_of(c) {
            Some(i) => Some(i as BoardId),
            None => None,
        }
    }

    /// The coordinates of the board with global-network address `a`, or `None` for an
    /// address that names no board (the graphics engine, the host, broadcast).
    pub const fn from_address(a: BoardId) -> Option<Coords> {
        Self::ADDRESSES.coords_of(a as usize)
    }

    /// Parses `X x Y x Z` (e.g. `4x4x4`), each axis `1 ..= AXIS_MAX`.
    pub fn parse(s: &str) -> Result<Machine, ParseMachineError> {
        let mut dims = [0usize; 3];
        let mut parts = s.split(['x', 'X']);
        for d in &mut dims {
            *d = parts
                .next()
                .and_then(|p| p.trim().parse().ok())
                .ok_or(ParseMachineError)?;
        }
        if parts.next().is_some() {
            return Err(ParseMachineError);
        }
        Machine::new(dims).ok_or(ParseMachineError)
    }
}

/// A machine size that is not `X x Y x Z` with `1 ..= 16` boards per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParseMachineError;

impl fmt::Display for ParseMachineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "expected X x Y x Z with 1..{} boards per axis, e.g. 4x4x4",
            Machine::AXIS_MAX
        )
    }
}

impl core::error::Error for ParseMachineError {}

impl fmt::Display for Machine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}x{}", self.dims[0], self.dims[1], self.dims[2])
    }
}

/// The coordinates across `face` of `c` in an unbounded array, or `None` below 0 or past
/// `usize::MAX`. A board that knows its coordinates but not the machine's size (the
/// firmware) asks this; [`Machine::neighbour`] also checks the far edge.
pub const fn across(c: Coords, face: Face) -> Option<Coords> {
    let a = face.axis() as usize;
    let mut n = c;
    n[a] = if face.sign() > 0 {
        match c[a].checked_add(1) {
            Some(v) => v,
            None => return None,
        }
    } else {
        match c[a].checked_sub(1) {
            Some(v) => v,
            None => return None,
        }
    };
    Some(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_and_coords_are_inverse_and_x_fastest() {
        let m = Machine::new([3, 2, 5]).unwrap();
        assert_eq!(m.count(), 30);
        for i in 0..m.count() {
            assert_eq!(m.index(m.coords(i)), i);
        }
        assert_eq!(m.coords(1), [1, 0, 0]);
        assert_eq!(m.coords(3), [0, 1, 0]);
        assert_eq!(m.coords(6), [0, 0, 1]);
        assert_eq!(m.coords_of(30), None);
        assert_eq!(m.index_of([3, 0, 0]), None);
    }

    #[test]
    fn neighbours_are_symmetric_and_stop_at_the_edge() {
        let m = Machine::new([2, 3, 1]).unwrap();
        let mut links = 0;
        for c in m.boards() {
            for f in m.linked_faces(c) {
                let n = m.neighbour(c, f).unwrap();
                assert_eq!(m.neighbour(n, f.opposite()), Some(c));
                links += 1;
            }
        }
        // Directed links: 2 * (x-links 1*3 + y-links 2*2) = 14.
        assert_eq!(links, 14);
        assert_eq!(m.neighbour([0, 0, 0], Face::NegX), None);
        assert_eq!(m.neighbour([0, 0, 0], Face::PosZ), None);
        assert_eq!(across([0, 0, 0], Face::PosZ), Some([0, 0, 1]));
    }

    #[test]
    fn addresses_are_the_4x4x4_index_whatever_the_machine() {
        assert_eq!(Machine::address([1, 0, 0]), Some(1));
        assert_eq!(Machine::address([0, 1, 0]), Some(GRID_DIM as u8));
        assert_eq!(
            Machine::address([0, 0, 1]),
            Some((GRID_DIM * GRID_DIM) as u8)
        );
        assert_eq!(Machine::address([GRID_DIM, 0, 0]), None);
        for a in 0..crate::limits::BOARD_COUNT as u8 {
            assert_eq!(Machine::address(Machine::from_address(a).unwrap()), Some(a));
        }
        assert_eq!(Machine::from_address(crate::packet::ADDR_HOST), None);
    }

    #[test]
    fn parse_accepts_sizes_and_refuses_the_rest() {
        assert_eq!(Machine::parse("4x2X1").ok(), Machine::new([4, 2, 1]));
        for bad in ["4x4", "4x4x4x4", "0x1x1", "17x1x1", "ax1x1", ""] {
            assert_eq!(Machine::parse(bad), Err(ParseMachineError), "{bad}");
        }
    }
}
