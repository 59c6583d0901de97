//! The zipped GenICam file of a camera's manifest: the one XML file inside a ZIP archive.
//!
//! In: the bytes of a ZIP archive (as a USB3 Vision manifest entry of file type 1 holds it).
//! Out: the bytes of its first file whose name ends in `.xml` (else its first file), stored or
//! deflated, checked against the archive's CRC-32 and size; or one line saying what is wrong.
//! Encrypted entries, ZIP64 archives and compression methods other than stored (0) and deflate
//! (8) are refused by name.

/// Largest XML accepted (bytes): the largest camera descriptions are a few MB.
pub const MAX_XML: usize = 64 << 20;

const EOCD: u32 = 0x0605_4b50;
const CENTRAL: u32 = 0x0201_4b50;
const LOCAL: u32 = 0x0403_4b50;

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// CRC-32 (IEEE, as ZIP uses it).
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// The XML file of a ZIP archive (see the module doc).
pub fn xml_from_zip(zip: &[u8]) -> Result<Vec<u8>, String> {
    let bad = |what: &str| format!("zipped GenICam file: {what}");
    // The end record is the last 22 bytes unless a comment follows it (up to 64 KiB).
    let lowest = zip.len().saturating_sub(22 + 0xFFFF);
    let eocd = (lowest..=zip.len().saturating_sub(22))
        .rev()
        .find(|&i| u32_at(zip, i) == Some(EOCD))
        .ok_or_else(|| bad("no end of central directory"))?;
    let entries = u16_at(zip, eocd + 10).ok_or_else(|| bad("truncated end record"))? as usize;
    let mut at = u32_at(zip, eocd + 16).ok_or_else(|| bad("truncated end record"))? as usize;
    if at == 0xFFFF_FFFF {
        return Err(bad("ZIP64 archives are not supported"));
    }
    let mut first = None;
    let mut xml = None;
    for _ in 0..entries {
        if u32_at(zip, at) != Some(CENTRAL) {
            return Err(bad("broken central directory"));
        }
        let field = |off: usize| u16_at(zip, at + off).ok_or_else(|| bad("truncated central directory"));
        let (flags, method) = (field(8)?, field(10)?);
        let crc = u32_at(zip, at + 16).ok_or_else(|| bad("truncated central directory"))?;
        let packed = u32_at(zip, at + 20).ok_or_else(|| bad("truncated central directory"))? as usize;
        let size = u32_at(zip, at + 24).ok_or_else(|| bad("truncated central directory"))? as usize;
        let (name_len, extra_len, comment_len) = (field(28)? as usize, field(30)? as usize, field(32)? as usize);
        let local = u32_at(zip, at + 42).ok_or_else(|| bad("truncated central directory"))? as usize;
        let name = zip
            .get(at + 46..at + 46 + name_len)
            .ok_or_else(|| bad("truncated file name"))?;
        let entry = (flags, method, crc, packed, size, local);
        if first.is_none() {
            first = Some(entry);
        }
        if xml.is_none() && name.to_ascii_lowercase().ends_with(b".xml") {
            xml = Some(entry);
        }
        at += 46 + name_len + extra_len + comment_len;
    }
    let (flags, method, crc, packed, size, local) = xml.or(first).ok_or_else(|| bad("the archive is empty"))?;
    if flags & 1 != 0 {
        return Err(bad("the file is encrypted"));
    }
    if size > MAX_XML {
        return Err(bad(&format!("the file has {size} bytes, more than {MAX_XML}")));
    }
    if u32_at(zip, local) != Some(LOCAL) {
        return Err(bad("broken local header"));
    }
    let start = local
        + 30
        + u16_at(zip, local + 26).ok_or_else(|| bad("truncated local header"))? as usize
        + u16_at(zip, local + 28).ok_or_else(|| bad("truncated local header"))? as usize;
    let data = zip
        .get(start..start + packed)
        .ok_or_else(|| bad("truncated file data"))?;
    let out = match method {
        0 => data.to_vec(),
        8 => miniz_oxide::inflate::decompress_to_vec_with_limit(data, size)
            .map_err(|e| bad(&format!("cannot inflate: {e:?}")))?,
        m => {
            return Err(bad(&format!(
                "compression method {m} (only stored and deflate are read)"
            )))
        }
    };
    if out.len() != size || crc32(&out) != crc {
        return Err(bad("size or CRC-32 does not match: the file is damaged"));
    }
    Ok(out)
}
