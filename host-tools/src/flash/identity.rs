//! Boards known by their chips: each MCU's 96-bit unique device ID (the STM32H743's at
//! 0x1FF1_E800, RM0433 "Unique device ID register (96 bits)"), read through every probe
//! before anything is written, and checked against the board map's `uid`.
//!
//! A probe on the wrong board (two probes swapped at the array) is refused naming both
//! positions; two probes that reach one board, or a probe on a board the map does not
//! know, are refused too. A map without `uid`s still flashes; `pe flash` then prints each
//! board's ID for the map.

use std::collections::BTreeMap;
use std::fmt;

use anyhow::{bail, Result};
use link_proto::machine::Coords;

/// A 96-bit unique device ID: its three words in address order (UID[31:0], UID[63:32],
/// UID[95:64]), written `XXXXXXXX:XXXXXXXX:XXXXXXXX` in board maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct UniqueId(pub [u32; 3]);

/// Bytes of a unique ID in memory.
pub const UNIQUE_ID_BYTES: usize = 12;

impl UniqueId {
    /// From a board map's text: 24 hex digits, optionally `0x`-prefixed per word and
    /// separated by `:`, `-`, `_` or spaces (e.g. `003A0028:31385104:33333439`).
    pub fn parse(text: &str) -> Option<UniqueId> {
        let digits: String = text
            .split([':', '-', '_', ' '])
            .map(|w| w.trim_start_matches("0x").trim_start_matches("0X"))
            .collect();
        if digits.len() != 24 || !digits.bytes().all(|b| b.is_ascii_hexdigit()) {
            return None;
        }
        let word = |k: usize| u32::from_str_radix(&digits[8 * k..8 * k + 8], 16).ok();
        Some(UniqueId([word(0)?, word(1)?, word(2)?]))
    }

    /// From the 12 bytes read at the ID's address (little-endian words).
    pub fn from_bytes(bytes: &[u8]) -> Option<UniqueId> {
        if bytes.len() != UNIQUE_ID_BYTES {
            return None;
        }
        let word = |k: usize| {
            let b: [u8; 4] = bytes[4 * k..4 * k + 4].try_into().ok()?;
            Some(u32::from_le_bytes(b))
        };
        Some(UniqueId([word(0)?, word(1)?, word(2)?]))
    }
}

impl fmt::Display for UniqueId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b, c] = self.0;
        write!(f, "{a:08X}:{b:08X}:{c:08X}")
    }
}

fn at(c: Coords) -> String {
    let [x, y, z] = c;
    format!("({x},{y},{z})")
}

/// Checks the IDs read through each board's probe (`read`, every board of the map) against
/// the map's (`mapped`, the boards that give one), before anything is written.
pub fn check_unique_ids(
    read: &BTreeMap<Coords, UniqueId>,
    mapped: &BTreeMap<Coords, UniqueId>,
    probes: &BTreeMap<Coords, String>,
) -> Result<()> {
    let owner_in_map: BTreeMap<UniqueId, Coords> = mapped.iter().map(|(c, u)| (*u, *c)).collect();
    let mut reached: BTreeMap<UniqueId, Coords> = BTreeMap::new();
    for (&board, &uid) in read {
        let probe = probes.get(&board).map_or("?", String::as_str);
        if let Some(first) = reached.insert(uid, board) {
            bail!(
                "boards {} and {}: their probes ({} and {probe}) reach the same chip (unique ID {uid}): one probe is on the wrong board",
                at(first),
                at(board),
                probes.get(&first).map_or("?", String::as_str)
            );
        }
        match (mapped.get(&board), owner_in_map.get(&uid)) {
            (Some(want), _) if *want == uid => {}
            (_, Some(&other)) if other != board => bail!(
                "board {}: probe {probe} is on the chip with unique ID {uid}, which the board map gives board {}: the probes of boards {} and {} look swapped; nothing was written",
                at(board),
                at(other),
                at(board),
                at(other)
            ),
            (Some(want), _) => bail!(
                "board {}: probe {probe} is on the chip with unique ID {uid}, not {want} as the board map says, and no board of the map has that chip; nothing was written",
                at(board)
            ),
            (None, _) => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_parse_in_the_common_spellings_and_round_trip() {
        let want = UniqueId([0x003A_0028, 0x3138_5104, 0x3333_3439]);
        for text in [
            "003A0028:31385104:33333439",
            "0x003a0028 0x31385104 0x33333439",
            "003a002831385104-33333439",
        ] {
            assert_eq!(UniqueId::parse(text), Some(want), "{text}");
        }
        assert_eq!(UniqueId::parse(&want.to_string()), Some(want));
        for bad in [
            "",
            "003A0028:31385104",
            "003A0028:31385104:3333343G",
            "1:2:3",
        ] {
            assert_eq!(UniqueId::parse(bad), None, "{bad}");
        }
        // Memory order: the first word at the lowest address, little-endian.
        let bytes = [
            0x28, 0x00, 0x3A, 0x00, 0x04, 0x51, 0x38, 0x31, 0x39, 0x34, 0x33, 0x33,
        ];
        assert_eq!(UniqueId::from_bytes(&bytes), Some(want));
        assert_eq!(UniqueId::from_bytes(&bytes[..11]), None);
    }

    #[test]
    fn swapped_duplicated_and_unknown_chips_are_named() {
        let (a, b) = (UniqueId([1, 2, 3]), UniqueId([4, 5, 6]));
        let (p0, p1) = ([0, 0, 0], [1, 0, 0]);
        let probes = BTreeMap::from([(p0, "PA".to_string()), (p1, "PB".to_string())]);
        let mapped = BTreeMap::from([(p0, a), (p1, b)]);
        let ok = BTreeMap::from([(p0, a), (p1, b)]);
        assert!(check_unique_ids(&ok, &mapped, &probes).is_ok());
        let swapped = BTreeMap::from([(p0, b), (p1, a)]);
        let e = check_unique_ids(&swapped, &mapped, &probes)
            .unwrap_err()
            .to_string();
        assert!(e.contains("board (0,0,0): probe PA is on the chip with unique ID 00000004:00000005:00000006, which the board map gives board (1,0,0)"), "{e}");
        let same = BTreeMap::from([(p0, a), (p1, a)]);
        let e = check_unique_ids(&same, &BTreeMap::new(), &probes)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("boards (0,0,0) and (1,0,0): their probes (PA and PB) reach the same chip"),
            "{e}"
        );
        let stranger = BTreeMap::from([(p0, a), (p1, UniqueId([7, 7, 7]))]);
        let e = check_unique_ids(&stranger, &mapped, &probes)
            .unwrap_err()
            .to_string();
        assert!(e.contains("board (1,0,0): probe PB is on the chip with unique ID 00000007:00000007:00000007, not 00000004:00000005:00000006"), "{e}");
        // Boards the map gives no ID pass, unless their chip is another board's.
        let partial = BTreeMap::from([(p1, b)]);
        assert!(check_unique_ids(&ok, &partial, &probes).is_ok());
        let e = check_unique_ids(
            &BTreeMap::from([(p0, b), (p1, UniqueId([9, 9, 9]))]),
            &partial,
            &probes,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("which the board map gives board (1,0,0)"), "{e}");
    }
}
