//! The length of a classic CAN frame on the wire, in bits, and its time at a bit rate
//! (ISO 11898-1 classic CAN 2.0A/2.0B data and remote frames; CAN FD worst case only).
//!
//! A frame's bits: SOF, arbitration and control fields, data, CRC-15 sequence — the region the
//! transmitter stuffs (after five equal bits one bit of the opposite value, which itself starts
//! the next run) — then CRC delimiter, ACK slot, ACK delimiter, 7 EOF bits (never stuffed), then
//! the 3-bit intermission before the next SOF may follow.
//!
//! * [`exact`]: builds the actual bit sequence (CRC computed) and counts its stuff bits.
//! * [`worst_case_bits`]: the bound of Davis, Burns, Bril, Lukkien, "Controller Area Network
//!   (CAN) schedulability analysis: refuted, revisited and revised", Real-Time Systems 35
//!   (2007), eq. (2): `C = (g + 8s + 13 + ⌊(g + 8s − 1)/4⌋)` bit times with g = 34 stuffable
//!   bits of overhead for 11-bit identifiers and g = 54 for 29-bit ones, i.e.
//!   `8s + 47 + ⌊(34 + 8s − 1)/4⌋` and `8s + 67 + ⌊(54 + 8s − 1)/4⌋` (the 13 are CRC delimiter,
//!   ACK, ACK delimiter, EOF and the 3-bit intermission).
//!
//! Every count here includes the intermission ([`INTERMISSION_BITS`]), as the bound does: it is
//! the spacing from one SOF to the next on a busy bus. The end of the frame proper (the last EOF
//! bit, where the frame is valid for the transmitter) is [`FrameBits::to_eof`].

use crate::frame::CanFrame;

/// Intermission after EOF: the bus is not free for the next SOF before it has passed.
pub const INTERMISSION_BITS: u32 = 3;
/// CRC delimiter 1, ACK slot 1, ACK delimiter 1, EOF 7: never stuffed.
pub const TRAILER_BITS: u32 = 10;
/// CRC-15 generator x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1 (ISO 11898-1).
pub const CRC15_POLY: u16 = 0x4599;

/// What [`exact`] found for one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameBits {
    /// SOF through the last CRC bit, before stuffing.
    pub unstuffed: u32,
    /// Stuff bits the transmitter inserts into that region.
    pub stuff_bits: u32,
    /// The CRC-15 sequence of the frame.
    pub crc: u16,
}

impl FrameBits {
    /// Bits from SOF through the end of the intermission (SOF-to-SOF spacing on a busy bus).
    pub const fn total(&self) -> u32 {
        self.unstuffed + self.stuff_bits + TRAILER_BITS + INTERMISSION_BITS
    }
    /// Bits from SOF through the last EOF bit.
    pub const fn to_eof(&self) -> u32 {
        self.unstuffed + self.stuff_bits + TRAILER_BITS
    }
}

/// Up to 118 bits (extended id, 8 data bytes, CRC) packed MSB first.
struct BitSeq {
    bits: u128,
    len: u32,
}

impl BitSeq {
    const fn push(mut self, value: u64, n: u32) -> Self {
        self.bits = (self.bits << n) | (value as u128 & ((1u128 << n) - 1));
        self.len += n;
        self
    }
    const fn bit(&self, i: u32) -> bool {
        (self.bits >> (self.len - 1 - i)) & 1 == 1
    }
}

/// CRC-15 of the first `n` bits of `seq` (shift register as in ISO 11898-1: CRC_NXT = bit XOR
/// CRC_RG(14); shift left; XOR the generator if CRC_NXT).
const fn crc15_of(seq: &BitSeq, n: u32) -> u16 {
    let mut crc: u16 = 0;
    let mut i = 0;
    while i < n {
        let next = seq.bit(i) ^ (crc & 0x4000 != 0);
        crc = (crc << 1) & 0x7FFF;
        if next {
            crc ^= CRC15_POLY;
        }
        i += 1;
    }
    crc
}

/// CRC-15/CAN of a byte string, MSB first (the CRC catalogue's "CRC-15/CAN": check value of
/// `b"123456789"` is 0x059E). The frame's CRC is this over its bit sequence (not byte aligned).
pub const fn crc15_bytes(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    let mut k = 0;
    while k < bytes.len() {
        let mut b = 0;
        while b < 8 {
            let bit = (bytes[k] >> (7 - b)) & 1 == 1;
            let next = bit ^ (crc & 0x4000 != 0);
            crc = (crc << 1) & 0x7FFF;
            if next {
                crc ^= CRC15_POLY;
            }
            b += 1;
        }
        k += 1;
    }
    crc
}

/// Stuff bits inserted into the first `n` bits of `seq`: after five equal bits one of the
/// opposite value, which counts as the first of the next run; a run of five that ends on the
/// last CRC bit is still followed by a stuff bit.
const fn stuff_count(seq: &BitSeq, n: u32) -> u32 {
    let mut stuffed = 0;
    let mut last = seq.bit(0);
    let mut run = 1;
    let mut i = 1;
    while i < n {
        let b = seq.bit(i);
        if b == last {
            run += 1;
        } else {
            last = b;
            run = 1;
        }
        if run == 5 {
            stuffed += 1;
            last = !last;
            run = 1;
        }
        i += 1;
    }
    // A run of five can also end on the very first bits only if n >= 5; handled above.
    stuffed
}

/// The exact bits of a classic frame given by its fields: `len` is the DLC (0..=8, clamped);
/// a remote frame (`rtr`) carries the DLC but no data field. `id` is masked to its width.
pub const fn exact_fields(
    id: u32,
    extended: bool,
    rtr: bool,
    len: u8,
    data: &[u8; 8],
) -> FrameBits {
    let dlc = if len > 8 { 8 } else { len };
    let mut s = BitSeq { bits: 0, len: 0 };
    s = s.push(0, 1); // SOF, dominant
    if extended {
        let id = id & 0x1FFF_FFFF;
        s = s.push((id >> 18) as u64, 11); // base identifier
        s = s.push(1, 1); // SRR, recessive
        s = s.push(1, 1); // IDE, recessive: extended
        s = s.push((id & 0x3FFFF) as u64, 18); // identifier extension
        s = s.push(rtr as u64, 1);
        s = s.push(0, 2); // r1, r0
    } else {
        s = s.push((id & 0x7FF) as u64, 11);
        s = s.push(rtr as u64, 1);
        s = s.push(0, 1); // IDE, dominant: standard
        s = s.push(0, 1); // r0
    }
    s = s.push(dlc as u64, 4);
    if !rtr {
        let mut k = 0;
        while k < dlc as usize {
            s = s.push(data[k] as u64, 8);
            k += 1;
        }
    }
    let covered = s.len;
    let crc = crc15_of(&s, covered);
    s = s.push(crc as u64, 15);
    FrameBits {
        unstuffed: s.len,
        stuff_bits: stuff_count(&s, s.len),
        crc,
    }
}

/// The exact bits of `frame` on the wire (see [`exact_fields`]).
pub const fn exact(frame: &CanFrame) -> FrameBits {
    exact_fields(
        frame.id(),
        frame.is_extended(),
        frame.is_rtr(),
        frame.len() as u8,
        frame.raw_data(),
    )
}

/// Davis et al. (2007) eq. (2): the most bits a frame with `data_len` data bytes (0 for a
/// remote frame) can take on the wire, stuffing included, plus the 3-bit intermission.
pub const fn worst_case_bits(extended: bool, data_len: u8) -> u32 {
    let n = if data_len > 8 { 8 } else { data_len } as u32;
    let g = if extended { 54 } else { 34 };
    g + 8 * n + 13 + (g + 8 * n - 1) / 4
}

/// Bits without any stuff bit (the best case), intermission included: 47 + 8n / 67 + 8n.
pub const fn unstuffed_bits(extended: bool, data_len: u8) -> u32 {
    let n = if data_len > 8 { 8 } else { data_len } as u32;
    (if extended { 67 } else { 47 }) + 8 * n
}

/// CAN FD worst case, one bit rate throughout (the Linux kernel's
/// `can_frame_bits(true, is_eff, true, true, len)` of `include/linux/can/length.h`): header and
/// data dynamically stuffed (⌊(k − 1)/4⌋ for k bits), the stuff count, CRC-17 (≤ 16 data bytes)
/// or CRC-21 field with its fixed stuff bits, ACK, EOF, intermission. `data_len` is the FD
/// payload length (0..=64).
pub const fn fd_worst_case_bits(extended: bool, data_len: u8) -> u32 {
    let n = if data_len > 64 { 64 } else { data_len } as u32;
    let header = if extended { 41 } else { 22 };
    let dynamic = header + 8 * n;
    let crc_field = if n <= 16 { 28 } else { 33 };
    dynamic + (dynamic - 1) / 4 + crc_field + 9 + INTERMISSION_BITS
}

/// CAN FD worst case with a bit rate switch: (bits at the nominal rate, bits at the data rate).
/// The data phase runs from the sample point of BRS to that of the CRC delimiter; counted here
/// from ESI through the CRC sequence (with their stuff and fixed stuff bits), the rest — SOF to
/// BRS with its stuff bits, CRC delimiter, ACK, EOF, intermission — at the nominal rate.
pub const fn fd_worst_case_split(extended: bool, data_len: u8) -> (u32, u32) {
    let total = fd_worst_case_bits(extended, data_len);
    // SOF, id, RRS, IDE, FDF, res, BRS (+ SRR and the id extension when extended).
    let arb = if extended { 36 } else { 17 };
    let arb_stuffed = arb + (arb - 1) / 4;
    let nominal = arb_stuffed + 1 + 9 + INTERMISSION_BITS; // + CRC delimiter, ACK, ACK del, EOF
    (nominal, total - nominal)
}

/// Time of `bits` at `bitrate_bps`, ns (rounded down; exact for the usual rates, whose bit
/// time is a whole number of ns).
pub const fn bits_to_ns(bits: u32, bitrate_bps: u32) -> u64 {
    bits as u64 * 1_000_000_000 / bitrate_bps as u64
}

/// Time of a CAN FD frame with a bit rate switch: nominal-phase bits at `nominal_bps`, data-phase
/// bits at `data_bps` ([`fd_worst_case_split`]).
pub const fn fd_worst_case_ns(
    extended: bool,
    data_len: u8,
    nominal_bps: u32,
    data_bps: u32,
) -> u64 {
    let (nominal, data) = fd_worst_case_split(extended, data_len);
    bits_to_ns(nominal, nominal_bps) + bits_to_ns(data, data_bps)
}
