//! SDO transfers (CiA 301 §7.2.4.3): expedited and segmented, upload and download, as pure
//! state machines over the 8 data bytes of the SDO frames — [`SdoClient`] for drive-io (one
//! transfer per node at a time) and [`SdoServer`] for the simulated nodes. Block transfer is
//! not implemented: a server offers it only when the client asks for it, which drive-io never
//! does.
//!
//! A server may answer any upload segmented (`0x41`, size in bytes 4-7, then `0x00`/`0x10`
//! segments), also for a 4-byte value: the client follows it to the end instead of taking the
//! initiate response for a failed transfer. Values are held in fixed buffers of [`SDO_MAX`]
//! bytes; a longer value is aborted with 0x05040005 (out of memory) and reported as such.

/// Largest value either side transfers (bytes): device names, version strings, parameters.
pub const SDO_MAX: usize = 128;

pub const ABORT_TOGGLE: u32 = 0x0503_0000;
pub const ABORT_COMMAND: u32 = 0x0504_0001;
pub const ABORT_OUT_OF_MEMORY: u32 = 0x0504_0005;
pub const ABORT_LENGTH: u32 = 0x0607_0010;
pub const ABORT_LENGTH_HIGH: u32 = 0x0607_0012;
pub const ABORT_LENGTH_LOW: u32 = 0x0607_0013;

fn header(cs: u8, index: u16, sub: u8) -> [u8; 8] {
    let i = index.to_le_bytes();
    [cs, i[0], i[1], sub, 0, 0, 0, 0]
}

/// The abort frame's data for `(index, sub)` with `code`.
pub fn abort_data(index: u16, sub: u8, code: u32) -> [u8; 8] {
    let mut d = header(0x80, index, sub);
    d[4..].copy_from_slice(&code.to_le_bytes());
    d
}

fn index_sub(d: &[u8; 8]) -> (u16, u8) {
    (u16::from_le_bytes([d[1], d[2]]), d[3])
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ClientState {
    Idle,
    /// Initiate download sent (expedited or segmented).
    DownloadInit,
    /// Download segments: the next one starts at `pos`.
    DownloadSegments,
    UploadInit,
    UploadSegments,
}

/// What the client does after a response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClientStep {
    /// Send this request (the next segment) and wait again.
    Send([u8; 8]),
    /// The transfer is complete; an upload's value is [`SdoClient::data`].
    Done,
    /// The server aborted the transfer with this code.
    Aborted(u32),
    /// The server broke the protocol (wrong toggle, unknown command, too long a value): send
    /// `abort` and fail the transfer with `code`.
    Failed { code: u32, abort: [u8; 8] },
    /// Not a response to this transfer (another object, or no transfer running): ignore.
    Ignored,
}

/// One node's SDO client: one transfer at a time, no allocation.
#[derive(Debug, Clone, Copy)]
pub struct SdoClient {
    state: ClientState,
    index: u16,
    sub: u8,
    toggle: bool,
    buf: [u8; SDO_MAX],
    len: usize,
    pos: usize,
    /// Upload: the size the server announced.
    expected: Option<usize>,
}

impl Default for SdoClient {
    fn default() -> Self {
        Self {
            state: ClientState::Idle,
            index: 0,
            sub: 0,
            toggle: false,
            buf: [0; SDO_MAX],
            len: 0,
            pos: 0,
            expected: None,
        }
    }
}

/// A download longer than [`SDO_MAX`] bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{len} bytes exceed the SDO buffer of {SDO_MAX} bytes")]
pub struct TooLong {
    pub len: usize,
}

impl SdoClient {
    /// Starts an upload (read) of `(index, sub)`: the initiate request to send.
    pub fn upload(&mut self, index: u16, sub: u8) -> [u8; 8] {
        *self = Self {
            state: ClientState::UploadInit,
            index,
            sub,
            ..Self::default()
        };
        header(0x40, index, sub)
    }

    /// Starts a download (write) of `data` to `(index, sub)`: expedited up to 4 bytes, else
    /// segmented with the size indicated. The initiate request to send.
    pub fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<[u8; 8], TooLong> {
        if data.len() > SDO_MAX {
            return Err(TooLong { len: data.len() });
        }
        *self = Self {
            state: ClientState::DownloadInit,
            index,
            sub,
            len: data.len(),
            ..Self::default()
        };
        self.buf[..data.len()].copy_from_slice(data);
        let mut d;
        if (1..=4).contains(&data.len()) {
            // ccs 1, n = 4 - len bytes without data, expedited, size indicated.
            d = header(0x23 | ((4 - data.len() as u8) << 2), index, sub);
            d[4..4 + data.len()].copy_from_slice(data);
        } else {
            d = header(0x21, index, sub);
            d[4..].copy_from_slice(&(data.len() as u32).to_le_bytes());
        }
        Ok(d)
    }

    /// True while a transfer runs.
    pub fn busy(&self) -> bool {
        self.state != ClientState::Idle
    }

    /// The uploaded value (valid after [`ClientStep::Done`] of an upload).
    pub fn data(&self) -> &[u8] {
        &self.buf[..self.len]
    }

    /// The uploaded value as the little-endian bits of an integer (first 4 bytes).
    pub fn data_u32(&self) -> u32 {
        let mut b = [0u8; 4];
        let n = self.len.min(4);
        b[..n].copy_from_slice(&self.buf[..n]);
        u32::from_le_bytes(b)
    }

    fn fail(&mut self, code: u32) -> ClientStep {
        self.state = ClientState::Idle;
        ClientStep::Failed {
            code,
            abort: abort_data(self.index, self.sub, code),
        }
    }

    fn next_download_segment(&mut self) -> ClientStep {
        let rest = self.len - self.pos;
        let n = rest.min(7);
        let last = rest <= 7;
        let mut d = [0u8; 8];
        d[0] = (u8::from(self.toggle) << 4) | (((7 - n) as u8) << 1) | u8::from(last);
        d[1..1 + n].copy_from_slice(&self.buf[self.pos..self.pos + n]);
        self.pos += n;
        ClientStep::Send(d)
    }

    /// Handles the server's response `d` (the SDO response frame's data).
    pub fn on_response(&mut self, d: &[u8; 8]) -> ClientStep {
        use ClientState::*;
        if self.state == Idle {
            return ClientStep::Ignored;
        }
        let scs = d[0] >> 5;
        // Initiate responses and aborts name the object; segment responses do not.
        let names_object = matches!(self.state, DownloadInit | UploadInit) || d[0] == 0x80;
        if names_object && index_sub(d) != (self.index, self.sub) {
            return ClientStep::Ignored;
        }
        if d[0] == 0x80 {
            self.state = Idle;
            return ClientStep::Aborted(u32::from_le_bytes([d[4], d[5], d[6], d[7]]));
        }
        match self.state {
            Idle => ClientStep::Ignored,
            DownloadInit => {
                if scs != 3 {
                    return self.fail(ABORT_COMMAND);
                }
                if self.len <= 4 && self.len > 0 {
                    self.state = Idle;
                    return ClientStep::Done;
                }
                self.state = DownloadSegments;
                self.toggle = false;
                self.next_download_segment()
            }
            DownloadSegments => {
                if scs != 1 {
                    return self.fail(ABORT_COMMAND);
                }
                if (d[0] & 0x10 != 0) != self.toggle {
                    return self.fail(ABORT_TOGGLE);
                }
                if self.pos >= self.len {
                    self.state = Idle;
                    return ClientStep::Done;
                }
                self.toggle = !self.toggle;
                self.next_download_segment()
            }
            UploadInit => {
                if scs != 2 {
                    return self.fail(ABORT_COMMAND);
                }
                let expedited = d[0] & 0x02 != 0;
                let sized = d[0] & 0x01 != 0;
                if expedited {
                    let n = if sized {
                        4 - usize::from((d[0] >> 2) & 0x03)
                    } else {
                        4
                    };
                    self.buf[..n].copy_from_slice(&d[4..4 + n]);
                    self.len = n;
                    self.state = Idle;
                    return ClientStep::Done;
                }
                self.expected = if sized {
                    let size = u32::from_le_bytes([d[4], d[5], d[6], d[7]]) as usize;
                    if size > SDO_MAX {
                        return self.fail(ABORT_OUT_OF_MEMORY);
                    }
                    Some(size)
                } else {
                    None
                };
                self.state = UploadSegments;
                self.toggle = false;
                self.len = 0;
                ClientStep::Send([0x60, 0, 0, 0, 0, 0, 0, 0])
            }
            UploadSegments => {
                if scs != 0 {
                    return self.fail(ABORT_COMMAND);
                }
                if (d[0] & 0x10 != 0) != self.toggle {
                    return self.fail(ABORT_TOGGLE);
                }
                let n = 7 - usize::from((d[0] >> 1) & 0x07);
                if self.len + n > SDO_MAX {
                    return self.fail(ABORT_OUT_OF_MEMORY);
                }
                self.buf[self.len..self.len + n].copy_from_slice(&d[1..1 + n]);
                self.len += n;
                if d[0] & 0x01 != 0 {
                    self.state = Idle;
                    return match self.expected {
                        Some(e) if e != self.len => self.fail(if self.len > e {
                            ABORT_LENGTH_HIGH
                        } else {
                            ABORT_LENGTH_LOW
                        }),
                        _ => ClientStep::Done,
                    };
                }
                self.toggle = !self.toggle;
                ClientStep::Send([0x60 | (u8::from(self.toggle) << 4), 0, 0, 0, 0, 0, 0, 0])
            }
        }
    }
}

/// The object dictionary behind an [`SdoServer`].
pub trait ObjectAccess {
    /// The value's bytes written into `out` (its length returned), or an abort code.
    fn sdo_read(&mut self, index: u16, sub: u8, out: &mut [u8; SDO_MAX]) -> Result<usize, u32>;
    /// Writes the value's bytes, or returns an abort code.
    fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32>;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ServerState {
    Idle,
    Upload,
    Download,
}

/// One node's SDO server: expedited and segmented transfers; a new initiate request abandons
/// a transfer in progress (as CiA 301 servers do when a client restarts).
#[derive(Debug, Clone, Copy)]
pub struct SdoServer {
    state: ServerState,
    index: u16,
    sub: u8,
    toggle: bool,
    buf: [u8; SDO_MAX],
    len: usize,
    pos: usize,
}

impl Default for SdoServer {
    fn default() -> Self {
        Self {
            state: ServerState::Idle,
            index: 0,
            sub: 0,
            toggle: false,
            buf: [0; SDO_MAX],
            len: 0,
            pos: 0,
        }
    }
}

impl SdoServer {
    fn abort(&mut self, index: u16, sub: u8, code: u32) -> Option<[u8; 8]> {
        self.state = ServerState::Idle;
        Some(abort_data(index, sub, code))
    }

    /// Handles a request; the response to send (None for a client's abort).
    pub fn handle(&mut self, d: &[u8; 8], od: &mut impl ObjectAccess) -> Option<[u8; 8]> {
        let (index, sub) = index_sub(d);
        match d[0] >> 5 {
            1 => self.initiate_download(d, index, sub, od),
            0 if self.state == ServerState::Download => self.download_segment(d, od),
            2 => self.initiate_upload(index, sub, od),
            3 if self.state == ServerState::Upload => self.upload_segment(d),
            // The client aborts: nothing to answer.
            4 => {
                self.state = ServerState::Idle;
                None
            }
            _ => {
                let (i, s) = if self.state == ServerState::Idle {
                    (index, sub)
                } else {
                    (self.index, self.sub)
                };
                self.abort(i, s, ABORT_COMMAND)
            }
        }
    }

    /// Initiate download: an expedited write at once, or the start of a segmented one.
    fn initiate_download(
        &mut self,
        d: &[u8; 8],
        index: u16,
        sub: u8,
        od: &mut impl ObjectAccess,
    ) -> Option<[u8; 8]> {
        self.state = ServerState::Idle;
        let expedited = d[0] & 0x02 != 0;
        let sized = d[0] & 0x01 != 0;
        if expedited {
            let n = if sized {
                4 - usize::from((d[0] >> 2) & 0x03)
            } else {
                4
            };
            return match od.sdo_write(index, sub, &d[4..4 + n]) {
                Ok(()) => Some(header(0x60, index, sub)),
                Err(code) => self.abort(index, sub, code),
            };
        }
        let size = if sized {
            u32::from_le_bytes([d[4], d[5], d[6], d[7]]) as usize
        } else {
            0
        };
        if size > SDO_MAX {
            return self.abort(index, sub, ABORT_OUT_OF_MEMORY);
        }
        *self = Self {
            state: ServerState::Download,
            index,
            sub,
            len: size,
            ..Self::default()
        };
        Some(header(0x60, index, sub))
    }

    /// Download segment: appended; the last one writes the whole value.
    fn download_segment(&mut self, d: &[u8; 8], od: &mut impl ObjectAccess) -> Option<[u8; 8]> {
        let (index, sub) = (self.index, self.sub);
        if (d[0] & 0x10 != 0) != self.toggle {
            return self.abort(index, sub, ABORT_TOGGLE);
        }
        let n = 7 - usize::from((d[0] >> 1) & 0x07);
        if self.pos + n > SDO_MAX {
            return self.abort(index, sub, ABORT_OUT_OF_MEMORY);
        }
        self.buf[self.pos..self.pos + n].copy_from_slice(&d[1..1 + n]);
        self.pos += n;
        let resp = [0x20 | (u8::from(self.toggle) << 4), 0, 0, 0, 0, 0, 0, 0];
        self.toggle = !self.toggle;
        if d[0] & 0x01 == 0 {
            return Some(resp);
        }
        self.state = ServerState::Idle;
        if self.len != 0 && self.len != self.pos {
            return self.abort(index, sub, ABORT_LENGTH);
        }
        let (buf, pos) = (self.buf, self.pos);
        match od.sdo_write(index, sub, &buf[..pos]) {
            Ok(()) => Some(resp),
            Err(code) => self.abort(index, sub, code),
        }
    }

    /// Initiate upload: up to 4 bytes expedited, more segmented.
    fn initiate_upload(
        &mut self,
        index: u16,
        sub: u8,
        od: &mut impl ObjectAccess,
    ) -> Option<[u8; 8]> {
        self.state = ServerState::Idle;
        let mut buf = [0u8; SDO_MAX];
        let n = match od.sdo_read(index, sub, &mut buf) {
            Ok(n) => n.min(SDO_MAX),
            Err(code) => return self.abort(index, sub, code),
        };
        if (1..=4).contains(&n) {
            let mut r = header(0x43 | ((4 - n as u8) << 2), index, sub);
            r[4..4 + n].copy_from_slice(&buf[..n]);
            return Some(r);
        }
        *self = Self {
            state: ServerState::Upload,
            index,
            sub,
            buf,
            len: n,
            ..Self::default()
        };
        let mut r = header(0x41, index, sub);
        r[4..].copy_from_slice(&(n as u32).to_le_bytes());
        Some(r)
    }

    /// Upload segment: the next up to 7 bytes.
    fn upload_segment(&mut self, d: &[u8; 8]) -> Option<[u8; 8]> {
        if (d[0] & 0x10 != 0) != self.toggle {
            return self.abort(self.index, self.sub, ABORT_TOGGLE);
        }
        let rest = self.len - self.pos;
        let n = rest.min(7);
        let last = rest <= 7;
        let mut r = [0u8; 8];
        r[0] = (u8::from(self.toggle) << 4) | (((7 - n) as u8) << 1) | u8::from(last);
        r[1..1 + n].copy_from_slice(&self.buf[self.pos..self.pos + n]);
        self.pos += n;
        self.toggle = !self.toggle;
        if last {
            self.state = ServerState::Idle;
        }
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(Default)]
    struct Od(BTreeMap<(u16, u8), Vec<u8>>);

    impl ObjectAccess for Od {
        fn sdo_read(&mut self, i: u16, s: u8, out: &mut [u8; SDO_MAX]) -> Result<usize, u32> {
            let v = self.0.get(&(i, s)).ok_or(0x0602_0000u32)?;
            out[..v.len()].copy_from_slice(v);
            Ok(v.len())
        }
        fn sdo_write(&mut self, i: u16, s: u8, data: &[u8]) -> Result<(), u32> {
            if i == 0x1008 {
                return Err(0x0601_0002);
            }
            self.0.insert((i, s), data.to_vec());
            Ok(())
        }
    }

    /// Runs a transfer between a client and a server to its end; the frames exchanged.
    fn run(c: &mut SdoClient, srv: &mut SdoServer, od: &mut Od, first: [u8; 8]) -> ClientStep {
        let mut req = first;
        for _ in 0..100 {
            let resp = srv.handle(&req, od).expect("a response");
            match c.on_response(&resp) {
                ClientStep::Send(next) => req = next,
                other => return other,
            }
        }
        panic!("transfer did not end");
    }

    #[test]
    fn expedited_and_segmented_transfers_round_trip() {
        let mut od = Od::default();
        od.0.insert((0x1008, 0), b"ACME CSP-2000 servo drive".to_vec());
        let (mut c, mut srv) = (SdoClient::default(), SdoServer::default());
        // Segmented upload of a 25-byte string: 4 segments, toggling.
        let first = c.upload(0x1008, 0);
        assert_eq!(first[0], 0x40);
        assert_eq!(run(&mut c, &mut srv, &mut od, first), ClientStep::Done);
        assert_eq!(c.data(), b"ACME CSP-2000 servo drive");
        // Segmented download of 9 bytes, then read back.
        let first = c.download(0x2000, 1, b"parameter").unwrap();
        assert_eq!(first[0], 0x21);
        assert_eq!(run(&mut c, &mut srv, &mut od, first), ClientStep::Done);
        assert_eq!(od.0[&(0x2000, 1)], b"parameter");
        // Exactly 7 and 14 bytes: the last segment is full.
        for len in [5usize, 7, 14, 128] {
            let v: Vec<u8> = (0..len as u8).collect();
            let first = c.download(0x2001, 0, &v).unwrap();
            assert_eq!(run(&mut c, &mut srv, &mut od, first), ClientStep::Done);
            let first = c.upload(0x2001, 0);
            assert_eq!(run(&mut c, &mut srv, &mut od, first), ClientStep::Done);
            assert_eq!(c.data(), &v[..], "{len} bytes");
        }
        // Expedited: 2 bytes.
        let first = c.download(0x1017, 0, &[10, 0]).unwrap();
        assert_eq!(first[0], 0x2B);
        assert_eq!(run(&mut c, &mut srv, &mut od, first), ClientStep::Done);
        let first = c.upload(0x1017, 0);
        assert_eq!(run(&mut c, &mut srv, &mut od, first), ClientStep::Done);
        assert_eq!((c.data(), c.data_u32()), (&[10u8, 0][..], 10));
        // Aborts from the server's object dictionary.
        let first = c.upload(0x3000, 0);
        assert_eq!(
            run(&mut c, &mut srv, &mut od, first),
            ClientStep::Aborted(0x0602_0000)
        );
        let first = c.download(0x1008, 0, b"another name").unwrap();
        assert_eq!(
            run(&mut c, &mut srv, &mut od, first),
            ClientStep::Aborted(0x0601_0002)
        );
        assert!(c.download(0x2000, 0, &[0; SDO_MAX + 1]).is_err());
    }

    /// A 4-byte value answered segmented (0x41) completes as a value, not a failure.
    #[test]
    fn a_segmented_answer_to_a_small_value_completes() {
        let mut c = SdoClient::default();
        c.upload(0x1018, 1);
        let mut init = header(0x41, 0x1018, 1);
        init[4] = 4;
        assert_eq!(
            c.on_response(&init),
            ClientStep::Send([0x60, 0, 0, 0, 0, 0, 0, 0])
        );
        // 4 bytes in one last segment: n = 3 bytes without data, c = 1.
        let seg = [(3 << 1) | 1, 0x78, 0x56, 0x34, 0x12, 0, 0, 0];
        assert_eq!(c.on_response(&seg), ClientStep::Done);
        assert_eq!(c.data_u32(), 0x1234_5678);
    }

    #[test]
    fn protocol_errors_fail_with_an_abort() {
        let mut c = SdoClient::default();
        c.upload(0x1008, 0);
        let mut init = header(0x41, 0x1008, 0);
        init[4] = 10;
        assert!(matches!(c.on_response(&init), ClientStep::Send(_)));
        // Wrong toggle (1 on the first segment).
        match c.on_response(&[0x10, 1, 2, 3, 4, 5, 6, 7]) {
            ClientStep::Failed { code, abort } => {
                assert_eq!(code, ABORT_TOGGLE);
                assert_eq!(abort, abort_data(0x1008, 0, ABORT_TOGGLE));
            }
            s => panic!("{s:?}"),
        }
        // Announced size beyond the buffer.
        c.upload(0x1008, 0);
        let mut init = header(0x41, 0x1008, 0);
        init[4..].copy_from_slice(&1000u32.to_le_bytes());
        assert!(matches!(
            c.on_response(&init),
            ClientStep::Failed {
                code: ABORT_OUT_OF_MEMORY,
                ..
            }
        ));
        // Fewer bytes than announced.
        c.upload(0x1008, 0);
        let mut init = header(0x41, 0x1008, 0);
        init[4] = 9;
        c.on_response(&init);
        assert!(matches!(
            c.on_response(&[0x01 | (4 << 1), 1, 2, 3, 0, 0, 0, 0]),
            ClientStep::Failed {
                code: ABORT_LENGTH_LOW,
                ..
            }
        ));
        // A response for another object is not this transfer's.
        c.upload(0x1008, 0);
        assert_eq!(c.on_response(&header(0x43, 0x1009, 0)), ClientStep::Ignored);
        // Nothing running: ignored.
        let mut idle = SdoClient::default();
        assert_eq!(idle.on_response(&header(0x60, 1, 0)), ClientStep::Ignored);
    }

    #[test]
    fn server_restarts_on_a_new_initiate_and_rejects_stray_segments() {
        let mut od = Od::default();
        od.0.insert((0x1008, 0), b"a long device name".to_vec());
        let mut srv = SdoServer::default();
        let r = srv.handle(&header(0x40, 0x1008, 0), &mut od).unwrap();
        assert_eq!(r[0], 0x41);
        // The client restarts: a fresh initiate is answered afresh.
        let r = srv.handle(&header(0x40, 0x1008, 0), &mut od).unwrap();
        assert_eq!((r[0], r[4]), (0x41, 18));
        // A segment request with the wrong toggle aborts.
        let r = srv.handle(&[0x70, 0, 0, 0, 0, 0, 0, 0], &mut od).unwrap();
        assert_eq!(r, abort_data(0x1008, 0, ABORT_TOGGLE));
        // A segment without a transfer: command specifier not valid.
        let r = srv.handle(&[0x60, 0, 0, 0, 0, 0, 0, 0], &mut od).unwrap();
        assert_eq!(r[0], 0x80);
        assert_eq!(u32::from_le_bytes([r[4], r[5], r[6], r[7]]), ABORT_COMMAND);
        // A client abort is not answered.
        assert!(srv.handle(&abort_data(0x1008, 0, 1), &mut od).is_none());
    }

    proptest::proptest! {
        #[test]
        fn client_and_server_never_panic(frames in proptest::collection::vec(proptest::array::uniform8(proptest::num::u8::ANY), 0..40)) {
            let mut od = Od::default();
            od.0.insert((0x1008, 0), vec![7; 40]);
            let (mut c, mut srv) = (SdoClient::default(), SdoServer::default());
            c.upload(0x1008, 0);
            for f in &frames {
                let _ = c.on_response(f);
                let _ = srv.handle(f, &mut od);
            }
        }
    }
}
