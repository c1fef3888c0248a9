//! The safety I/O node (drives.toml `[safety_io]`) as the simulated plant and the winch
//! emulator play it: a CiA 401 digital I/O module that is a CiA 304 SRDO consumer of the safety
//! monitor's doubled heartbeat, wired to the safe-torque-off (STO) input of every drive.
//!
//! * **Output** (STO release, one relay contact per drive, all driven alike): released only
//!   while the node is NMT operational, its safety watch ([`SafetyWatch`], the same validation
//!   the drives and drive-io do: validation time, pair window, configuration signature,
//!   counters) permits motion, and the e-stop circuit is closed. Anything else — a dead or
//!   silent monitor, a STOP pair, an invalid pair, an NMT stop, a pressed e-stop button —
//!   removes torque from every drive at once (stop category 0; the brakes close), independently
//!   of what the drives' CANopen side believes. An open e-stop circuit and an NMT stop also
//!   inhibit the node's watch ([`SafetyWatch::inhibit_locally`]): releasing the button or an NMT
//!   start gives the torque back only with the monitor's next reset (a newer epoch), never by
//!   itself.
//! * **Inputs**: bit 0 = e-stop circuit closed (button released; a normally-closed contact,
//!   so a broken wire reads as pressed), bit 1 = the operator's reset key turned. Reported in
//!   TPDO1 `[inputs, outputs]` on every change and at least every `inputs_period_ms`.
//! * **NMT**: a self-starting device (CiA 302 0x1F80 bit 2: it enters operational on its own
//!   after boot-up — drive-io, the drives' NMT master, addresses its drives only and never
//!   resets or starts the safety system's devices); stopped on NMT stop (the monitor's
//!   emergency stop: STO), operational again on NMT start (the monitor's reset); heartbeat every
//!   `heartbeat_ms`. PDOs only when operational.
//!
//! Pure logic: frames and times in, frames out ([`FrameBuf`]); no I/O, no allocation.

use can_transport::CanFrame;
use drive_bus::canopen::{
    FrameBuf, NMT_ENTER_PREOP, NMT_RESET_COMM, NMT_RESET_NODE, NMT_START, NMT_STOP, NmtState,
    heartbeat,
};
use drive_bus::safety_watch::{SafetyWatch, SafetyWatchConfig};
use drives_config::{SafetyIoConfig, safety_io_tpdo_cob_id};

/// Input bit: the e-stop circuit is closed (button released).
pub const INPUT_ESTOP_CLOSED: u8 = 0x01;
/// Input bit: the reset key is turned.
pub const INPUT_RESET_KEY: u8 = 0x02;
/// Output bit: STO released (torque permitted).
pub const OUTPUT_STO_RELEASED: u8 = 0x01;

/// The node (see the module docs).
pub struct SafetyIoNode {
    node: u8,
    nmt: NmtState,
    watch: SafetyWatch,
    inputs: u8,
    outputs: u8,
    /// Inputs/outputs last sent in TPDO1.
    sent: Option<(u8, u8)>,
    last_tpdo_ns: u64,
    inputs_period_ns: u64,
    heartbeat_ns: u64,
    next_heartbeat_ns: u64,
}

impl SafetyIoNode {
    pub fn new(cfg: &SafetyIoConfig, watch: SafetyWatchConfig) -> Self {
        Self {
            node: cfg.node_id,
            nmt: NmtState::BootUp,
            watch: SafetyWatch::new(watch),
            inputs: INPUT_ESTOP_CLOSED,
            outputs: 0,
            sent: None,
            last_tpdo_ns: 0,
            inputs_period_ns: u64::from(cfg.inputs_period_ms) * 1_000_000,
            heartbeat_ns: u64::from(cfg.heartbeat_ms) * 1_000_000,
            next_heartbeat_ns: 0,
        }
    }

    pub fn node_id(&self) -> u8 {
        self.node
    }

    pub fn nmt_state(&self) -> NmtState {
        self.nmt
    }

    /// Power-on: boot-up message, then operational on its own (a self-starting device).
    pub fn start(&mut self, now_ns: u64, out: &mut FrameBuf) {
        out.push(heartbeat(self.node, NmtState::BootUp));
        self.nmt = NmtState::Operational;
        self.next_heartbeat_ns = now_ns + self.heartbeat_ns;
        self.outputs = 0;
    }

    /// The operator's devices: e-stop circuit closed (button released), reset key turned.
    pub fn set_inputs(&mut self, estop_closed: bool, reset_key: bool) {
        self.inputs =
            (u8::from(estop_closed) * INPUT_ESTOP_CLOSED) | (u8::from(reset_key) * INPUT_RESET_KEY);
    }

    pub fn inputs(&self) -> u8 {
        self.inputs
    }

    /// One frame from the bus.
    pub fn handle_frame(&mut self, frame: &CanFrame, now_ns: u64, out: &mut FrameBuf) {
        if frame.is_extended() || frame.is_rtr() {
            return;
        }
        let d = frame.data();
        if frame.id() == 0 && d.len() == 2 && (d[1] == 0 || d[1] == self.node) {
            match d[0] {
                NMT_START => self.nmt = NmtState::Operational,
                NMT_STOP => {
                    self.nmt = NmtState::Stopped;
                    self.watch.inhibit_locally(now_ns);
                }
                NMT_ENTER_PREOP => self.nmt = NmtState::PreOperational,
                NMT_RESET_NODE | NMT_RESET_COMM => {
                    self.sent = None;
                    self.start(now_ns, out);
                }
                _ => {}
            }
            self.update_outputs(now_ns);
            return;
        }
        self.watch.on_frame(frame, now_ns);
        self.update_outputs(now_ns);
    }

    fn update_outputs(&mut self, now_ns: u64) {
        if self.inputs & INPUT_ESTOP_CLOSED == 0 {
            self.watch.inhibit_locally(now_ns);
        }
        let release = self.nmt == NmtState::Operational
            && self.inputs & INPUT_ESTOP_CLOSED != 0
            && self.watch.permits(now_ns);
        self.outputs = u8::from(release) * OUTPUT_STO_RELEASED;
    }

    /// The validation time, the heartbeat and TPDO1 when due.
    pub fn poll(&mut self, now_ns: u64, out: &mut FrameBuf) {
        self.update_outputs(now_ns);
        if self.nmt != NmtState::BootUp && now_ns >= self.next_heartbeat_ns {
            out.push(heartbeat(self.node, self.nmt));
            self.next_heartbeat_ns = if now_ns - self.next_heartbeat_ns > self.heartbeat_ns {
                now_ns + self.heartbeat_ns
            } else {
                self.next_heartbeat_ns + self.heartbeat_ns
            };
        }
        if self.nmt == NmtState::Operational {
            let changed = self.sent != Some((self.inputs, self.outputs));
            if changed || now_ns.saturating_sub(self.last_tpdo_ns) >= self.inputs_period_ns {
                out.push(CanFrame::new_std_lossy(
                    safety_io_tpdo_cob_id(self.node),
                    &[self.inputs, self.outputs],
                ));
                self.sent = Some((self.inputs, self.outputs));
                self.last_tpdo_ns = now_ns;
            }
        }
    }

    /// True while the drives' STO is released (torque permitted).
    pub fn sto_released(&self) -> bool {
        self.outputs & OUTPUT_STO_RELEASED != 0
    }

    /// The node's safety watch (its state and trips, for logs and tests).
    pub fn watch(&self) -> &SafetyWatch {
        &self.watch
    }

    pub fn watch_mut(&mut self) -> &mut SafetyWatch {
        &mut self.watch
    }

    /// When the node next has something to send on its own (heartbeat, TPDO event timer).
    pub fn next_due_ns(&self) -> u64 {
        let tpdo = if self.nmt == NmtState::Operational {
            self.last_tpdo_ns + self.inputs_period_ns
        } else {
            u64::MAX
        };
        self.next_heartbeat_ns.min(tpdo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::safety_frame::{self, ConfigSignature, SafetyHeartbeat, SafetyState};

    const MS: u64 = 1_000_000;

    fn node() -> (SafetyIoNode, SafetyWatchConfig) {
        let w: SafetyWatchConfig = toml::from_str(
            "cob_id = 0x101\nvalidation_time_ms = 50\npair_window_ms = 10\nrelease_pairs = 3\n\
             refresh_time_ms = 15\n",
        )
        .unwrap();
        let io = SafetyIoConfig {
            interface: "safety".into(),
            node_id: 0x30,
            inputs_period_ms: 10,
            heartbeat_ms: 10,
        };
        (SafetyIoNode::new(&io, w), w)
    }

    /// The monitor's cycle: signature pair then heartbeat pair (epoch 1).
    fn monitor_cycle(
        n: &mut SafetyIoNode,
        w: &SafetyWatchConfig,
        k: u16,
        state: SafetyState,
        t: u64,
        out: &mut FrameBuf,
    ) {
        monitor_cycle_e(n, w, k, state, 1, t, out)
    }

    fn monitor_cycle_e(
        n: &mut SafetyIoNode,
        w: &SafetyWatchConfig,
        k: u16,
        state: SafetyState,
        epoch: u32,
        t: u64,
        out: &mut FrameBuf,
    ) {
        let sig = ConfigSignature {
            srdo_crc: w.srdo_crc(),
            safety_params_crc: 0,
        }
        .encode(w.cob_id);
        for f in &sig {
            n.handle_frame(f, t, out);
        }
        let hb = SafetyHeartbeat {
            state,
            cause: 0,
            counter: k,
            epoch,
        };
        for f in &safety_frame::encode(&hb, w.cob_id) {
            n.handle_frame(f, t, out);
        }
        n.poll(t, out);
    }

    #[test]
    fn sto_is_released_only_by_valid_run_pairs_while_operational_and_the_estop_is_closed() {
        let (mut n, w) = node();
        let mut out = FrameBuf::default();
        n.start(0, &mut out);
        assert_eq!(out.as_slice()[0].id(), 0x730);
        // Self-starting; pre-operational (NMT "enter pre-op"), RUN pairs release nothing.
        assert_eq!(n.nmt_state(), NmtState::Operational);
        n.handle_frame(&drive_bus::canopen::nmt(NMT_ENTER_PREOP, 0x30), 0, &mut out);
        let mut t = MS;
        for k in 0..5 {
            monitor_cycle(&mut n, &w, k, SafetyState::Run, t, &mut out);
            t += 15 * MS;
        }
        assert!(!n.sto_released(), "not operational");
        n.handle_frame(&drive_bus::canopen::nmt(NMT_START, 0), t, &mut out);
        for k in 5..10 {
            monitor_cycle(&mut n, &w, k, SafetyState::Run, t, &mut out);
            t += 15 * MS;
        }
        assert!(n.sto_released());
        // The monitor falls silent: torque is removed within the validation time.
        n.poll(t + 30 * MS, &mut out);
        assert!(n.sto_released());
        n.poll(t + 60 * MS, &mut out);
        assert!(!n.sto_released(), "silent monitor");
        // A STOP pair, the e-stop button and the monitor's NMT stop each remove it.
        let (mut n, w) = node();
        n.start(0, &mut out);
        n.handle_frame(&drive_bus::canopen::nmt(NMT_START, 0x30), 0, &mut out);
        let mut t = MS;
        for k in 0..5 {
            monitor_cycle(&mut n, &w, k, SafetyState::Run, t, &mut out);
            t += 15 * MS;
        }
        assert!(n.sto_released());
        n.set_inputs(false, false);
        n.poll(t, &mut out);
        assert!(!n.sto_released(), "e-stop pressed");
        // Released: the same epoch's RUN pairs do not give the torque back (no self-release);
        // the monitor's next reset (a newer epoch) does.
        n.set_inputs(true, false);
        for k in 5..10 {
            monitor_cycle(
                &mut n,
                &w,
                k,
                SafetyState::Run,
                t + u64::from(k) * MS,
                &mut out,
            );
        }
        assert!(!n.sto_released(), "released by the button");
        for k in 10..13 {
            monitor_cycle_e(
                &mut n,
                &w,
                k,
                SafetyState::Run,
                2,
                t + u64::from(k) * MS,
                &mut out,
            );
        }
        assert!(n.sto_released(), "released by the monitor's reset");
        monitor_cycle_e(&mut n, &w, 13, SafetyState::Stop, 2, t + 15 * MS, &mut out);
        assert!(!n.sto_released(), "STOP pair");
        n.handle_frame(&drive_bus::canopen::nmt(NMT_STOP, 0), t + 16 * MS, &mut out);
        assert_eq!(n.nmt_state(), NmtState::Stopped);
        // Its TPDO1 reports the inputs and the output, on change.
        out.clear();
        let (mut n, w) = node();
        n.start(0, &mut out);
        n.handle_frame(&drive_bus::canopen::nmt(NMT_START, 0), 0, &mut out);
        n.set_inputs(true, true);
        monitor_cycle(&mut n, &w, 0, SafetyState::Run, MS, &mut out);
        let tpdo = out
            .as_slice()
            .iter()
            .rev()
            .find(|f| f.id() == 0x1B0)
            .copied()
            .expect("TPDO1");
        assert_eq!(tpdo.data()[0], INPUT_ESTOP_CLOSED | INPUT_RESET_KEY);
    }
}
