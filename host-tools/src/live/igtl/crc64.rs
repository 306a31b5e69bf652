//! CRC-64 as OpenIGTLink computes it over a message body: the ECMA-182 polynomial
//! `0x42F0E1EBA9EA3693`, initial value 0, no reflection of input or output, no final xor
//! (the catalogue's CRC-64/ECMA-182, check value `0x6C40DF5F0B497347` over the ASCII
//! bytes "123456789": <https://reveng.sourceforge.io/crc-catalogue/17plus.htm>).
//!
//! Sources: the header spec (`Documents/Protocol/header.md` in
//! <https://github.com/openigtlink/OpenIGTLink>) names ECMA-182 and points to
//! `Source/igtlutil/igtl_util.c` (`crc64`: a most-significant-bit-first table over the
//! top byte, started from `crc64(0, 0, 0)` = 0 in `igtlMessageBase.cxx`); pyigtl
//! (`pyigtl/messages.py`, `CRC64 = crcmod.mkCrcFun(0x142F0E1EBA9EA3693, rev=False,
//! initCrc=0, xorOut=0)`) computes the same.

/// The generator polynomial (ECMA-182), without its x^64 term.
pub const POLY: u64 = 0x42F0_E1EB_A9EA_3693;

/// The remainder of each byte value shifted to the top of the register.
const TABLE: [u64; 256] = table();

const fn table() -> [u64; 256] {
    let mut t = [0u64; 256];
    let mut i = 0;
    while i < 256 {
        let mut r = (i as u64) << 56;
        let mut bit = 0;
        while bit < 8 {
            r = if r & (1 << 63) != 0 {
                (r << 1) ^ POLY
            } else {
                r << 1
            };
            bit += 1;
        }
        t[i] = r;
        i += 1;
    }
    t
}

/// The CRC-64 of `bytes` continuing from `crc` (0 for a new body).
pub fn update(crc: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(crc, |c, &b| {
        TABLE[usize::from(b ^ (c >> 56) as u8)] ^ (c << 8)
    })
}

/// The CRC-64 of `bytes`.
pub fn crc64(bytes: &[u8]) -> u64 {
    update(0, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Long division of the message times x^64 by the polynomial, one bit at a time: the
    /// definition, without the table.
    fn bitwise(bytes: &[u8]) -> u64 {
        let mut r = 0u64;
        for &b in bytes {
            for k in (0..8).rev() {
                let top = (r >> 63) != 0;
                let bit = (b >> k) & 1 != 0;
                r <<= 1;
                if top != bit {
                    r ^= POLY;
                }
            }
        }
        r
    }

    #[test]
    fn the_published_check_value() {
        // CRC-64/ECMA-182 check over "123456789" (reveng catalogue).
        assert_eq!(crc64(b"123456789"), 0x6C40_DF5F_0B49_7347);
        assert_eq!(bitwise(b"123456789"), 0x6C40_DF5F_0B49_7347);
    }

    #[test]
    fn the_table_agrees_with_the_bitwise_definition_and_updates_compose() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7919 % 251) as u8).collect();
        assert_ne!(crc64(&data), 0);
        assert_eq!(crc64(&data), bitwise(&data));
        assert_eq!(update(crc64(&data[..333]), &data[333..]), crc64(&data));
        assert_eq!(crc64(&[]), 0);
    }
}
