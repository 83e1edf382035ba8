//! The CDR byte layout ROS 2 gives its messages (OMG's Common Data Representation, plain version 1):
//! a 4-byte encapsulation header (`00 01` little endian, `00 00` big endian, then two option bytes),
//! then the fields in order, each primitive aligned to its own size counted from the end of that
//! header; strings are a `u32` length that counts a closing NUL, the bytes and the NUL; sequences a
//! `u32` count and the elements; fixed arrays the elements alone.
//!
//! [`CdrReader`] reads a message's fields one by one and never panics: a message that ends early or
//! holds a length beyond its own size is a [`CdrError`] naming the byte and the field. [`CdrWriter`]
//! writes little-endian messages (what every ROS 2 machine in use writes).

/// A message that cannot be read as its type says.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("byte {offset}: {message}")]
pub struct CdrError {
    /// Byte of the message (counted from its first byte, the encapsulation header's) where reading failed.
    pub offset: usize,
    /// What was being read and why it failed.
    pub message: String,
}

/// Reads the fields of one CDR message in order.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    /// Position in `data`, past the encapsulation header from the start.
    pos: usize,
    little: bool,
}

/// Length of the encapsulation header, also where alignment is counted from.
const HEADER: usize = 4;

impl<'a> CdrReader<'a> {
    /// A reader of `data`, a whole message with its encapsulation header (plain CDR, either byte order).
    pub fn new(data: &'a [u8]) -> Result<Self, CdrError> {
        let Some(head) = data.get(..HEADER) else {
            return Err(CdrError {
                offset: 0,
                message: format!("{} bytes: shorter than the 4-byte CDR header", data.len()),
            });
        };
        let little = match (head[0], head[1]) {
            (0, 1) => true,
            (0, 0) => false,
            (a, b) => {
                return Err(CdrError {
                    offset: 0,
                    message: format!(
                        "encapsulation {a:02x} {b:02x} is not plain CDR (00 00 big endian, 00 01 little endian)"
                    ),
                })
            }
        };
        Ok(Self { data, pos: HEADER, little })
    }

    /// Byte position of the next field.
    pub fn position(&self) -> usize {
        self.pos
    }

    fn take(&mut self, n: usize, align: usize, what: &str) -> Result<&'a [u8], CdrError> {
        let rel = self.pos - HEADER;
        let pad = (align - rel % align) % align;
        let start = self.pos + pad;
        let end = start.checked_add(n).filter(|&e| e <= self.data.len()).ok_or_else(|| CdrError {
            offset: self.pos,
            message: format!("{what}: {n} bytes needed, the message ends at byte {}", self.data.len()),
        })?;
        self.pos = end;
        Ok(&self.data[start..end])
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], CdrError> {
        let b = self.take(N, N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(b);
        if !self.little {
            a.reverse();
        }
        Ok(a)
    }

    /// An `uint8` (also `char`, `byte`).
    pub fn u8(&mut self, what: &str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, what)?[0])
    }

    /// A `bool` (one byte, 0 or 1).
    pub fn bool(&mut self, what: &str) -> Result<bool, CdrError> {
        let at = self.pos;
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(CdrError { offset: at, message: format!("{what}: {v} is not a bool (0 or 1)") }),
        }
    }

    /// An `uint32`.
    pub fn u32(&mut self, what: &str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.array::<4>(what)?))
    }

    /// An `int32`.
    pub fn i32(&mut self, what: &str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.array::<4>(what)?))
    }

    /// A `float64`.
    pub fn f64(&mut self, what: &str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.array::<8>(what)?))
    }

    /// A `string`: its length counts the closing NUL, which must be there; UTF-8.
    pub fn string(&mut self, what: &str) -> Result<String, CdrError> {
        let at = self.pos;
        let n = self.u32(what)? as usize;
        if n == 0 {
            // some writers put an empty string as a bare zero length
            return Ok(String::new());
        }
        let bytes = self.take(n, 1, what)?;
        let (last, text) = bytes.split_last().unwrap_or((&0, &[]));
        if *last != 0 {
            return Err(CdrError {
                offset: at,
                message: format!("{what}: a string of {n} bytes without its closing NUL"),
            });
        }
        String::from_utf8(text.to_vec())
            .map_err(|_| CdrError { offset: at, message: format!("{what}: not UTF-8 text") })
    }

    /// The count of a sequence whose elements take `element` bytes each, checked against the bytes left
    /// (a corrupt count cannot ask for more memory than the message holds).
    pub fn sequence_len(&mut self, element: usize, what: &str) -> Result<usize, CdrError> {
        let at = self.pos;
        let n = self.u32(what)? as usize;
        let left = self.data.len() - self.pos;
        if n.saturating_mul(element.max(1)) > left {
            return Err(CdrError {
                offset: at,
                message: format!("{what}: {n} elements declared, the message holds {left} more bytes"),
            });
        }
        Ok(n)
    }

    /// A `uint8[]` sequence, borrowed from the message.
    pub fn bytes(&mut self, what: &str) -> Result<&'a [u8], CdrError> {
        let n = self.sequence_len(1, what)?;
        self.take(n, 1, what)
    }

    /// A `float64[]` sequence.
    pub fn f64_sequence(&mut self, what: &str) -> Result<Vec<f64>, CdrError> {
        let n = self.sequence_len(8, what)?;
        (0..n).map(|_| self.f64(what)).collect()
    }

    /// A `float64[N]` array.
    pub fn f64_array<const N: usize>(&mut self, what: &str) -> Result<[f64; N], CdrError> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f64(what)?;
        }
        Ok(a)
    }
}

/// Writes one little-endian CDR message, field by field.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    data: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    /// A message with its encapsulation header (little endian, no options).
    pub fn new() -> Self {
        Self { data: vec![0, 1, 0, 0] }
    }

    fn align(&mut self, n: usize) {
        while (self.data.len() - HEADER) % n != 0 {
            self.data.push(0);
        }
    }

    /// An `uint8`.
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.data.push(v);
        self
    }

    /// A `bool`.
    pub fn bool(&mut self, v: bool) -> &mut Self {
        self.u8(u8::from(v))
    }

    /// An `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.data.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.data.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float32`.
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.align(4);
        self.data.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.data.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `string` (its length counts the closing NUL).
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.data.extend_from_slice(s.as_bytes());
        self.data.push(0);
        self
    }

    /// A sequence's count (its elements follow, written by the caller).
    pub fn count(&mut self, n: usize) -> &mut Self {
        self.u32(n as u32)
    }

    /// A `uint8[]` sequence.
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.count(b.len());
        self.data.extend_from_slice(b);
        self
    }

    /// A `float64[N]` array or the elements of a `float64[]` sequence.
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for x in v {
            self.f64(*x);
        }
        self
    }

    /// The message.
    pub fn finish(self) -> Vec<u8> {
        self.data
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_come_back_as_written_with_their_alignment() {
        let mut w = CdrWriter::new();
        w.i32(-7).u32(42).string("cam0").f64(1.5).bool(true).bytes(&[1, 2, 3]).f64s(&[2.0, 3.0]);
        let data = w.finish();
        // after "cam0\0" (4 + 5 bytes at offset 8) the f64 is padded to a multiple of 8 from the header's end
        assert_eq!(data.len() - 4, 8 + 9 + 7 + 8 + 1 + 3 + 4 + 3 + 5 + 16);
        let mut r = CdrReader::new(&data).expect("header");
        assert_eq!(r.i32("a").expect("a"), -7);
        assert_eq!(r.u32("b").expect("b"), 42);
        assert_eq!(r.string("c").expect("c"), "cam0");
        assert_eq!(r.f64("d").expect("d"), 1.5);
        assert!(r.bool("e").expect("e"));
        assert_eq!(r.bytes("f").expect("f"), &[1, 2, 3]);
        assert_eq!(r.f64_array::<2>("g").expect("g"), [2.0, 3.0]);
        assert!(r.u8("past the end").is_err());
    }

    #[test]
    fn big_endian_messages_are_read_too() {
        let data = [0u8, 0, 0, 0, 0, 0, 1, 2, 0, 0, 0, 2, b'a', 0];
        let mut r = CdrReader::new(&data).expect("header");
        assert_eq!(r.u32("v").expect("v"), 258);
        assert_eq!(r.string("s").expect("s"), "a");
    }

    #[test]
    fn broken_messages_are_errors_naming_the_byte_and_field() {
        assert!(CdrReader::new(&[0, 1]).expect_err("short").message.contains("shorter than the 4-byte"));
        assert!(CdrReader::new(&[7, 7, 0, 0]).expect_err("kind").message.contains("not plain CDR"));
        // a sequence claiming four billion bytes in a message of a dozen
        let mut w = CdrWriter::new();
        w.u32(u32::MAX).u32(0);
        let data = w.finish();
        let e = CdrReader::new(&data).expect("header").bytes("data").expect_err("count");
        assert_eq!(e.offset, 4);
        assert!(e.message.contains("data: 4294967295 elements declared"), "{e}");
        // a string without its NUL, a bool of 2
        let data = [0u8, 1, 0, 0, 2, 0, 0, 0, b'a', b'b'];
        assert!(CdrReader::new(&data).expect("h").string("frame_id").expect_err("nul").message.contains("closing NUL"));
        let data = [0u8, 1, 0, 0, 2];
        assert!(CdrReader::new(&data).expect("h").bool("flag").expect_err("bool").message.contains("not a bool"));
        let e = CdrReader::new(&[0u8, 1, 0, 0, 1, 2]).expect("h").f64("x").expect_err("end");
        assert!(e.to_string().contains("x: 8 bytes needed, the message ends at byte 6"), "{e}");
    }
}
