//! Checks of a VTK XML file's bytes before vtkio reads them: raw appended data refused,
//! and the sizes that compressed data claims held to what the data can inflate to (vtkio
//! would allocate or index by them).

use super::*;

/// zlib inflates a byte into at most 1032 (RFC 1950/1951: a 258-byte match per 2 bits at
/// best); LZ4 into at most 255 + a little. Anything claiming more is not compressed data.
const INFLATE_RATIO_MAX: u64 = 1032;

/// The standard base64 alphabet's value of `c`, None for padding or anything else.
fn b64_value(c: u8) -> Option<u32> {
    Some(match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => return None,
    } as u32)
}

/// The first `n` bytes base64 `text` encodes (None if it holds fewer).
fn b64_prefix(text: &[u8], n: usize) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(n + 2);
    for quad in text.chunks(4) {
        if out.len() >= n {
            break;
        }
        let v: Vec<u32> = quad.iter().map_while(|&c| b64_value(c)).collect();
        if v.len() < 2 {
            return None;
        }
        let w = v.iter().fold(0u32, |a, &x| (a << 6) | x) << (6 * (4 - v.len()));
        out.extend_from_slice(&w.to_be_bytes()[1..v.len()]);
    }
    (out.len() >= n).then(|| {
        out.truncate(n);
        out
    })
}

/// A compressed VTU's binary arrays (inline, or appended base64) claim their
/// uncompressed size in a header that vtkio allocates before it inflates anything: a
/// damaged header (found by fuzzing: 2 GiB claimed by a 2.6 kB file) would make the tool
/// allocate it. Each header is read here first and a claim beyond what its compressed
/// bytes can inflate to is refused, naming the line of its DataArray.
pub(super) fn check_compressed_sizes(path: &Path, bytes: &[u8]) -> Result<(), MeshError> {
    // The XML before any appended data is text (appended data may be raw bytes).
    let appended_at = find_bytes(bytes, b"<AppendedData");
    // Lossy: vtkio reads a file with stray non-UTF-8 bytes (in a comment, say) all the same
    // (libFuzzer found a 2 GiB claim behind one); they change no base64 text or newline.
    let text = String::from_utf8_lossy(&bytes[..appended_at.unwrap_or(bytes.len())]);
    let text: &str = &text;
    if !text.contains("compressor=") {
        return Ok(());
    }
    let width = if text.contains("header_type=\"UInt64\"") {
        8
    } else {
        4
    };
    let damaged = |line: usize, what: String| {
        perr(
            path,
            Some(line),
            format!("a compressed DataArray's header {what}: a damaged header"),
        )
    };
    // Inline arrays: the base64 text right after the tag.
    let mut at = 0;
    while let Some(k) = text[at..].find("format=\"binary\"") {
        let tag_end = match text[at + k..].find('>') {
            Some(e) => at + k + e + 1,
            None => break,
        };
        at = tag_end;
        let body = text[tag_end..].trim_start().as_bytes();
        let line = 1 + text[..tag_end].matches('\n').count();
        compressed_header_claim(body, width).map_err(|what| damaged(line, what))?;
    }
    // Appended arrays: at their `offset` after the `_` that opens the AppendedData.
    let Some(a) = appended_at else {
        return Ok(());
    };
    let Some(tag_len) = bytes[a..].iter().position(|&b| b == b'>') else {
        return Ok(());
    };
    if String::from_utf8_lossy(&bytes[a..a + tag_len]).contains("encoding=\"raw\"") {
        return Ok(()); // refused by `refuse_raw_appended`
    }
    let after_tag = &bytes[a + tag_len + 1..];
    let Some(underscore) = after_tag.iter().position(|&b| b == b'_') else {
        return Ok(());
    };
    let data = &after_tag[underscore + 1..];
    let mut at = 0;
    while let Some(k) = text[at..].find("format=\"appended\"") {
        let tag_start = text[..at + k].rfind('<').unwrap_or(0);
        let tag_end = text[at + k..].find('>').map_or(text.len(), |e| at + k + e);
        at = tag_end.max(at + k + 1);
        let line = 1 + text[..tag_start].matches('\n').count();
        let Some(offset) = attribute(&text[tag_start..tag_end], "offset") else {
            continue; // vtkio names the missing offset
        };
        let Some(body) = offset.parse::<usize>().ok().and_then(|o| data.get(o..)) else {
            return Err(damaged(
                line,
                format!(
                    "is at offset {offset}, beyond the {} bytes of appended data",
                    data.len()
                ),
            ));
        };
        compressed_header_claim(body, width).map_err(|what| damaged(line, what))?;
    }
    Ok(())
}

/// vtkio 0.7 reads no raw appended data (ParaView's default for `.vtu`): its own error
/// ("unknown variant `raw`") does not say what to do, this one does, naming the line.
pub(super) fn refuse_raw_appended(path: &Path, bytes: &[u8]) -> Result<(), MeshError> {
    let Some(a) = find_bytes(bytes, b"<AppendedData") else {
        return Ok(());
    };
    let tag_len = bytes[a..]
        .iter()
        .position(|&b| b == b'>')
        .unwrap_or(bytes.len() - a);
    if !String::from_utf8_lossy(&bytes[a..a + tag_len]).contains("encoding=\"raw\"") {
        return Ok(());
    }
    let line = 1 + bytes[..a].iter().filter(|&&b| b == b'\n').count();
    Err(perr(
        path,
        Some(line),
        "appended data in raw encoding is not read (vtkio 0.7): save the file with its \
         appended data base64-encoded (ParaView: Encode Appended Data; VTK: \
         SetEncodeAppendedData(1)) or its data inline (meshio)"
            .to_string(),
    ))
}

/// The first position of `needle` in `hay`.
fn find_bytes(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// The value of XML attribute `name="..."` in `tag`.
fn attribute<'t>(tag: &'t str, name: &str) -> Option<&'t str> {
    let key = format!(" {name}=\"");
    let from = tag.find(&key)? + key.len();
    let len = tag[from..].find('"')?;
    Some(&tag[from..from + len])
}

/// Checks the header of one compressed array, `body` being its base64 text (the header is
/// encoded on its own, the compressed blocks after it): the block count first, then the block size, the last block's size and each
/// block's compressed size, `width` bytes each, little-endian. The error says what the
/// header claims that its data cannot hold.
fn compressed_header_claim(body: &[u8], width: usize) -> Result<(), String> {
    let num = |b: &[u8]| -> u64 { b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x)) };
    // The header's first `n` bytes.
    let header = |n: usize| b64_prefix(&body[..(4 * n.div_ceil(3)).min(body.len())], n);
    let Some(nb) = header(width).map(|h| num(&h)) else {
        return Ok(()); // too short for a block count: vtkio refuses it
    };
    // vtkio reads (and allocates) as many block sizes as the count claims.
    if nb == 0 || nb > body.len() as u64 {
        return Err(format!(
            "claims {nb} blocks in {} bytes of data",
            body.len()
        ));
    }
    let full = (3 + nb as usize) * width;
    let Some(h) = header(full) else {
        return Err(format!(
            "claims {nb} blocks, more sizes than its data holds"
        ));
    };
    let field = |i: usize| num(&h[i * width..(i + 1) * width]);
    let (block, last) = (field(1), field(2));
    let compressed: u64 = (3..3 + nb as usize).map(field).fold(0, u64::saturating_add);
    let claimed = block
        .saturating_mul(nb.saturating_sub(1))
        .saturating_add(last);
    if claimed
        > compressed
            .saturating_add(1)
            .saturating_mul(INFLATE_RATIO_MAX)
    {
        return Err(format!(
            "claims {claimed} bytes in {nb} blocks from {compressed} compressed bytes (compression inflates at most {INFLATE_RATIO_MAX}x)"
        ));
    }
    Ok(())
}
