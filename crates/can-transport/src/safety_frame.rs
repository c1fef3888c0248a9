//! Doubled safety frame ("safety heartbeat") after CiA 304's SRDO: every message is sent twice,
//! the data on COB-ID `n` and its bitwise inverse on the adjacent COB-ID `n + 1`. A consumer
//! accepts a message only as a valid PAIR: both frames 8 bytes, the second the exact bit-inverse
//! of the first, received within the pair window (CiA 304's SRVT, safeguard reception
//! validation time). Everything else is an error the consumer must treat as "not safe".
//!
//! The safety monitor (crates/safety-monitor) sends one pair every cycle (15 ms); the drives and
//! drive-io (`drive_bus::safety_watch`) brake when no valid pair with state [`SafetyState::Run`]
//! arrived within the validation time (CiA 304's SCT, safety cycle time; e.g. 50 ms), so a dead
//! or hung monitor stops the robot.
//!
//! Payload (both frames, little endian; the inverted frame carries `!byte` for every byte),
//! protocol version 2 (it added the reset epoch):
//!
//! | byte | content                                                                  |
//! |------|--------------------------------------------------------------------------|
//! | 0    | protocol version (high nibble, [`PROTOCOL_VERSION`]) and state (low nibble: 0x1 = RUN, motion permitted; 0x2 = STOP, e-stop) |
//! | 1    | cause code of the latched trip (0 = none)                                |
//! | 2..4 | counter u16, +1 per pair sent, wrapping (stuck/repeated data is detected)|
//! | 4..8 | reset epoch u32: the monitor instance (a random nonce drawn at its start) in the high 16 bits, the number of operator resets that instance verified and accepted (ISO 13849-1 §5.2.2 manual reset) in the low 16 bits ([`reset_epoch`]); consumers leave an inhibit only on a reset they have not acted on |
//!
//! Version 1 (state in byte 0 as 0x01/0x02, u32 counter, cable, version in byte 7) is refused:
//! its byte 0 has version nibble 0. The cable of a trip is no longer on the wire (the monitor's
//! trip log and its iceoryx2 e-stop event carry it).
//!
//! Default COB-IDs: 0x101 / 0x102, the CiA 304 default pair of SRDO 1 (0x0FF + 2n - 1 and
//! 0x100 + 2n); they do not collide with the CiA 301 predefined connection set (EMCY 0x081..0x0FF,
//! TIME 0x100, TPDO1 0x181..).
//!
//! Nothing here panics or allocates, whatever frame arrives.

use crate::frame::CanFrame;

/// COB-ID of the normal (non-inverted) frame of the default pair (SRDO 1).
pub const DEFAULT_COB_ID: u16 = 0x101;
/// Protocol version carried in the high nibble of byte 0.
pub const PROTOCOL_VERSION: u8 = 2;

const STATE_RUN: u8 = 0x01;
const STATE_STOP: u8 = 0x02;

/// What the monitor tells the drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SafetyState {
    /// The monitor runs and sees no fault: motion is permitted.
    Run,
    /// The monitor has tripped (latched e-stop): brake, do not enable.
    Stop,
}

/// One safety heartbeat message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SafetyHeartbeat {
    pub state: SafetyState,
    /// Cause code of the latched trip (monitor-specific; 0 = none).
    pub cause: u8,
    /// +1 for every pair the producer sends (wrapping).
    pub counter: u16,
    /// The monitor's reset epoch: +1 for every accepted operator reset (wrapping; compare with
    /// [`epoch_newer`]).
    pub epoch: u32,
}

/// The reset-epoch order, shared with motion-core's IPC reset gate (one home: `crs-limits`).
pub use crs_limits::epoch_newer;
/// The epoch's structure (monitor instance | reset count) and which epoch releases what.
pub use crs_limits::reset_epoch;

impl SafetyHeartbeat {
    /// The 8 data bytes of the normal frame.
    pub fn to_bytes(&self) -> [u8; 8] {
        let c = self.counter.to_le_bytes();
        let e = self.epoch.to_le_bytes();
        let s = match self.state {
            SafetyState::Run => STATE_RUN,
            SafetyState::Stop => STATE_STOP,
        };
        [
            (PROTOCOL_VERSION << 4) | s,
            self.cause,
            c[0],
            c[1],
            e[0],
            e[1],
            e[2],
            e[3],
        ]
    }

    /// Parses the 8 data bytes of a normal frame.
    pub fn from_bytes(d: &[u8; 8]) -> Result<Self, PairError> {
        if d[0] >> 4 != PROTOCOL_VERSION {
            return Err(PairError::Version(d[0] >> 4));
        }
        let state = match d[0] & 0x0F {
            STATE_RUN => SafetyState::Run,
            STATE_STOP => SafetyState::Stop,
            other => return Err(PairError::UnknownState(other)),
        };
        Ok(Self {
            state,
            cause: d[1],
            counter: u16::from_le_bytes([d[2], d[3]]),
            epoch: u32::from_le_bytes([d[4], d[5], d[6], d[7]]),
        })
    }
}

/// Why a received frame / pair is not a valid safety message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairError {
    /// A frame on one of the two COB-IDs with DLC != 8, or a remote frame.
    Malformed { cob_id: u16, len: u8 },
    /// A normal frame arrived while the previous one still waited for its inverse.
    MissingInverse,
    /// An inverted frame arrived without a preceding normal frame.
    UnexpectedInverse,
    /// The inverted frame is not the bitwise inverse of the normal frame.
    InverseMismatch,
    /// The inverted frame arrived later than the pair window after the normal frame.
    PairWindow { gap_ns: u64 },
    /// Unknown state byte.
    UnknownState(u8),
    /// Unknown protocol version byte.
    Version(u8),
}

impl core::fmt::Display for PairError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Malformed { cob_id, len } => {
                write!(f, "malformed safety frame {cob_id:#05x} (len {len})")
            }
            Self::MissingInverse => f.write_str("normal frame without its inverse"),
            Self::UnexpectedInverse => f.write_str("inverted frame without a normal frame"),
            Self::InverseMismatch => f.write_str("inverted frame is not the bit-inverse"),
            Self::PairWindow { gap_ns } => {
                write!(f, "pair incomplete within the window ({gap_ns} ns)")
            }
            Self::UnknownState(s) => write!(f, "unknown state byte {s:#04x}"),
            Self::Version(v) => write!(f, "unknown protocol version {v}"),
        }
    }
}

/// The two frames of one message: `[normal on cob_id, inverted on cob_id + 1]`.
/// `cob_id` must be an odd 11-bit id below 0x7FF so the pair fits (the default 0x101 does); it is
/// masked to 11 bits otherwise.
pub fn encode(msg: &SafetyHeartbeat, cob_id: u16) -> [CanFrame; 2] {
    let d = msg.to_bytes();
    let mut inv = [0u8; 8];
    for (o, b) in inv.iter_mut().zip(d) {
        *o = !b;
    }
    [
        CanFrame::new_std_lossy(cob_id, &d),
        CanFrame::new_std_lossy(cob_id.wrapping_add(1), &inv),
    ]
}

/// Checks a complete pair (normal, inverted) without timing.
pub fn decode_pair(
    normal: &CanFrame,
    inverted: &CanFrame,
    cob_id: u16,
) -> Result<SafetyHeartbeat, PairError> {
    let n = data8(normal, cob_id)?;
    let i = data8(inverted, cob_id.wrapping_add(1))?;
    check_inverse(&n, &i)?;
    SafetyHeartbeat::from_bytes(&n)
}

fn data8(f: &CanFrame, expect_id: u16) -> Result<[u8; 8], PairError> {
    if f.is_extended() || f.id() != u32::from(expect_id) || f.is_rtr() || f.len() != 8 {
        return Err(PairError::Malformed {
            cob_id: f.id() as u16,
            len: f.len() as u8,
        });
    }
    let mut d = [0u8; 8];
    d.copy_from_slice(f.data());
    Ok(d)
}

fn check_inverse(n: &[u8; 8], i: &[u8; 8]) -> Result<(), PairError> {
    if n.iter().zip(i).all(|(a, b)| *a == !*b) {
        Ok(())
    } else {
        Err(PairError::InverseMismatch)
    }
}

/// Consumer side: pairs frames as they arrive (any order of unrelated traffic in between).
#[derive(Debug, Clone)]
pub struct PairReceiver {
    cob_id: u16,
    window_ns: u64,
    pending: Option<([u8; 8], u64)>,
}

impl PairReceiver {
    /// Receiver for the pair `cob_id` / `cob_id + 1`; the inverse must follow within `window_ns`.
    pub fn new(cob_id: u16, window_ns: u64) -> Self {
        Self {
            cob_id,
            window_ns,
            pending: None,
        }
    }

    pub fn cob_id(&self) -> u16 {
        self.cob_id
    }

    /// True if `frame` uses one of the pair's COB-IDs (standard frame).
    pub fn is_safety_frame(&self, frame: &CanFrame) -> bool {
        !frame.is_extended()
            && (frame.id() == u32::from(self.cob_id)
                || frame.id() == u32::from(self.cob_id.wrapping_add(1)))
    }

    /// Feeds one received frame at `now_ns`. `None`: not a safety frame, or the first half of a
    /// pair. `Some(Ok)`: a valid pair completed. `Some(Err)`: the consumer must go safe.
    pub fn on_frame(
        &mut self,
        frame: &CanFrame,
        now_ns: u64,
    ) -> Option<Result<SafetyHeartbeat, PairError>> {
        self.on_frame_raw(frame, now_ns)
            .map(|r| r.and_then(|n| SafetyHeartbeat::from_bytes(&n)))
    }

    /// As [`PairReceiver::on_frame`], returning the 8 data bytes of a valid pair unparsed (the
    /// configuration signature pair, [`ConfigSignature`], uses the same doubling).
    pub fn on_frame_raw(
        &mut self,
        frame: &CanFrame,
        now_ns: u64,
    ) -> Option<Result<[u8; 8], PairError>> {
        if !self.is_safety_frame(frame) {
            return None;
        }
        let id = frame.id() as u16;
        if frame.is_rtr() || frame.len() != 8 {
            self.pending = None;
            return Some(Err(PairError::Malformed {
                cob_id: id,
                len: frame.len() as u8,
            }));
        }
        let mut d = [0u8; 8];
        d.copy_from_slice(frame.data());
        if id == self.cob_id {
            // A new normal frame replaces a pending one; the lost pair is an error.
            let had = self.pending.replace((d, now_ns)).is_some();
            return had.then_some(Err(PairError::MissingInverse));
        }
        let Some((n, t0)) = self.pending.take() else {
            return Some(Err(PairError::UnexpectedInverse));
        };
        let gap_ns = now_ns.saturating_sub(t0);
        if gap_ns > self.window_ns {
            return Some(Err(PairError::PairWindow { gap_ns }));
        }
        Some(check_inverse(&n, &d).map(|()| n))
    }
}

/// Kind nibble of the configuration signature pair (byte 0 low nibble).
const KIND_CONFIG: u8 = 0x03;

/// COB-ID of the normal frame of the configuration signature pair for a heartbeat on `cob_id`:
/// the next SRDO pair (`cob_id + 2`, inverse on `cob_id + 3`; 0x103/0x104 = CiA 304 SRDO 2).
pub fn config_cob_id(cob_id: u16) -> u16 {
    cob_id.wrapping_add(2)
}

/// The SRDO communication parameters of the safety heartbeat: what producer and consumers must
/// agree on (CiA 304 objects 0x1301..: COB-IDs, refresh time, SCT, SRVT). Each side computes
/// [`SrdoParams::crc`] from ITS OWN configuration; the producer announces its CRC in the
/// configuration signature pair and a consumer whose CRC differs never permits motion (CiA 304
/// keeps the signature in 0x13FF and refuses to go operational on a mismatch).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SrdoParams {
    /// Normal frame of the heartbeat pair (inverse on + 1, signature pair on + 2 / + 3).
    pub cob_id: u16,
    /// Producer refresh time (the monitor's cycle), ms.
    pub refresh_time_ms: u32,
    /// Safeguard cycle time (consumer validation time), ms.
    pub validation_time_ms: u32,
    /// Safeguard reception validation time (pair window), ms.
    pub pair_window_ms: u32,
}

impl SrdoParams {
    /// CRC-16/CCITT (polynomial 0x1021, initial value 0, CiA 304's checksum algorithm) over the
    /// canonical little-endian bytes: version, COB-ID u16, refresh u32, SCT u32, SRVT u32.
    pub fn crc(&self) -> u16 {
        let mut b = [0u8; 15];
        b[0] = PROTOCOL_VERSION;
        b[1..3].copy_from_slice(&self.cob_id.to_le_bytes());
        b[3..7].copy_from_slice(&self.refresh_time_ms.to_le_bytes());
        b[7..11].copy_from_slice(&self.validation_time_ms.to_le_bytes());
        b[11..15].copy_from_slice(&self.pair_window_ms.to_le_bytes());
        crc16_ccitt(&b)
    }
}

/// CRC-16/CCITT, polynomial 0x1021, initial value 0, no reflection, no final xor (also known
/// as CRC-16/XMODEM; python's `binascii.crc_hqx(data, 0)`). Check value of "123456789": 0x31C3.
pub fn crc16_ccitt(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320, as zlib's `crc32`). Check value of
/// "123456789": 0xCBF43926. Used for the safety parameter set's signature.
pub fn crc32_ieee(data: &[u8]) -> u32 {
    let mut crc: u32 = !0;
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

/// The configuration signature the monitor sends every cycle, doubled like the heartbeat, on
/// [`config_cob_id`]. Payload (normal frame; the inverse carries `!byte`):
///
/// | byte | content |
/// |------|---------|
/// | 0    | protocol version (high nibble) and kind 0x3 (configuration signature) |
/// | 1    | 0 (reserved) |
/// | 2..4 | [`SrdoParams::crc`] of the producer's SRDO configuration, u16 LE |
/// | 4..8 | CRC-32 of the monitor's safety parameter set, u32 LE (diagnosis: consumers log it) |
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfigSignature {
    pub srdo_crc: u16,
    pub safety_params_crc: u32,
}

impl ConfigSignature {
    pub fn to_bytes(&self) -> [u8; 8] {
        let c = self.srdo_crc.to_le_bytes();
        let p = self.safety_params_crc.to_le_bytes();
        [
            (PROTOCOL_VERSION << 4) | KIND_CONFIG,
            0,
            c[0],
            c[1],
            p[0],
            p[1],
            p[2],
            p[3],
        ]
    }

    pub fn from_bytes(d: &[u8; 8]) -> Result<Self, PairError> {
        if d[0] >> 4 != PROTOCOL_VERSION {
            return Err(PairError::Version(d[0] >> 4));
        }
        if d[0] & 0x0F != KIND_CONFIG || d[1] != 0 {
            return Err(PairError::UnknownState(d[0] & 0x0F));
        }
        Ok(Self {
            srdo_crc: u16::from_le_bytes([d[2], d[3]]),
            safety_params_crc: u32::from_le_bytes([d[4], d[5], d[6], d[7]]),
        })
    }

    /// The two frames: normal on `config_cob_id(heartbeat_cob_id)`, inverse on the next id.
    pub fn encode(&self, heartbeat_cob_id: u16) -> [CanFrame; 2] {
        let d = self.to_bytes();
        let mut inv = [0u8; 8];
        for (o, b) in inv.iter_mut().zip(d) {
            *o = !b;
        }
        let id = config_cob_id(heartbeat_cob_id);
        [
            CanFrame::new_std_lossy(id, &d),
            CanFrame::new_std_lossy(id.wrapping_add(1), &inv),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hb(counter: u16) -> SafetyHeartbeat {
        SafetyHeartbeat {
            state: SafetyState::Run,
            cause: 0,
            counter,
            epoch: 7,
        }
    }

    #[test]
    fn crcs_match_the_reference_check_values() {
        // Check values of the catalogue (and python: binascii.crc_hqx(b"123456789", 0),
        // zlib.crc32(b"123456789")).
        assert_eq!(crc16_ccitt(b"123456789"), 0x31C3);
        assert_eq!(crc32_ieee(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32_ieee(b""), 0);
    }

    #[test]
    fn srdo_crc_changes_with_every_parameter() {
        let p = SrdoParams {
            cob_id: 0x101,
            refresh_time_ms: 15,
            validation_time_ms: 50,
            pair_window_ms: 10,
        };
        let c = p.crc();
        assert_ne!(SrdoParams { cob_id: 0x103, ..p }.crc(), c);
        assert_ne!(
            SrdoParams {
                refresh_time_ms: 16,
                ..p
            }
            .crc(),
            c
        );
        assert_ne!(
            SrdoParams {
                validation_time_ms: 500,
                ..p
            }
            .crc(),
            c
        );
        assert_ne!(
            SrdoParams {
                pair_window_ms: 11,
                ..p
            }
            .crc(),
            c
        );
    }

    #[test]
    fn config_signature_round_trip_and_rejects() {
        let s = ConfigSignature {
            srdo_crc: 0xA1B2,
            safety_params_crc: 0xDEAD_BEEF,
        };
        let [a, b] = s.encode(DEFAULT_COB_ID);
        assert_eq!((a.id(), b.id()), (0x103, 0x104));
        let mut rx = PairReceiver::new(config_cob_id(DEFAULT_COB_ID), 1_000_000);
        assert_eq!(rx.on_frame_raw(&a, 0), None);
        let raw = rx.on_frame_raw(&b, 5).unwrap().unwrap();
        assert_eq!(ConfigSignature::from_bytes(&raw), Ok(s));
        // A heartbeat payload is not a signature, nor the reverse.
        assert!(ConfigSignature::from_bytes(&hb(1).to_bytes()).is_err());
        assert!(SafetyHeartbeat::from_bytes(&raw).is_err());
    }

    #[test]
    fn pair_round_trip() {
        let msg = SafetyHeartbeat {
            state: SafetyState::Stop,
            cause: 7,
            counter: 0xBEEF,
            epoch: 0xDEAD_0003,
        };
        let [a, b] = encode(&msg, DEFAULT_COB_ID);
        assert_eq!(a.id(), 0x101);
        assert_eq!(b.id(), 0x102);
        assert_eq!(decode_pair(&a, &b, DEFAULT_COB_ID), Ok(msg));
        let mut rx = PairReceiver::new(DEFAULT_COB_ID, 1_000_000);
        assert_eq!(rx.on_frame(&a, 0), None);
        assert_eq!(rx.on_frame(&b, 10), Some(Ok(msg)));
    }

    #[test]
    fn single_bit_flip_in_either_frame_is_rejected() {
        let [a, b] = encode(&hb(42), DEFAULT_COB_ID);
        for which in 0..2 {
            for bit in 0..64 {
                let (mut na, mut nb) = (a.data().to_vec(), b.data().to_vec());
                let t = if which == 0 { &mut na } else { &mut nb };
                t[bit / 8] ^= 1 << (bit % 8);
                let fa = CanFrame::new(0x101, &na).unwrap();
                let fb = CanFrame::new(0x102, &nb).unwrap();
                assert_eq!(
                    decode_pair(&fa, &fb, DEFAULT_COB_ID),
                    Err(PairError::InverseMismatch)
                );
            }
        }
    }

    #[test]
    fn timing_and_order_errors() {
        let [a, b] = encode(&hb(1), DEFAULT_COB_ID);
        let mut rx = PairReceiver::new(DEFAULT_COB_ID, 5_000_000);
        assert_eq!(rx.on_frame(&b, 0), Some(Err(PairError::UnexpectedInverse)));
        assert_eq!(rx.on_frame(&a, 0), None);
        assert_eq!(rx.on_frame(&a, 1), Some(Err(PairError::MissingInverse)));
        assert_eq!(
            rx.on_frame(&b, 6_000_002),
            Some(Err(PairError::PairWindow { gap_ns: 6_000_001 }))
        );
        // Unrelated traffic in between is fine.
        assert_eq!(rx.on_frame(&a, 10), None);
        assert_eq!(
            rx.on_frame(&CanFrame::new(0x181, &[1, 2]).unwrap(), 11),
            None
        );
        assert_eq!(rx.on_frame(&b, 12), Some(Ok(hb(1))));
        // Short frame on the pair's id.
        assert_eq!(
            rx.on_frame(&CanFrame::new(0x101, &[1]).unwrap(), 13),
            Some(Err(PairError::Malformed {
                cob_id: 0x101,
                len: 1
            }))
        );
    }

    #[test]
    fn unknown_state_and_version_are_rejected() {
        let mut d = hb(5).to_bytes();
        d[0] = 0x23;
        assert_eq!(
            SafetyHeartbeat::from_bytes(&d),
            Err(PairError::UnknownState(3))
        );
        let mut d = hb(5).to_bytes();
        d[0] = 0x91;
        assert_eq!(SafetyHeartbeat::from_bytes(&d), Err(PairError::Version(9)));
        // A version-1 frame (state 0x01 in byte 0) is refused.
        let v1 = [0x01, 0, 5, 0, 0, 0, 0xFF, 1];
        assert_eq!(SafetyHeartbeat::from_bytes(&v1), Err(PairError::Version(0)));
    }

    mod props {
        use super::super::*;
        use proptest::prelude::*;

        fn any_frame() -> impl Strategy<Value = CanFrame> {
            (
                prop_oneof![0x0FFu32..0x104, 0u32..0x800, 0u32..0x2000_0000],
                any::<bool>(),
                any::<bool>(),
                proptest::collection::vec(any::<u8>(), 0..=8),
            )
                .prop_filter_map("valid id", |(id, ext, rtr, d)| {
                    CanFrame::with_flags(id, ext || id > 0x7FF, rtr, &d).ok()
                })
        }

        proptest! {
            /// No panic on any frame sequence; a frame stream that is not an exact pair never
            /// yields a message other than one that was encoded.
            #[test]
            fn receiver_never_panics(frames in proptest::collection::vec((any_frame(), 0u64..20_000_000), 0..64)) {
                let mut rx = PairReceiver::new(DEFAULT_COB_ID, 5_000_000);
                let mut t = 0u64;
                for (f, dt) in &frames {
                    t = t.saturating_add(*dt);
                    if let Some(Ok(m)) = rx.on_frame(f, t) {
                        // A valid message can only come from a frame that is the exact inverse
                        // of its predecessor on the pair's ids: re-encoding must reproduce it.
                        let [_, b] = encode(&m, DEFAULT_COB_ID);
                        prop_assert_eq!(b.data(), f.data());
                    }
                    let _ = decode_pair(f, f, DEFAULT_COB_ID);
                }
            }

            #[test]
            fn any_message_round_trips(state in any::<bool>(), cause in any::<u8>(), counter in any::<u16>(), epoch in any::<u32>()) {
                let msg = SafetyHeartbeat {
                    state: if state { SafetyState::Run } else { SafetyState::Stop },
                    cause,
                    counter,
                    epoch,
                };
                let [a, b] = encode(&msg, DEFAULT_COB_ID);
                prop_assert_eq!(decode_pair(&a, &b, DEFAULT_COB_ID), Ok(msg));
                // Swapped frames are never accepted.
                prop_assert!(decode_pair(&b, &a, DEFAULT_COB_ID).is_err());
            }

            /// Any corruption of any byte of either frame is detected.
            #[test]
            fn any_corruption_is_detected(counter in any::<u16>(), epoch in any::<u32>(), which in 0usize..2, byte in 0usize..8, xor in 1u8..=255) {
                let msg = SafetyHeartbeat { state: SafetyState::Run, cause: 0, counter, epoch };
                let [a, b] = encode(&msg, DEFAULT_COB_ID);
                let (mut da, mut db) = ([0u8; 8], [0u8; 8]);
                da.copy_from_slice(a.data());
                db.copy_from_slice(b.data());
                if which == 0 { da[byte] ^= xor } else { db[byte] ^= xor }
                let fa = CanFrame::new(0x101, &da).unwrap();
                let fb = CanFrame::new(0x102, &db).unwrap();
                prop_assert_eq!(decode_pair(&fa, &fb, DEFAULT_COB_ID), Err(PairError::InverseMismatch));
            }
        }
    }
}
