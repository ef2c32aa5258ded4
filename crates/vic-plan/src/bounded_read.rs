//! Reading the user's files with a size limit: a scenario or a plan is read whole, so a path to
//! a device or a huge file (`--config /dev/zero`) must be refused after a bounded read, not eat
//! the memory.

use std::io::Read;
use std::path::Path;

/// The largest scenario file (TOML) read: 1 MiB, a thousand times the shipped ones.
pub const MAX_SCENARIO_BYTES: u64 = 1 << 20;

/// The largest plan file (JSON) read: 64 MiB. The shipped plans are 40–50 KB; a plan of 10,000
/// knots with the feedback gains of the VSA arm is about 10 MB.
pub const MAX_PLAN_BYTES: u64 = 64 << 20;

/// The bytes of the file at `path`, refused (`InvalidData`, saying the limit) when it holds more
/// than `limit` bytes; at most `limit + 1` bytes are ever read.
pub fn read_at_most(path: &Path, limit: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {}, the most a {what} may be", size(limit)),
        ));
    }
    Ok(bytes)
}

/// [`read_at_most`] as UTF-8 text.
pub fn read_text_at_most(path: &Path, limit: u64, what: &str) -> std::io::Result<String> {
    String::from_utf8(read_at_most(path, limit, what)?)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))
}

/// "1 MiB", "64 MiB", "100 bytes".
fn size(bytes: u64) -> String {
    match bytes {
        b if b >= 1 << 20 && b % (1 << 20) == 0 => format!("{} MiB", b >> 20),
        b => format!("{b} bytes"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_file_is_refused_after_a_bounded_read() {
        let e =
            read_at_most(Path::new("/dev/zero"), MAX_SCENARIO_BYTES, "scenario file").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidData);
        assert_eq!(
            e.to_string(),
            "larger than 1 MiB, the most a scenario file may be"
        );
    }

    #[test]
    fn a_file_at_the_limit_is_read() {
        let path = std::env::temp_dir().join(format!("vic-bounded-{}", std::process::id()));
        std::fs::write(&path, [b'a'; 100]).unwrap();
        assert_eq!(read_at_most(&path, 100, "file").unwrap().len(), 100);
        let e = read_at_most(&path, 99, "file").unwrap_err();
        assert!(e.to_string().contains("99 bytes"), "{e}");
        std::fs::remove_file(path).unwrap();
    }
}
