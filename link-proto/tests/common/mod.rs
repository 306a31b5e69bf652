//! Helpers shared by the frame and packet tests.

use link_proto::Error;

/// `count` mutations of `bases` (one or two bit flips, and a truncation to 12 bytes or more
/// in one of four), each with its last four bytes set to the CRC-32 of the rest, given to
/// `re_emit` (parse, then emit). Asserts that an accepted input re-emits to its own bytes
/// and that a refused one is not refused for its CRC; returns (accepted, refused).
pub fn mutations_with_crc(
    bases: &[&[u8]],
    seed: u64,
    count: usize,
    mut re_emit: impl FnMut(&[u8]) -> Result<Vec<u8>, Error>,
) -> (usize, usize) {
    let mut x = seed;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let (mut accepted, mut refused) = (0, 0);
    for k in 0..count {
        let mut bytes = bases[k % bases.len()].to_vec();
        for _ in 0..1 + next() % 2 {
            let i = (next() % bytes.len() as u64) as usize;
            bytes[i] ^= 1 << (next() % 8);
        }
        if next() % 4 == 0 {
            bytes.truncate(12 + (next() % (bytes.len() as u64 - 11)) as usize);
        }
        let body = bytes.len() - 4;
        let crc = link_proto::frame::crc32(&bytes[..body]);
        bytes[body..].copy_from_slice(&crc.to_le_bytes());
        match re_emit(&bytes) {
            Ok(out) => {
                assert_eq!(out, bytes, "mutation {k} re-emits to its bytes");
                accepted += 1;
            }
            Err(e) => {
                assert_ne!(e, Error::BadCrc, "mutation {k}: the CRC is correct");
                refused += 1;
            }
        }
    }
    println!("{accepted} accepted, {refused} refused");
    (accepted, refused)
}
