//! The bytes a message travels as over the bridge: exactly its `#[repr(C)]` layout (the one
//! `docs/PROTOCOL.md` documents), so no vic process re-encodes anything and the board's own
//! validation (version, session, order, age) applies to what crossed the link as to what came
//! over shared memory.

use crate::transport::ports::Topic;
use crate::transport::protocol::{Header, PROTOCOL_VERSION};

/// A protocol payload: a plain `#[repr(C)]` struct of integers and floats led by a [`Header`],
/// so that every bit pattern of its size is a value (no references, no enums with holes, no
/// `bool`) and its bytes may be copied in and out.
///
/// # Safety
/// Implement only for such types.
pub unsafe trait Plain: Topic {
    /// The header every payload starts with.
    fn header(&self) -> &Header;
}

macro_rules! plain {
    ($($t:ty),*) => {$(
        // SAFETY: `$t` is a `#[repr(C)]` struct of `u32`, `u64`, `f64` and arrays of them (see
        // `rt::transport::protocol`); every bit pattern is a value.
        unsafe impl Plain for $t {
            fn header(&self) -> &Header {
                &self.header
            }
        }
    )*};
}
use crate::transport::protocol::{CommandSlice, Control, Disturbance, StateMsg, Telemetry};
plain!(StateMsg, Telemetry, CommandSlice, Control, Disturbance);

/// The bytes of `value`, as laid out in memory.
pub fn encode<T: Plain>(value: &T) -> &[u8] {
    // SAFETY: `T: Plain` is plain data of `size_of::<T>()` initialised bytes (padding is spelled
    // out as `_pad` fields in the protocol types, so no byte is uninitialised).
    unsafe { std::slice::from_raw_parts((value as *const T).cast::<u8>(), size_of::<T>()) }
}

/// Why bytes from the link were not a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Malformed {
    /// Not the size of the message type.
    Size { got: usize, expected: usize },
    /// Another protocol version (the board would reject it too; the bridge does not forward it).
    Version(u32),
}

/// The message in `bytes`, when they have its exact size and this protocol's version.
pub(crate) fn decode<T: Plain>(bytes: &[u8]) -> Result<T, Malformed> {
    if bytes.len() != size_of::<T>() {
        return Err(Malformed::Size {
            got: bytes.len(),
            expected: size_of::<T>(),
        });
    }
    // SAFETY: the length is checked above, `read_unaligned` copes with any alignment, and
    // every bit pattern is a value of `T: Plain`.
    let value = unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<T>()) };
    match value.header().version {
        PROTOCOL_VERSION => Ok(value),
        v => Err(Malformed::Version(v)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_crosses_byte_for_byte() {
        let mut c = CommandSlice {
            header: Header::new(42, 7_000),
            count: 3,
            knot_dt_ns: 10_000_000,
            ..Default::default()
        };
        c.knots[2].stiffness = [12.5, -3.0];
        let bytes = encode(&c).to_vec();
        assert_eq!(bytes.len(), size_of::<CommandSlice>());
        let back: CommandSlice = decode(&bytes).unwrap();
        assert_eq!(back.header, c.header);
        assert_eq!(back.knots[2].stiffness, [12.5, -3.0]);
        assert_eq!(encode(&back), &bytes[..]);
    }

    #[test]
    fn wrong_sizes_and_versions_are_refused() {
        let s = StateMsg {
            header: Header::new(1, 1),
            ..Default::default()
        };
        let bytes = encode(&s).to_vec();
        assert_eq!(
            decode::<StateMsg>(&bytes[..bytes.len() - 1]),
            Err(Malformed::Size {
                got: bytes.len() - 1,
                expected: bytes.len()
            })
        );
        // A state's bytes are not a command.
        assert!(matches!(
            decode::<CommandSlice>(&bytes),
            Err(Malformed::Size { .. })
        ));
        let mut old = s;
        old.header.version = PROTOCOL_VERSION - 1;
        assert_eq!(
            decode::<StateMsg>(encode(&old)),
            Err(Malformed::Version(PROTOCOL_VERSION - 1))
        );
    }
}
