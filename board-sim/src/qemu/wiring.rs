//! How an emulated array is wired: which faces each board exchanges over (from its image)
//! and the UART each goes on (`pe_firmware::profile::mps2_uarts`), and the cables that join
//! a face connector to the one across it, two of them crossed on request.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use host_tools::compile::Manifest;
use link_proto::link::FACE_NAMES;
use link_proto::machine::across;
use link_proto::Face;
use pe_firmware::image::ImageReader;
use pe_firmware::profile::mps2_uarts;

/// One end of a cable: a board's face connector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Connector {
    pub board: [usize; 3],
    pub face: usize,
}

impl std::fmt::Display for Connector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.board;
        let name = FACE_NAMES[self.face];
        write!(f, "({x},{y},{z}) {name}")
    }
}

/// Board coordinates `X,Y,Z`.
pub fn parse_board(s: &str) -> Option<[usize; 3]> {
    let c: Vec<usize> = s
        .split(',')
        .map(|v| v.trim().parse().ok())
        .collect::<Option<_>>()?;
    c.try_into().ok()
}

impl Connector {
    /// `X,Y,Z:FACE`, e.g. `0,0,0:+x`.
    pub fn parse(s: &str) -> Result<Self> {
        let bad = || anyhow!("{s:?}: expected a connector X,Y,Z:FACE such as 0,0,0:+x");
        let (b, f) = s.split_once(':').ok_or_else(bad)?;
        let [x, y, z] = parse_board(b).ok_or_else(bad)?;
        let face = FACE_NAMES
            .iter()
            .position(|n| *n == f.trim())
            .ok_or_else(bad)?;
        Ok(Connector {
            board: [x, y, z],
            face,
        })
    }
}

/// A board as reports name it: `(x,y,z)`.
pub(crate) fn name(c: [usize; 3]) -> String {
    format!("({},{},{})", c[0], c[1], c[2])
}

/// The global address of a board.
pub(crate) fn address(c: [usize; 3]) -> u8 {
    link_proto::Machine::address(c).unwrap_or(u8::MAX)
}

/// A board's UART: (board, UART number).
pub(crate) type Uart = ([usize; 3], usize);

/// Per board (by coordinates): the faces it exchanges over.
pub type Linked = BTreeMap<[usize; 3], [bool; 6]>;

/// The wiring of the array compiled in a directory.
pub(crate) struct Wiring {
    /// The faces each board exchanges over.
    pub linked: Linked,
    /// The UART of each of a board's faces (None: not linked).
    pub uarts: BTreeMap<[usize; 3], [Option<usize>; 6]>,
    /// The cables, `cross` applied.
    pub cables: Vec<(Connector, Connector)>,
    /// The scene's tools: the most any image holds (a board that owns no contact node
    /// carries no contact tables).
    pub tools: usize,
}

impl Wiring {
    /// Reads the images of `m`'s boards in `dir`: the faces each exchanges over and the
    /// UART each goes on; the cables between them, `cross` applied.
    pub fn read(dir: &Path, m: &Manifest, cross: Option<[Connector; 2]>) -> Result<Wiring> {
        let mut linked = BTreeMap::new();
        let mut uarts = BTreeMap::new();
        let mut tools = 0;
        for b in &m.boards {
            let p = dir.join(&b.file);
            let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
            let h = ImageReader::new(&bytes, Some(b.board.map(|v| v as u8)))
                .map_err(|e| anyhow!("board {}: {}: {e}", name(b.board), p.display()))?
                .header;
            tools = tools.max(h.counts.tools as usize);
            let l = h.linked_faces();
            let u = mps2_uarts::face_uarts(l).map_err(|n| {
                anyhow!(
                    "board {} exchanges over {n} faces; QEMU's mps2-an500 has {} UARTs for faces (the fifth is the global port)",
                    name(b.board),
                    mps2_uarts::FACE_UARTS.len()
                )
            })?;
            linked.insert(b.board, l);
            uarts.insert(b.board, u);
        }
        let cables = cables(&linked, cross)?;
        Ok(Wiring {
            linked,
            uarts,
            cables,
            tools,
        })
    }

    /// Every UART a board uses: its faces' and the global port.
    pub fn board_uarts(&self) -> impl Iterator<Item = Uart> + '_ {
        self.uarts.iter().flat_map(|(&b, u)| {
            u.iter()
                .flatten()
                .copied()
                .chain([mps2_uarts::GLOBAL_UART])
                .map(move |uart| (b, uart))
        })
    }
}

/// The cables of a machine: each linked face connector with the one across it (each cable
/// once, lower board first), `cross` applied.
pub fn cables(
    linked: &Linked,
    cross: Option<[Connector; 2]>,
) -> Result<Vec<(Connector, Connector)>> {
    let mut out = Vec::new();
    for (&b, l) in linked {
        for face in Face::ALL.into_iter().filter(|f| f.sign() > 0) {
            if !l[face.index()] {
                continue;
            }
            let n = across(b, face).context("a board past usize::MAX")?;
            if !linked.get(&n).is_some_and(|nl| nl[face.opposite().index()]) {
                bail!(
                    "board {} exchanges over {} but board {} does not over {}: the images disagree on the machine",
                    name(b),
                    FACE_NAMES[face.index()],
                    name(n),
                    FACE_NAMES[face.opposite().index()]
                );
            }
            out.push((
                Connector {
                    board: b,
                    face: face.index(),
                },
                Connector {
                    board: n,
                    face: face.opposite().index(),
                },
            ));
        }
    }
    if let Some(pair) = cross {
        cross_cables(&mut out, pair)?;
    }
    Ok(out)
}

/// Swaps the far ends of the cables at connectors `a` and `b`.
fn cross_cables(out: &mut [(Connector, Connector)], [a, b]: [Connector; 2]) -> Result<()> {
    let find = |c: Connector| {
        out.iter()
            .position(|&(p, q)| p == c || q == c)
            .ok_or_else(|| anyhow!("--cross: connector {c} carries no cable in this machine"))
    };
    let (i, j) = (find(a)?, find(b)?);
    if i == j {
        bail!("--cross: {a} and {b} are the two ends of one cable: crossing it changes nothing");
    }
    // Each cable as (the named connector, its far end); the far ends swap.
    let split = |k: usize, c: Connector| {
        let (p, q) = out[k];
        if p == c {
            (p, q)
        } else {
            (q, p)
        }
    };
    let ((a, fa), (b, fb)) = (split(i, a), split(j, b));
    out[i] = (a, fb);
    out[j] = (b, fa);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine(m: [usize; 3]) -> Linked {
        let mut out = BTreeMap::new();
        for z in 0..m[2] {
            for y in 0..m[1] {
                for x in 0..m[0] {
                    let b = [x as u8, y as u8, z as u8];
                    let l = pe_firmware::image::linked_faces(b, m.map(|v| v as u8), [1, 1, 1]);
                    out.insert([x, y, z], l);
                }
            }
        }
        out
    }

    fn c(b: [usize; 3], face: Face) -> Connector {
        Connector {
            board: b,
            face: face.index(),
        }
    }

    /// Every link of a 2x2x2 machine once (12 cables), each joining a face to its
    /// neighbour's opposite face; crossing two swaps their far ends and nothing else.
    #[test]
    fn cables_join_opposite_faces_and_cross_swaps_far_ends() {
        let plain = cables(&machine([2, 2, 2]), None).unwrap();
        assert_eq!(plain.len(), 12);
        for &(a, b) in &plain {
            assert_eq!(b.face, Face::ALL[a.face].opposite().index());
            let mut n = a.board;
            n[a.face / 2] += 1;
            assert_eq!(b.board, n);
        }
        let (x, y) = (c([0, 0, 0], Face::PosX), c([0, 0, 0], Face::PosY));
        let crossed = cables(&machine([2, 2, 2]), Some([x, y])).unwrap();
        assert_eq!(crossed.len(), plain.len());
        let far = |cs: &[(Connector, Connector)], k: Connector| {
            cs.iter()
                .find_map(|&(p, q)| (p == k).then_some(q).or((q == k).then_some(p)))
                .unwrap()
        };
        assert_eq!(far(&crossed, x), c([0, 1, 0], Face::NegY));
        assert_eq!(far(&crossed, y), c([1, 0, 0], Face::NegX));
        let unchanged = plain.iter().zip(&crossed).filter(|(p, q)| p == q).count();
        assert_eq!(unchanged, 10);
    }

    /// A connector without a cable, or both ends of one cable, cannot be crossed.
    #[test]
    fn crossing_needs_two_cables() {
        let m = machine([2, 1, 1]);
        let e = cables(
            &m,
            Some([c([0, 0, 0], Face::PosX), c([0, 0, 0], Face::PosY)]),
        );
        assert!(e
            .unwrap_err()
            .to_string()
            .contains("(0,0,0) +y carries no cable"));
        let e = cables(
            &m,
            Some([c([0, 0, 0], Face::PosX), c([1, 0, 0], Face::NegX)]),
        );
        assert!(e.unwrap_err().to_string().contains("two ends of one cable"));
    }

    #[test]
    fn connectors_parse_as_written() {
        assert_eq!(
            Connector::parse("1,0,2:-z").unwrap(),
            c([1, 0, 2], Face::NegZ)
        );
        assert!(Connector::parse("1,0:+x").is_err());
        assert!(Connector::parse("1,0,0:x").is_err());
        assert_eq!(c([1, 0, 2], Face::NegZ).to_string(), "(1,0,2) -z");
    }
}
