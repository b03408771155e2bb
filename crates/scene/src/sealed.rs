//! Files that carry their own integrity check: a magic header, the payload, and a CRC-32 of
//! both. Checkpoints use it so that a truncated or bit-flipped file is reported as corrupt when
//! it is read, instead of resuming from garbage (a flipped bit in a float parameter decodes
//! fine and surfaces thousands of iterations later as "training diverged").

use std::path::Path;

use crate::error::{Result, SceneError};

/// Bytes of the trailing checksum.
const CHECKSUM_BYTES: usize = 4;

/// `magic`, then `payload`, then the little-endian CRC-32 (IEEE) of the two.
pub fn seal(magic: &[u8], payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(magic.len() + payload.len() + CHECKSUM_BYTES);
    out.extend_from_slice(magic);
    out.extend_from_slice(payload);
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// The payload of a file written by [`seal`] with the same `magic`. `what` names the kind of
/// file in the error ("a surface checkpoint"); `older` lists magics of earlier versions of the
/// format, which are refused with a message saying so.
pub fn unseal<'a>(
    path: &Path,
    bytes: &'a [u8],
    magic: &[u8],
    older: &[&[u8]],
    what: &str,
) -> Result<&'a [u8]> {
    if !bytes.starts_with(magic) {
        if older.iter().any(|m| bytes.starts_with(m)) {
            return Err(SceneError::format(
                path,
                format!(
                    "{what} from an older version of fewview; start the run again without --resume"
                ),
            ));
        }
        return Err(SceneError::format(path, format!("not {what}")));
    }
    if bytes.len() < magic.len() + CHECKSUM_BYTES {
        return Err(SceneError::format(
            path,
            format!("corrupt {what}: truncated"),
        ));
    }
    let (body, tail) = bytes.split_at(bytes.len() - CHECKSUM_BYTES);
    let stored = u32::from_le_bytes(tail.try_into().expect("four bytes"));
    if crc32fast::hash(body) != stored {
        return Err(SceneError::format(
            path,
            format!("corrupt {what}: checksum mismatch (truncated or altered)"),
        ));
    }
    Ok(&body[magic.len()..])
}

/// Writes `payload` sealed under `magic` ([`seal`]) to `path`, atomically
/// ([`crate::atomic::write_bytes`]).
pub fn write(path: &Path, magic: &[u8], payload: &[u8]) -> Result<()> {
    crate::atomic::write_bytes(path, &seal(magic, payload))
}

/// Reads a file written by [`write()`] and returns its payload, checked as [`unseal`] checks it.
pub fn read(path: &Path, magic: &[u8], older: &[&[u8]], what: &str) -> Result<Vec<u8>> {
    let mut bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    let payload_len = unseal(path, &bytes, magic, older, what)?.len();
    // The payload in place: drop the checksum, then the header.
    bytes.truncate(magic.len() + payload_len);
    bytes.drain(..magic.len());
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAGIC: &[u8] = b"TESTv2\0";

    #[test]
    fn a_sealed_payload_comes_back_unchanged() {
        let payload: Vec<u8> = (0..=255u8).collect();
        let file = seal(MAGIC, &payload);
        let back = unseal(Path::new("x"), &file, MAGIC, &[], "a test file").unwrap();
        assert_eq!(back, payload.as_slice());
    }

    #[test]
    fn a_written_file_reads_back_its_payload() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.bin");
        write(&path, MAGIC, b"payload").unwrap();
        assert_eq!(read(&path, MAGIC, &[], "a test file").unwrap(), b"payload");
        let e = read(&dir.path().join("missing"), MAGIC, &[], "a test file").unwrap_err();
        assert!(e.to_string().contains("missing"), "{e}");
    }

    #[test]
    fn every_single_bit_flip_is_caught() {
        let payload = b"parameters 0.125 0.25".to_vec();
        let file = seal(MAGIC, &payload);
        for byte in 0..file.len() {
            for bit in 0..8 {
                let mut bad = file.clone();
                bad[byte] ^= 1 << bit;
                assert!(
                    unseal(Path::new("x"), &bad, MAGIC, &[], "a test file").is_err(),
                    "flip at byte {byte} bit {bit} passed"
                );
            }
        }
    }

    #[test]
    fn truncation_and_older_versions_are_named() {
        let file = seal(MAGIC, b"abc");
        let short = &file[..file.len() - 1];
        let e = unseal(Path::new("ck.bin"), short, MAGIC, &[], "a test file").unwrap_err();
        assert!(
            e.to_string().starts_with("ck.bin: corrupt a test file"),
            "{e}"
        );
        let old = [b"TESTv1\0".as_slice(), b"payload"].concat();
        let e = unseal(
            Path::new("ck.bin"),
            &old,
            MAGIC,
            &[b"TESTv1\0"],
            "a test file",
        )
        .unwrap_err();
        assert!(e.to_string().contains("older version"), "{e}");
        let e = unseal(Path::new("ck.bin"), b"PNG", MAGIC, &[], "a test file").unwrap_err();
        assert_eq!(e.to_string(), "ck.bin: not a test file");
    }
}
