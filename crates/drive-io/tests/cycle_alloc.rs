//! The master's cycle allocates nothing: boot, start-up scripts and enabling are allowed to,
//! but once the drives follow, `Master::cycle`, `Master::on_frame` and `Master::feedback`
//! make no heap allocation per cycle (counting allocator on this thread; the drive side runs
//! outside the counted calls).

use can_transport::RxFrame;
use cia402_drive::slave::{DriveSlave, MotionDemand, SlaveEvent, WinchAxis};
use crs_ipc::{BusState, JointSetpoint};
use crs_test_support::alloc::{CountingAlloc, count_allocations};
use drive_bus::canopen::{self, BusFrames, FrameBuf};
use drive_io::Master;
use drives_config::DrivesConfig;

#[global_allocator]
static A: CountingAlloc = CountingAlloc;

const PERIOD_NS: u64 = 1_000_000;

fn config() -> DrivesConfig {
    let mut text = String::from(
        "[bus]\ntransport = \"udpbus:239.255.0.1:1\"\nsync_period_us = 1000\n\
         heartbeat_producer_ms = 20\nheartbeat_timeout_ms = 300\n",
    );
    for i in 1..=4 {
        text.push_str(&format!(
            "[[winch]]\nnode_id = {i}\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\n\
             counts_per_rev = 1048576\nsign = 1\n"
        ));
    }
    DrivesConfig::parse(&text).unwrap()
}

/// The master and its drives in virtual time, every buffer allocated up front.
struct Rig {
    cfg: DrivesConfig,
    master: Master,
    slaves: Vec<DriveSlave>,
    axes: Vec<WinchAxis>,
    out: BusFrames,
    replies: FrameBuf,
    now: u64,
}

impl Rig {
    fn new() -> Self {
        let cfg = config();
        let master = Master::new(&cfg).unwrap();
        let slaves = cfg
            .winches
            .iter()
            .map(|w| DriveSlave::new(w.node_id, 20))
            .collect();
        let axes = (0..cfg.winches.len())
            .map(|i| WinchAxis::new(3.0 + i as f64, 5.0, 14.0))
            .collect();
        let mut rig = Self {
            cfg,
            master,
            slaves,
            axes,
            out: BusFrames::new(1),
            replies: FrameBuf::default(),
            now: 1_000_000_000,
        };
        for (i, s) in rig.slaves.iter_mut().enumerate() {
            let c = rig.cfg.winches[i]
                .length_to_counts(rig.axes[i].length_m)
                .unwrap();
            s.set_actual(c, 0, 1000);
            s.start(rig.now, &mut rig.replies);
        }
        rig
    }

    /// One cycle; returns the heap allocations the master's calls made.
    fn step(&mut self, sp: Option<&JointSetpoint>) -> u64 {
        self.now += PERIOD_NS;
        let (now, master, out, replies) =
            (self.now, &mut self.master, &mut self.out, &self.replies);
        let ((), counted) = count_allocations(|| {
            for f in replies.as_slice() {
                let rx = RxFrame {
                    frame: *f,
                    rx_monotonic_ns: now,
                    kernel_rx_realtime_ns: None,
                    own: false,
                };
                master.on_frame(0, &rx);
            }
            out.clear();
            master.cycle(now, sp, out);
            master.mark_written(now);
            let _ = master.feedback();
        });
        self.replies.clear();
        let sync = canopen::sync();
        let frames = self
            .out
            .on(0)
            .iter()
            .chain(self.out.sync_requested().then_some(&sync));
        for f in frames {
            for (i, s) in self.slaves.iter_mut().enumerate() {
                if s.handle_frame(f, now, &mut self.replies) != SlaveEvent::Sync {
                    continue;
                }
                let w = &self.cfg.winches[i];
                match s.demand() {
                    MotionDemand::Follow { target_counts } => {
                        self.axes[i].step(Some(w.counts_to_length(target_counts)), 1e-3)
                    }
                    MotionDemand::QuickStop => self.axes[i].step(None, 1e-3),
                    MotionDemand::Hold => self.axes[i].hold(),
                }
                let c = w.length_to_counts(self.axes[i].length_m).unwrap();
                let v = w.m_per_s_to_counts_per_s(self.axes[i].velocity_m_per_s);
                s.set_actual(c, v, 1000);
                s.transmit_pdos(&mut self.replies);
            }
        }
        for s in &mut self.slaves {
            s.poll(now, &mut self.replies);
        }
        counted
    }
}

#[test]
fn the_cycle_allocates_nothing_while_the_drives_follow() {
    let mut rig = Rig::new();
    for _ in 0..2000 {
        rig.step(None);
        if rig.master.state() == BusState::Ready {
            break;
        }
    }
    assert_eq!(
        rig.master.state(),
        BusState::Ready,
        "the drives never enabled"
    );
    let mut sp = JointSetpoint {
        cable_count: 4,
        ..Default::default()
    };
    let start: Vec<f64> = rig.axes.iter().map(|a| a.length_m).collect();
    let mut allocations = 0;
    for k in 1..=2000u64 {
        // Every cable paid out at a constant 0.2 m/s²: the drives follow, the bus stays Running.
        let t = k as f64 * 1e-3;
        for (i, l) in start.iter().enumerate() {
            sp.cable_length_m[i] = l + 0.1 * t * t;
            sp.cable_velocity_m_per_s[i] = 0.2 * t;
        }
        sp.sequence = k;
        sp.timestamp_ns = rig.now + PERIOD_NS;
        allocations += rig.step(Some(&sp));
    }
    assert_eq!(rig.master.state(), BusState::Running, "not following");
    assert_eq!(allocations, 0, "heap allocations in 2000 running cycles");
}
