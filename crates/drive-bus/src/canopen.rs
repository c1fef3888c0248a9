//! CANopen (CiA 301) + CiA 402 wire encoding used by both master and slave. The mapping is
//! documented in docs/can-protocol.md; keep the two in sync.

use can_transport::CanFrame;

// ---- COB-IDs (predefined connection set, CiA 301 §7.3.3) ----
pub const COB_NMT: u16 = 0x000;
pub const COB_SYNC: u16 = 0x080;
pub const COB_EMCY_BASE: u16 = 0x080; // + node id
pub const COB_TPDO1_BASE: u16 = 0x180; // statusword + position actual
pub const COB_RPDO1_BASE: u16 = 0x200; // controlword + target position
pub const COB_TPDO2_BASE: u16 = 0x280; // velocity actual + pulley force
pub const COB_SDO_TX_BASE: u16 = 0x580; // drive -> master
pub const COB_SDO_RX_BASE: u16 = 0x600; // master -> drive
pub const COB_HEARTBEAT_BASE: u16 = 0x700;

// ---- NMT commands ----
pub const NMT_START: u8 = 0x01;
pub const NMT_STOP: u8 = 0x02;
pub const NMT_ENTER_PREOP: u8 = 0x80;
pub const NMT_RESET_NODE: u8 = 0x81;
pub const NMT_RESET_COMM: u8 = 0x82;

/// NMT state as carried in heartbeat messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtState {
    BootUp,
    Stopped,
    Operational,
    PreOperational,
}

impl NmtState {
    pub fn code(self) -> u8 {
        match self {
            Self::BootUp => 0x00,
            Self::Stopped => 0x04,
            Self::Operational => 0x05,
            Self::PreOperational => 0x7F,
        }
    }
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c & 0x7F {
            0x00 => Self::BootUp,
            0x04 => Self::Stopped,
            0x05 => Self::Operational,
            0x7F => Self::PreOperational,
            _ => return None,
        })
    }
}

// ---- Object dictionary indices ----
pub const OD_DEVICE_TYPE: u16 = 0x1000;
pub const OD_PRODUCER_HEARTBEAT_MS: u16 = 0x1017;
pub const OD_CONTROLWORD: u16 = 0x6040;
pub const OD_STATUSWORD: u16 = 0x6041;
pub const OD_MODES_OF_OPERATION: u16 = 0x6060;
pub const OD_MODES_DISPLAY: u16 = 0x6061;
pub const OD_POSITION_ACTUAL: u16 = 0x6064;
pub const OD_VELOCITY_ACTUAL: u16 = 0x606C;
pub const OD_TARGET_POSITION: u16 = 0x607A;
/// Manufacturer-specific: pulley force sensor, i32 in mN.
pub const OD_PULLEY_FORCE_MN: u16 = 0x2110;
pub const OD_ERROR_REGISTER: u16 = 0x1001;
pub const OD_COB_ID_SYNC: u16 = 0x1005;
pub const OD_COMM_CYCLE_PERIOD_US: u16 = 0x1006;
pub const OD_CONSUMER_HEARTBEAT: u16 = 0x1016;
pub const OD_ERROR_CODE: u16 = 0x603F;
/// CiA 402: action on NMT stop / heartbeat loss (0 none, 1 fault, 2 disable voltage, 3 quick stop).
pub const OD_ABORT_CONNECTION: u16 = 0x6007;
/// CiA 402: quick stop option code (2: ramp then switch on disabled, 6: ramp and stay in QSA).
pub const OD_QUICK_STOP_OPTION: u16 = 0x605A;
pub const OD_FOLLOWING_ERROR_WINDOW: u16 = 0x6065;
pub const OD_FOLLOWING_ERROR_TIMEOUT_MS: u16 = 0x6066;
/// Software position limit: sub 1 min, sub 2 max (counts).
pub const OD_SOFTWARE_POSITION_LIMIT: u16 = 0x607D;
pub const OD_MAX_PROFILE_VELOCITY: u16 = 0x607F;
/// Cyclic synchronous position mode.
pub const MODE_CSP: i8 = 8;
/// CiA 402 device type (servo drive) reported in 0x1000.
pub const DEVICE_TYPE_SERVO: u32 = 0x0002_0192;

// ---- CiA 402 controlword commands (§ "Device control") ----
pub const CW_SHUTDOWN: u16 = 0x0006;
pub const CW_SWITCH_ON: u16 = 0x0007;
pub const CW_ENABLE_OPERATION: u16 = 0x000F;
pub const CW_DISABLE_VOLTAGE: u16 = 0x0000;
pub const CW_QUICK_STOP: u16 = 0x0002;
pub const CW_FAULT_RESET: u16 = 0x0080;

// ---- CiA 402 statusword bits of cyclic synchronous position mode ----
/// Bit 12 in CSP: the drive follows the target position (0: target ignored).
pub const SW_FOLLOWS_TARGET: u16 = 0x1000;
/// Bit 13 in CSP: following error.
pub const SW_FOLLOWING_ERROR: u16 = 0x2000;

/// CiA 402 drive state, decoded from the statusword.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ds402State {
    NotReadyToSwitchOn,
    SwitchOnDisabled,
    ReadyToSwitchOn,
    SwitchedOn,
    OperationEnabled,
    QuickStopActive,
    FaultReactionActive,
    Fault,
    Unknown,
}

impl Ds402State {
    /// Decodes statusword bits 0-3, 5, 6 (CiA 402 table "state coding").
    pub fn from_statusword(sw: u16) -> Self {
        if sw & 0x4F == 0x00 {
            Self::NotReadyToSwitchOn
        } else if sw & 0x4F == 0x40 {
            Self::SwitchOnDisabled
        } else if sw & 0x6F == 0x21 {
            Self::ReadyToSwitchOn
        } else if sw & 0x6F == 0x23 {
            Self::SwitchedOn
        } else if sw & 0x6F == 0x27 {
            Self::OperationEnabled
        } else if sw & 0x6F == 0x07 {
            Self::QuickStopActive
        } else if sw & 0x4F == 0x0F {
            Self::FaultReactionActive
        } else if sw & 0x4F == 0x08 {
            Self::Fault
        } else {
            Self::Unknown
        }
    }

    /// Statusword the slave reports in this state (bit 9 remote; bit 12 "following the command
    /// value" in CSP when enabled).
    pub fn statusword(self) -> u16 {
        match self {
            Self::NotReadyToSwitchOn => 0x0200,
            Self::SwitchOnDisabled => 0x0250,
            Self::ReadyToSwitchOn => 0x0231,
            Self::SwitchedOn => 0x0233,
            Self::OperationEnabled => 0x1237,
            Self::QuickStopActive => 0x0217,
            Self::FaultReactionActive => 0x021F,
            Self::Fault => 0x0218,
            Self::Unknown => 0x0200,
        }
    }
}

/// Controlword the master sends to walk a drive from `state` towards Operation Enabled.
/// `toggle` alternates each cycle so the fault reset gets its rising edge on bit 7.
pub fn enable_step(state: Ds402State, toggle: bool) -> u16 {
    match state {
        Ds402State::Fault => {
            if toggle {
                CW_FAULT_RESET
            } else {
                CW_DISABLE_VOLTAGE
            }
        }
        Ds402State::SwitchOnDisabled => CW_SHUTDOWN,
        Ds402State::ReadyToSwitchOn => CW_SWITCH_ON,
        Ds402State::SwitchedOn | Ds402State::OperationEnabled => CW_ENABLE_OPERATION,
        Ds402State::QuickStopActive
        | Ds402State::NotReadyToSwitchOn
        | Ds402State::FaultReactionActive
        | Ds402State::Unknown => CW_DISABLE_VOLTAGE,
    }
}

// ---- Frame builders (ids are node-relative; node ids are validated 1..=127) ----

fn id(base: u16, node: u8) -> u16 {
    base + u16::from(node & 0x7F)
}

pub fn nmt(command: u8, node: u8) -> CanFrame {
    CanFrame::new_std_lossy(COB_NMT, &[command, node])
}
pub fn sync() -> CanFrame {
    CanFrame::new_std_lossy(COB_SYNC, &[])
}
pub fn heartbeat(node: u8, state: NmtState) -> CanFrame {
    CanFrame::new_std_lossy(id(COB_HEARTBEAT_BASE, node), &[state.code()])
}
pub fn rpdo1(node: u8, controlword: u16, target_counts: i32) -> CanFrame {
    let mut d = [0u8; 6];
    d[..2].copy_from_slice(&controlword.to_le_bytes());
    d[2..].copy_from_slice(&target_counts.to_le_bytes());
    CanFrame::new_std_lossy(id(COB_RPDO1_BASE, node), &d)
}
pub fn tpdo1(node: u8, statusword: u16, position_counts: i32) -> CanFrame {
    let mut d = [0u8; 6];
    d[..2].copy_from_slice(&statusword.to_le_bytes());
    d[2..].copy_from_slice(&position_counts.to_le_bytes());
    CanFrame::new_std_lossy(id(COB_TPDO1_BASE, node), &d)
}
pub fn tpdo2(node: u8, velocity_counts_per_s: i32, force_mn: i32) -> CanFrame {
    let mut d = [0u8; 8];
    d[..4].copy_from_slice(&velocity_counts_per_s.to_le_bytes());
    d[4..].copy_from_slice(&force_mn.to_le_bytes());
    CanFrame::new_std_lossy(id(COB_TPDO2_BASE, node), &d)
}
pub fn emcy(node: u8, code: u16, error_register: u8) -> CanFrame {
    let c = code.to_le_bytes();
    CanFrame::new_std_lossy(
        id(COB_EMCY_BASE, node),
        &[c[0], c[1], error_register, 0, 0, 0, 0, 0],
    )
}

/// A decoded frame (what either side cares about). Unknown or malformed frames decode to
/// `Other` / `Malformed`, never panic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    Nmt {
        command: u8,
        node: u8,
    },
    Sync,
    Emcy {
        node: u8,
        code: u16,
        error_register: u8,
    },
    Tpdo1 {
        node: u8,
        statusword: u16,
        position_counts: i32,
    },
    Tpdo2 {
        node: u8,
        velocity_counts_per_s: i32,
        force_mn: i32,
    },
    Rpdo1 {
        node: u8,
        controlword: u16,
        target_counts: i32,
    },
    SdoRequest {
        node: u8,
        data: [u8; 8],
    },
    SdoResponse {
        node: u8,
        data: [u8; 8],
    },
    Heartbeat {
        node: u8,
        state: u8,
    },
    Malformed {
        cob_id: u16,
        len: u8,
    },
    Other,
}

fn le16(d: &[u8]) -> u16 {
    u16::from_le_bytes([d[0], d[1]])
}
fn le32(d: &[u8]) -> i32 {
    i32::from_le_bytes([d[0], d[1], d[2], d[3]])
}

pub fn decode(frame: &CanFrame) -> Message {
    if frame.is_extended() || frame.is_rtr() {
        return Message::Other;
    }
    let cob = frame.id() as u16;
    let d = frame.data();
    let bad = Message::Malformed {
        cob_id: cob,
        len: d.len() as u8,
    };
    let node = (cob & 0x7F) as u8;
    match cob {
        COB_NMT => {
            if d.len() == 2 {
                Message::Nmt {
                    command: d[0],
                    node: d[1],
                }
            } else {
                bad
            }
        }
        COB_SYNC => {
            if d.len() <= 1 {
                Message::Sync
            } else {
                bad
            }
        }
        _ if node == 0 => Message::Other,
        _ => match cob & 0x780 {
            COB_EMCY_BASE => {
                if d.len() == 8 {
                    Message::Emcy {
                        node,
                        code: le16(d),
                        error_register: d[2],
                    }
                } else {
                    bad
                }
            }
            COB_TPDO1_BASE => {
                if d.len() == 6 {
                    Message::Tpdo1 {
                        node,
                        statusword: le16(d),
                        position_counts: le32(&d[2..]),
                    }
                } else {
                    bad
                }
            }
            COB_TPDO2_BASE => {
                if d.len() == 8 {
                    Message::Tpdo2 {
                        node,
                        velocity_counts_per_s: le32(d),
                        force_mn: le32(&d[4..]),
                    }
                } else {
                    bad
                }
            }
            COB_RPDO1_BASE => {
                if d.len() == 6 {
                    Message::Rpdo1 {
                        node,
                        controlword: le16(d),
                        target_counts: le32(&d[2..]),
                    }
                } else {
                    bad
                }
            }
            COB_SDO_RX_BASE | COB_SDO_TX_BASE => {
                if d.len() == 8 {
                    let mut data = [0u8; 8];
                    data.copy_from_slice(d);
                    if cob & 0x780 == COB_SDO_RX_BASE {
                        Message::SdoRequest { node, data }
                    } else {
                        Message::SdoResponse { node, data }
                    }
                } else {
                    bad
                }
            }
            COB_HEARTBEAT_BASE => {
                if d.len() == 1 {
                    Message::Heartbeat { node, state: d[0] }
                } else {
                    bad
                }
            }
            _ => Message::Other,
        },
    }
}

// ---- SDO expedited transfers (CiA 301 §7.2.4.3) ----

/// SDO abort codes used here.
pub const SDO_ABORT_NO_OBJECT: u32 = 0x0602_0000;
pub const SDO_ABORT_READ_ONLY: u32 = 0x0601_0002;
pub const SDO_ABORT_VALUE_RANGE: u32 = 0x0609_0030;
pub const SDO_ABORT_COMMAND: u32 = 0x0504_0001;
pub const SDO_ABORT_LENGTH: u32 = 0x0607_0010;
pub const SDO_ABORT_UNSUPPORTED_ACCESS: u32 = 0x0601_0000;
pub const SDO_ABORT_WRITE_ONLY: u32 = 0x0601_0001;
pub const SDO_ABORT_NO_SUB: u32 = 0x0609_0011;
pub const SDO_ABORT_VALUE_HIGH: u32 = 0x0609_0031;
pub const SDO_ABORT_VALUE_LOW: u32 = 0x0609_0032;
pub const SDO_ABORT_NOT_MAPPABLE: u32 = 0x0604_0041;
pub const SDO_ABORT_PDO_LENGTH: u32 = 0x0604_0042;
pub const SDO_ABORT_DEVICE_STATE: u32 = 0x0800_0022;

// ---- EMCY error codes (CiA 301 table 21, CiA 402 §"error code") ----
pub const EMCY_HEARTBEAT: u16 = 0x8130;
pub const EMCY_PDO_LENGTH: u16 = 0x8210;
pub const EMCY_FOLLOWING_ERROR: u16 = 0x8611;
pub const EMCY_SLACK_CABLE: u16 = 0xFF10;
pub const EMCY_OVERLOAD: u16 = 0xFF11;

/// The name of an EMCY error code (CiA 301 table 21 / CiA 402 error codes; the 0xFFxx codes
/// are this project's winch drives'), for logs.
pub fn emcy_name(code: u16) -> &'static str {
    match code {
        0x0000 => "error reset or no error",
        0x1000 => "generic error",
        0x2310 => "continuous over-current",
        0x2320 => "short circuit / earth leakage",
        0x3210 => "DC link over-voltage",
        0x3220 => "DC link under-voltage",
        0x4310 => "drive temperature too high",
        0x5000 => "device hardware",
        0x5530 => "data storage (non-volatile memory)",
        0x6000 => "device software",
        0x6320 => "parameter error",
        0x7300 => "sensor error",
        0x7305 => "incremental sensor 1 fault",
        0x8100 => "communication: generic",
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        EMCY_HEARTBEAT => "life guard error or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8150 => "CAN-ID collision",
        EMCY_PDO_LENGTH => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x8250 => "RPDO timeout",
        0x8400 => "velocity speed controller: deviation",
        EMCY_FOLLOWING_ERROR => "position controller: following error",
        0x8612 => "reference limit",
        0x9000 => "external error",
        EMCY_SLACK_CABLE => "winch: slack cable (force below minimum)",
        EMCY_OVERLOAD => "winch: cable overload (force above maximum)",
        c if c & 0xFF00 == 0x2300 => "current, device output side",
        c if c & 0xF000 == 0x2000 => "current",
        c if c & 0xF000 == 0x3000 => "voltage",
        c if c & 0xF000 == 0x4000 => "temperature",
        c if c & 0xF000 == 0x5000 => "device hardware",
        c if c & 0xF000 == 0x6000 => "device software",
        c if c & 0xF000 == 0x7000 => "additional modules",
        c if c & 0xF000 == 0x8000 => "monitoring",
        c if c & 0xFF00 == 0xFF00 => "manufacturer specific",
        _ => "unknown error code",
    }
}

/// Expedited download (write) request of `len` (1, 2 or 4) bytes.
pub fn sdo_download(node: u8, index: u16, sub: u8, value: u32, len: u8) -> CanFrame {
    let cs = match len {
        1 => 0x2F,
        2 => 0x2B,
        _ => 0x23,
    };
    let i = index.to_le_bytes();
    let v = value.to_le_bytes();
    CanFrame::new_std_lossy(
        id(COB_SDO_RX_BASE, node),
        &[cs, i[0], i[1], sub, v[0], v[1], v[2], v[3]],
    )
}

/// Upload (read) request.
pub fn sdo_upload(node: u8, index: u16, sub: u8) -> CanFrame {
    let i = index.to_le_bytes();
    CanFrame::new_std_lossy(
        id(COB_SDO_RX_BASE, node),
        &[0x40, i[0], i[1], sub, 0, 0, 0, 0],
    )
}

/// Server-side response frames.
pub fn sdo_download_ok(node: u8, index: u16, sub: u8) -> CanFrame {
    let i = index.to_le_bytes();
    CanFrame::new_std_lossy(
        id(COB_SDO_TX_BASE, node),
        &[0x60, i[0], i[1], sub, 0, 0, 0, 0],
    )
}
pub fn sdo_upload_ok(node: u8, index: u16, sub: u8, value: u32, len: u8) -> CanFrame {
    let cs = match len {
        1 => 0x4F,
        2 => 0x4B,
        _ => 0x43,
    };
    let i = index.to_le_bytes();
    let v = value.to_le_bytes();
    CanFrame::new_std_lossy(
        id(COB_SDO_TX_BASE, node),
        &[cs, i[0], i[1], sub, v[0], v[1], v[2], v[3]],
    )
}
pub fn sdo_abort(node: u8, index: u16, sub: u8, code: u32) -> CanFrame {
    let i = index.to_le_bytes();
    let c = code.to_le_bytes();
    CanFrame::new_std_lossy(
        id(COB_SDO_TX_BASE, node),
        &[0x80, i[0], i[1], sub, c[0], c[1], c[2], c[3]],
    )
}

/// A decoded SDO request (server side).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoRequest {
    Download {
        index: u16,
        sub: u8,
        value: u32,
        len: u8,
    },
    Upload {
        index: u16,
        sub: u8,
    },
    Unsupported {
        index: u16,
        sub: u8,
    },
}

pub fn parse_sdo_request(d: &[u8; 8]) -> SdoRequest {
    let index = u16::from_le_bytes([d[1], d[2]]);
    let sub = d[3];
    let value = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
    let cs = d[0];
    match cs >> 5 {
        1 if cs & 0x03 == 0x03 => {
            // expedited, size indicated: n = number of bytes NOT containing data
            let len = 4 - ((cs >> 2) & 0x03);
            let mask = if len == 4 {
                u32::MAX
            } else {
                (1u32 << (8 * u32::from(len))) - 1
            };
            SdoRequest::Download {
                index,
                sub,
                value: value & mask,
                len,
            }
        }
        2 => SdoRequest::Upload { index, sub },
        _ => SdoRequest::Unsupported { index, sub },
    }
}

/// A decoded SDO response (client side).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoResponse {
    DownloadOk { index: u16, sub: u8 },
    UploadOk { index: u16, sub: u8, value: u32 },
    Abort { index: u16, sub: u8, code: u32 },
    Unsupported,
}

pub fn parse_sdo_response(d: &[u8; 8]) -> SdoResponse {
    let index = u16::from_le_bytes([d[1], d[2]]);
    let sub = d[3];
    let value = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
    match d[0] {
        0x60 => SdoResponse::DownloadOk { index, sub },
        0x80 => SdoResponse::Abort {
            index,
            sub,
            code: value,
        },
        cs if cs >> 5 == 2 && cs & 0x03 == 0x03 => {
            let len = 4 - ((cs >> 2) & 0x03);
            let mask = if len == 4 {
                u32::MAX
            } else {
                (1u32 << (8 * u32::from(len))) - 1
            };
            SdoResponse::UploadOk {
                index,
                sub,
                value: value & mask,
            }
        }
        _ => SdoResponse::Unsupported,
    }
}

/// Fixed-capacity frame output buffer: the per-SYNC path collects frames here without allocating.
#[derive(Debug, Clone)]
pub struct FrameBuf {
    frames: [CanFrame; Self::CAPACITY],
    len: usize,
    dropped: u32,
    /// Bit k: frame k is a cycle's RPDO ([`FrameBuf::push_rpdo`]; CAPACITY is 64).
    rpdos: u64,
}

impl Default for FrameBuf {
    fn default() -> Self {
        Self {
            frames: [CanFrame::default(); Self::CAPACITY],
            len: 0,
            dropped: 0,
            rpdos: 0,
        }
    }
}

impl FrameBuf {
    pub const CAPACITY: usize = 64;
    pub fn push(&mut self, f: CanFrame) {
        if self.len < Self::CAPACITY {
            self.frames[self.len] = f;
            self.len += 1;
        } else {
            self.dropped += 1;
        }
    }
    /// Queues a cycle's RPDO: process data the next cycle's RPDO replaces (the runner counts
    /// the cycles whose RPDOs queue behind earlier frames, [`FrameBuf::is_rpdo`]; never an
    /// NMT, SDO or heartbeat frame).
    pub fn push_rpdo(&mut self, f: CanFrame) {
        if self.len < Self::CAPACITY {
            self.rpdos |= 1 << self.len;
        }
        self.push(f);
    }
    /// Whether frame `k` of [`FrameBuf::as_slice`] is a cycle's RPDO.
    pub fn is_rpdo(&self, k: usize) -> bool {
        k < Self::CAPACITY && self.rpdos & (1 << k) != 0
    }
    pub fn as_slice(&self) -> &[CanFrame] {
        &self.frames[..self.len]
    }
    pub fn clear(&mut self) {
        self.len = 0;
        self.rpdos = 0;
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// Frames that did not fit (a programming error if ever non-zero).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }
}

/// At most this many CAN interfaces (`[[bus.interface]]`) per drive-io: PCIe/USB CAN cards
/// have 1–4 channels, two cards 8.
pub const MAX_INTERFACES: usize = 8;

/// The frames of one drive-io cycle on every CAN interface (index = the interface's position
/// in `DrivesConfig::interfaces()`), plus whether the cycle ends with a SYNC on every interface
/// (sent by the runner: right after the frames, or at the isochronous SYNC instant).
#[derive(Debug, Clone)]
pub struct BusFrames {
    bufs: [FrameBuf; MAX_INTERFACES],
    interfaces: usize,
    sync: bool,
}

impl BusFrames {
    /// Buffers for `interfaces` interfaces (1..=MAX_INTERFACES; clamped).
    pub fn new(interfaces: usize) -> Self {
        Self {
            bufs: std::array::from_fn(|_| FrameBuf::default()),
            interfaces: interfaces.clamp(1, MAX_INTERFACES),
            sync: false,
        }
    }
    /// Number of interfaces.
    pub fn interfaces(&self) -> usize {
        self.interfaces
    }
    /// Queues `f` on interface `iface` (out-of-range indices go to the last interface's
    /// buffer's drop count: a programming error).
    pub fn push(&mut self, iface: usize, f: CanFrame) {
        let i = iface.min(self.interfaces - 1);
        self.bufs[i].push(f);
    }
    /// Queues a cycle's RPDO on interface `iface` ([`FrameBuf::push_rpdo`]).
    pub fn push_rpdo(&mut self, iface: usize, f: CanFrame) {
        let i = iface.min(self.interfaces - 1);
        self.bufs[i].push_rpdo(f);
    }
    /// The frames of interface `iface` with whether each is a cycle's RPDO.
    pub fn on_tagged(&self, iface: usize) -> impl Iterator<Item = (&CanFrame, bool)> + '_ {
        let b = self.bufs.get(iface);
        b.map(FrameBuf::as_slice)
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .map(move |(k, f)| (f, b.is_some_and(|b| b.is_rpdo(k))))
    }
    /// Queues `f` on every interface.
    pub fn push_all(&mut self, f: CanFrame) {
        for b in &mut self.bufs[..self.interfaces] {
            b.push(f);
        }
    }
    /// The cycle ends with a SYNC on every interface.
    pub fn request_sync(&mut self) {
        self.sync = true;
    }
    pub fn sync_requested(&self) -> bool {
        self.sync
    }
    /// The frames queued on interface `iface`.
    pub fn on(&self, iface: usize) -> &[CanFrame] {
        self.bufs.get(iface).map_or(&[], FrameBuf::as_slice)
    }
    /// Every queued frame with its interface, interface by interface (tests, single-bus rigs).
    pub fn iter(&self) -> impl Iterator<Item = (usize, &CanFrame)> + '_ {
        self.bufs[..self.interfaces]
            .iter()
            .enumerate()
            .flat_map(|(i, b)| b.as_slice().iter().map(move |f| (i, f)))
    }
    pub fn clear(&mut self) {
        for b in &mut self.bufs[..self.interfaces] {
            b.clear();
        }
        self.sync = false;
    }
    pub fn is_empty(&self) -> bool {
        self.bufs[..self.interfaces].iter().all(FrameBuf::is_empty) && !self.sync
    }
    /// Frames that did not fit (a programming error if ever non-zero).
    pub fn dropped(&self) -> u32 {
        self.bufs.iter().map(FrameBuf::dropped).sum()
    }
}
