//! Reads fuzz input bytes as numbers, by hand rather than with the `arbitrary` crate: the
//! byte format is then fixed by this file alone (a new `arbitrary` release cannot silently
//! re-interpret the committed corpus), and the main crate's corpus-replay test needs no new
//! dev-dependency. Past the end every read returns zero, so decoding never fails.

/// A cursor over fuzz input.
pub struct Cursor<'a> {
    data: &'a [u8],
}

/// Values that break arithmetic, for [`Cursor::f64`] to pick from.
const SPECIAL: [f64; 16] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MAX,
    f64::MIN,
    f64::MIN_POSITIVE,
    -f64::MIN_POSITIVE,
    0.0,
    -0.0,
    1e300,
    -1e300,
    1e-300,
    f64::EPSILON,
    5e-324,
    1e15,
    -1e15,
];

impl<'a> Cursor<'a> {
    /// A cursor at the start of `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data }
    }

    /// Whether every byte has been read.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        let n = N.min(self.data.len());
        out[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        out
    }

    /// One byte.
    pub fn u8(&mut self) -> u8 {
        self.bytes::<1>()[0]
    }

    /// Two bytes, little-endian.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.bytes())
    }

    /// Four bytes, little-endian.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.bytes())
    }

    /// Eight bytes, little-endian.
    pub fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.bytes())
    }

    /// A number in `0..n` from one byte (`n` ≤ 256), 0 when `n` is 0.
    pub fn below(&mut self, n: usize) -> usize {
        let b = self.u8() as usize;
        if n == 0 {
            0
        } else {
            b % n
        }
    }

    /// A float: 16 special values (NaN, ±inf, extremes, subnormals), raw bits, or an i16 on a
    /// fine (1/1024, ±32) or coarse (1/16, ±2048) grid, by the first byte.
    pub fn f64(&mut self) -> f64 {
        match self.u8() {
            tag @ 0..=15 => SPECIAL[tag as usize],
            16..=23 => f64::from_bits(self.u64()),
            24..=127 => f64::from(self.u16() as i16) / 1024.0,
            _ => f64::from(self.u16() as i16) / 16.0,
        }
    }
}

/// Writes what [`Cursor`] reads, for building seed inputs.
#[derive(Default)]
pub struct Writer {
    /// The bytes so far.
    pub bytes: Vec<u8>,
}

impl Writer {
    /// One byte.
    pub fn u8(&mut self, v: u8) {
        self.bytes.push(v);
    }

    /// Two bytes, little-endian.
    pub fn u16(&mut self, v: u16) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// Eight bytes, little-endian.
    pub fn u64(&mut self, v: u64) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// `v` on the finest grid of [`Cursor::f64`] that holds it; returns what will be read back.
    pub fn f64(&mut self, v: f64) -> f64 {
        let fine = (v * 1024.0).round();
        if fine.abs() < 32767.0 {
            self.u8(24);
            self.u16(fine as i16 as u16);
            fine / 1024.0
        } else {
            let coarse = (v * 16.0).round().clamp(-32768.0, 32767.0);
            self.u8(128);
            self.u16(coarse as i16 as u16);
            coarse / 16.0
        }
    }
}
