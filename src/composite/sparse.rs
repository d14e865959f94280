//! Sparse image pieces on the wire: run-length encoding of the non-empty pixels of a range, as
//! IceT does, so ranks send and blend only the pixels they covered.
//!
//! Layout (little-endian): `u32 runs`, `u32 pixels` (the range's length, which the receiver's
//! range must match), then `runs` pairs `(u32 skip, u32 len)` (empty pixels to skip, then active
//! pixels that follow), then the active pixels' bytes back to back. A range that is entirely
//! empty is 8 bytes; a dense range is 16 bytes plus its pixels. The leading skips make the
//! encoding also a bounding interval of the active pixels.

use super::pixel::Pixel;
use alloc::vec::Vec;

/// Bytes of the header of an encoded piece with `runs` runs.
///
/// ```
/// use strahl::composite::{Pixel, RgbaF32, encode, sparse::header_bytes};
/// let mut wire = Vec::new();
/// encode(&[RgbaF32::EMPTY; 8], true, &mut wire);
/// assert_eq!(wire.len(), header_bytes(0)); // all empty: only the run count and the length
/// let (a, e) = (RgbaF32([1.0; 4]), RgbaF32::EMPTY);
/// wire.clear();
/// encode(&[a, e, a], true, &mut wire);
/// assert_eq!(wire.len(), header_bytes(2) + 2 * RgbaF32::BYTES);
/// ```
pub const fn header_bytes(runs: usize) -> usize {
    8 + 8 * runs
}

/// Appends the encoding of `pixels` to `out`. With `sparse == false` the whole range is one run
/// (empty pixels are sent too), for comparison.
///
/// ```
/// use strahl::composite::{RgbaF32, Pixel, encode, decode_composite};
/// let e = RgbaF32::EMPTY;
/// let px = [e, RgbaF32([0.5; 4]), RgbaF32([0.5; 4]), e, e];
/// let mut wire = Vec::new();
/// encode(&px, true, &mut wire);
/// assert_eq!(wire.len(), 8 + 8 + 2 * 16); // one run of two pixels
/// let mut acc = [e; 5];
/// decode_composite(&wire, &mut acc, true).unwrap();
/// assert_eq!(acc, px);
/// ```
pub fn encode<P: Pixel>(pixels: &[P], sparse: bool, out: &mut Vec<u8>) {
    let start = out.len();
    out.extend_from_slice(&0u32.to_le_bytes());
    // (A range beyond `u32::MAX` pixels, which `composite` refuses, would not decode anywhere.)
    out.extend_from_slice(&u32::try_from(pixels.len()).unwrap_or(u32::MAX).to_le_bytes());
    let mut runs = 0u32;
    let mut active: Vec<(usize, usize)> = Vec::new();
    if !sparse {
        if !pixels.is_empty() {
            active.push((0, pixels.len()));
        }
    } else {
        let mut i = 0;
        while i < pixels.len() {
            while i < pixels.len() && pixels[i] == P::EMPTY {
                i += 1;
            }
            let s = i;
            while i < pixels.len() && pixels[i] != P::EMPTY {
                i += 1;
            }
            if i > s {
                active.push((s, i));
            }
        }
    }
    let mut prev = 0;
    for &(s, e) in &active {
        out.extend_from_slice(&((s - prev) as u32).to_le_bytes());
        out.extend_from_slice(&((e - s) as u32).to_le_bytes());
        prev = e;
        runs += 1;
    }
    for &(s, e) in &active {
        out.extend_from_slice(bytemuck::cast_slice(&pixels[s..e]));
    }
    out[start..start + 4].copy_from_slice(&runs.to_le_bytes());
}

/// Why an encoded piece could not be read.
///
/// ```
/// use strahl::composite::{DecodeError, Pixel, RgbaF32, decode_composite, encode};
/// let mut wire = Vec::new();
/// encode(&[RgbaF32([1.0; 4]); 3], true, &mut wire);
/// let (mut two, mut three) = ([RgbaF32::EMPTY; 2], [RgbaF32::EMPTY; 3]);
/// assert_eq!(decode_composite(&wire, &mut two, true), Err(DecodeError::LengthMismatch));
/// assert_eq!(decode_composite(&wire[..wire.len() - 1], &mut three, true), Err(DecodeError::Truncated));
/// wire.push(0);
/// assert_eq!(decode_composite(&wire, &mut three, true), Err(DecodeError::TrailingBytes));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// The message is shorter than its header says.
    Truncated,
    /// The runs reach past the end of the range they are composited into.
    OutOfRange,
    /// The piece was encoded from a range of another length than the one it is composited into
    /// (ranks with images of different sizes).
    LengthMismatch,
    /// Bytes are left over after the last pixel.
    TrailingBytes,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Truncated => "compositing message is truncated",
            Self::OutOfRange => "compositing message runs past its pixel range",
            Self::LengthMismatch => "compositing message is for a pixel range of another length",
            Self::TrailingBytes => "compositing message has trailing bytes",
        })
    }
}

impl core::error::Error for DecodeError {}

/// Composites an encoded piece into `acc` (the same pixel range): the piece's pixels are behind
/// `acc` (`acc_in_front`) or in front of it. Skipped pixels are left untouched (they are
/// [`Pixel::EMPTY`], the identity). Never panics on malformed input.
///
/// ```
/// use strahl::composite::{RgbaF32, decode_composite, encode};
/// let (red, green) = (RgbaF32([0.5, 0.0, 0.0, 0.5]), RgbaF32([0.0, 1.0, 0.0, 1.0]));
/// let mut wire = Vec::new();
/// encode(&[green], true, &mut wire);
/// let mut acc = [red];
/// decode_composite(&wire, &mut acc, true).unwrap(); // green behind half-transparent red
/// assert_eq!(acc, [RgbaF32([0.5, 0.5, 0.0, 1.0])]);
/// let mut acc = [red];
/// decode_composite(&wire, &mut acc, false).unwrap(); // opaque green in front hides red
/// assert_eq!(acc, [green]);
/// assert!(decode_composite(&[9], &mut acc, true).is_err());
/// ```
pub fn decode_composite<P: Pixel>(wire: &[u8], acc: &mut [P], acc_in_front: bool) -> Result<(), DecodeError> {
    let word = |at: usize| -> Result<usize, DecodeError> {
        let b = wire.get(at..at + 4).ok_or(DecodeError::Truncated)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let runs = word(0)?;
    if word(4)? != acc.len() {
        return Err(DecodeError::LengthMismatch);
    }
    let header = runs
        .checked_mul(8)
        .and_then(|r| r.checked_add(8))
        .ok_or(DecodeError::Truncated)?;
    if header > wire.len() {
        return Err(DecodeError::Truncated);
    }
    let mut data = header;
    let mut at = 0usize;
    let mut scratch: Vec<P> = Vec::new();
    for r in 0..runs {
        let (skip, len) = (word(8 + 8 * r)?, word(12 + 8 * r)?);
        let s = at.checked_add(skip).ok_or(DecodeError::OutOfRange)?;
        let e = s.checked_add(len).ok_or(DecodeError::OutOfRange)?;
        if e > acc.len() {
            return Err(DecodeError::OutOfRange);
        }
        // `size_of`, not the overridable `P::BYTES`: what `encode` wrote, and what the copy
        // below needs. `len <= acc.len()`, so it cannot overflow.
        let bytes = len * core::mem::size_of::<P>();
        let src = wire.get(data..data + bytes).ok_or(DecodeError::Truncated)?;
        // The wire is not aligned for `P`: copy into an aligned scratch buffer.
        scratch.clear();
        scratch.resize(len, P::EMPTY);
        bytemuck::cast_slice_mut::<P, u8>(&mut scratch).copy_from_slice(src);
        if acc_in_front {
            P::composite_behind(&mut acc[s..e], &scratch);
        } else {
            P::composite_in_front(&mut acc[s..e], &scratch);
        }
        data += bytes;
        at = e;
    }
    if data != wire.len() {
        return Err(DecodeError::TrailingBytes);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::composite::{DepthPixel, RgbaF32};
    use alloc::vec;

    #[test]
    fn round_trip_sparse_and_dense() {
        let e = DepthPixel::EMPTY;
        let a = DepthPixel::new(1.0, 7);
        for px in [vec![], vec![e], vec![a], vec![e, a, a, e, a], vec![a; 9], vec![e; 9]] {
            for sparse in [true, false] {
                let mut wire = Vec::new();
                encode(&px, sparse, &mut wire);
                let mut acc = vec![e; px.len()];
                decode_composite(&wire, &mut acc, true).unwrap();
                assert_eq!(acc, px);
            }
        }
        let mut wire = Vec::new();
        encode(&[e; 100], true, &mut wire);
        assert_eq!(wire.len(), 8);
    }

    #[test]
    fn malformed_messages_are_errors() {
        let mut acc = [RgbaF32::EMPTY; 4];
        assert_eq!(decode_composite(&[], &mut acc, true), Err(DecodeError::Truncated));
        assert_eq!(
            decode_composite(&[1, 0, 0, 0], &mut acc, true),
            Err(DecodeError::Truncated)
        );
        let mut wire = Vec::new();
        encode(&[RgbaF32([1.0; 4]); 5], true, &mut wire);
        assert_eq!(
            decode_composite(&wire, &mut acc, true),
            Err(DecodeError::LengthMismatch)
        );
        // The same runs with a header that claims 4 pixels: they reach past the range.
        wire[4..8].copy_from_slice(&4u32.to_le_bytes());
        assert_eq!(decode_composite(&wire, &mut acc, true), Err(DecodeError::OutOfRange));
        let mut wire = Vec::new();
        encode(&[RgbaF32([1.0; 4]); 4], true, &mut wire);
        wire.push(0);
        assert_eq!(decode_composite(&wire, &mut acc, true), Err(DecodeError::TrailingBytes));
        wire.truncate(wire.len() - 5);
        assert_eq!(decode_composite(&wire, &mut acc, true), Err(DecodeError::Truncated));
        // A huge run count must not allocate or overflow.
        assert_eq!(
            decode_composite(&[255, 255, 255, 255], &mut acc, true),
            Err(DecodeError::Truncated)
        );
        let mut huge = vec![1, 0, 0, 0, 4, 0, 0, 0];
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(decode_composite(&huge, &mut acc, true), Err(DecodeError::OutOfRange));
    }
}
