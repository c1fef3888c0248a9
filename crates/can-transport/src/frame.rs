//! Classic CAN 2.0 frame (no CAN FD), independent of the transport.

/// Largest standard (11-bit) identifier.
pub const SFF_MAX: u32 = 0x7FF;
/// Largest extended (29-bit) identifier.
pub const EFF_MAX: u32 = 0x1FFF_FFFF;

#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    #[error("CAN id {id:#x} exceeds the {bits}-bit range")]
    IdRange { id: u32, bits: u8 },
    #[error("data length {0} > 8")]
    Length(usize),
}

/// A classic CAN frame. `data[len..]` is zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CanFrame {
    id: u32,
    extended: bool,
    rtr: bool,
    len: u8,
    data: [u8; 8],
}

impl CanFrame {
    /// Standard (11-bit) data frame.
    pub fn new(id: u16, data: &[u8]) -> Result<Self, FrameError> {
        Self::with_flags(u32::from(id), false, false, data)
    }

    /// Standard data frame for ids/lengths known valid at compile time by the caller
    /// (masks the id, truncates data to 8 bytes instead of failing).
    pub fn new_std_lossy(id: u16, data: &[u8]) -> Self {
        let len = data.len().min(8);
        let mut d = [0u8; 8];
        d[..len].copy_from_slice(&data[..len]);
        Self {
            id: u32::from(id) & SFF_MAX,
            extended: false,
            rtr: false,
            len: len as u8,
            data: d,
        }
    }

    /// Any frame. For RTR frames `data` gives only the DLC (contents ignored).
    pub fn with_flags(id: u32, extended: bool, rtr: bool, data: &[u8]) -> Result<Self, FrameError> {
        let max = if extended { EFF_MAX } else { SFF_MAX };
        if id > max {
            return Err(FrameError::IdRange {
                id,
                bits: if extended { 29 } else { 11 },
            });
        }
        if data.len() > 8 {
            return Err(FrameError::Length(data.len()));
        }
        let mut d = [0u8; 8];
        if !rtr {
            d[..data.len()].copy_from_slice(data);
        }
        Ok(Self {
            id,
            extended,
            rtr,
            len: data.len() as u8,
            data: d,
        })
    }

    /// Remote frame with DLC `len`.
    pub fn remote(id: u32, extended: bool, len: u8) -> Result<Self, FrameError> {
        if len > 8 {
            return Err(FrameError::Length(len as usize));
        }
        Self::with_flags(id, extended, true, &[0u8; 8][..len as usize])
    }

    pub const fn id(&self) -> u32 {
        self.id
    }
    pub const fn is_extended(&self) -> bool {
        self.extended
    }
    pub const fn is_rtr(&self) -> bool {
        self.rtr
    }
    pub const fn len(&self) -> usize {
        self.len as usize
    }
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// All 8 data bytes: the payload, zero beyond [`CanFrame::len`] and for remote frames.
    pub const fn raw_data(&self) -> &[u8; 8] {
        &self.data
    }
    /// Payload bytes (empty for RTR frames).
    pub fn data(&self) -> &[u8] {
        if self.rtr {
            &[]
        } else {
            &self.data[..self.len as usize]
        }
    }
}

/// A received frame with its receive time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxFrame {
    pub frame: CanFrame,
    /// CLOCK_MONOTONIC ns when user space received it; on the `wire:` transport the frame's
    /// end-of-frame time in the bus model (the moment it was complete on the wire).
    pub rx_monotonic_ns: u64,
    /// Kernel receive timestamp (CLOCK_REALTIME ns, SO_TIMESTAMP) where the transport provides it.
    pub kernel_rx_realtime_ns: Option<u64>,
    /// The receiving endpoint's own frame, echoed back once it left the wire (transmit
    /// confirmation, after [`crate::CanBus::enable_tx_echo`]); false for every other frame.
    pub own: bool,
}
