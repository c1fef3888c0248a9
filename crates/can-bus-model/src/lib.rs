//! # can-bus-model: one classic CAN bus as it is on the wire
//!
//! A bit rate, nodes with a bounded FIFO transmit queue each, arbitration by identifier
//! whenever the bus is idle, and every frame occupying the bus for its exact length in bits
//! ([`can_transport::wire::bits::exact`]). The `can-wire` hub runs it for every simulated
//! bus; the processes on the bus reach it through can-transport's `wire:` client.
//!
//! Pure logic: time is passed in (CLOCK_MONOTONIC ns in the hub, any ns in tests), there is no
//! I/O, and nothing allocates after [`Bus::new`].
//!
//! What happens, in model time:
//! * A node submits a frame at its send time; it joins the tail of the node's queue (the
//!   SocketCAN qdisc is FIFO: only the head of each node's queue competes). A node holds at
//!   most `queue_len` frames not yet off the wire (waiting plus the one on the wire); one more
//!   is refused ([`SubmitError::QueueFull`], the sender's ENOBUFS).
//! * When the bus is idle, the queue heads submitted by then arbitrate: the lowest arbitration
//!   field wins ([`arbitration_key`]: identifier bit by bit, dominant 0 first; a standard frame
//!   beats an extended one with the same base identifier; a data frame beats a remote frame).
//! * The winner starts at that instant, is complete at its end of frame
//!   (start + [`can_transport::wire::bits::FrameBits::to_eof`] bit times): delivered to every
//!   other node and confirmed to its sender then; the bus is free again after the 3-bit
//!   intermission.
//! * A submission stamped before an arbitration decision already taken is a model violation:
//!   the frame should have competed in it but was not known yet (the hub learned of it too
//!   late). It is counted, and the frame competes at the next arbitration.
//!
//! Not modelled: bit errors, error frames and retransmission, error counters, bus-off, the
//! exact bit position of an arbitration loss (a loser simply waits for the next idle bus),
//! frames from two nodes with the same arbitration field (the lower node index wins; counted).

use can_transport::CanFrame;
use can_transport::wire::bits;
use hdrhistogram::Histogram;

/// Length of a load window, ns.
pub const WINDOW_NS: u64 = 1_000_000_000;
/// Transmit queue length of a node when none is configured: `txqueuelen` of a Linux CAN
/// netdev (10).
pub const DEFAULT_QUEUE_LEN: usize = 10;
/// Largest delay a histogram resolves, ns; longer ones are recorded as this.
pub const HISTOGRAM_MAX_NS: u64 = 60_000_000_000;
/// Significant decimal digits of the delay histograms (relative resolution 1 %).
pub const HISTOGRAM_SIGFIG: u8 = 2;

/// The fixed description of one bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusConfig {
    /// Nominal bit rate, bit/s.
    pub bitrate_bps: u32,
    /// Nodes the bus can ever have (node indices are not reused).
    pub max_nodes: usize,
    /// Frames a node holds that have not left the wire yet (queue plus the one on the wire).
    pub queue_len: usize,
    /// Distinct identifiers with their own statistics; further ones are pooled as "other".
    pub max_ids: usize,
}

impl BusConfig {
    /// A bus at `bitrate_bps` with the defaults: 32 nodes, queues of
    /// [`DEFAULT_QUEUE_LEN`], statistics for 128 identifiers.
    pub fn new(bitrate_bps: u32) -> Self {
        Self {
            bitrate_bps,
            max_nodes: 32,
            queue_len: DEFAULT_QUEUE_LEN,
            max_ids: 128,
        }
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(1_000..=1_000_000).contains(&self.bitrate_bps) {
            return Err(ConfigError::BitRate(self.bitrate_bps));
        }
        if !(1..=4096).contains(&self.queue_len) {
            return Err(ConfigError::QueueLen(self.queue_len));
        }
        if !(1..=256).contains(&self.max_nodes) {
            return Err(ConfigError::Nodes(self.max_nodes));
        }
        if !(1..=4096).contains(&self.max_ids) {
            return Err(ConfigError::Ids(self.max_ids));
        }
        Ok(())
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    #[error("bit rate {0} bit/s out of range (1000..=1000000 for classic CAN)")]
    BitRate(u32),
    #[error("queue length {0} out of range (1..=4096)")]
    QueueLen(usize),
    #[error("node count {0} out of range (1..=256)")]
    Nodes(usize),
    #[error("identifier statistics capacity {0} out of range (1..=4096)")]
    Ids(usize),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SubmitError {
    #[error("node {0} is not on the bus")]
    NoNode(usize),
    #[error("transmit queue of node {node} full ({len} frames not yet off the wire)")]
    QueueFull { node: usize, len: usize },
}

/// The arbitration field as one number: lower wins. Bits 31..21 base identifier, bit 20 RTR
/// (standard) or SRR (extended, recessive), bit 19 IDE, bits 18..1 identifier extension,
/// bit 0 RTR (extended) — the order in which they go onto the wire, dominant = 0.
pub const fn arbitration_key(frame: &CanFrame) -> u32 {
    let rtr = frame.is_rtr() as u32;
    if frame.is_extended() {
        let id = frame.id() & 0x1FFF_FFFF;
        ((id >> 18) << 21) | (1 << 20) | (1 << 19) | ((id & 0x3FFFF) << 1) | rtr
    } else {
        ((frame.id() & 0x7FF) << 21) | (rtr << 20)
    }
}

/// A frame that left the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Delivery {
    /// The sender.
    pub node: usize,
    pub frame: CanFrame,
    /// The sender's tag from [`Bus::submit`].
    pub tag: u32,
    pub submit_ns: u64,
    /// SOF.
    pub start_ns: u64,
    /// End of the last EOF bit: delivered to the others, confirmed to the sender.
    pub eof_ns: u64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Pending {
    frame: CanFrame,
    submit_ns: u64,
    tag: u32,
}

#[derive(Debug, Clone, Copy, Default)]
struct Queue {
    head: usize,
    len: usize,
    active: bool,
}

#[derive(Debug, Clone, Copy)]
struct InFlight {
    node: usize,
    start_ns: u64,
    eof_ns: u64,
    free_ns: u64,
}

/// Per-node statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NodeStats {
    /// Frames that left the wire.
    pub sent: u64,
    /// Frames refused because the node's queue was full.
    pub dropped: u64,
    /// Frames still waiting when the node left the bus.
    pub lost_at_leave: u64,
    /// Most frames the node held not yet off the wire.
    pub max_depth: u32,
}

/// Statistics of one identifier (standard or extended).
#[derive(Debug, Clone)]
pub struct IdStats {
    pub count: u64,
    pub dropped: u64,
    /// SOF − submit, ns.
    pub queueing: Histogram<u32>,
    /// End of frame − submit, ns.
    pub latency: Histogram<u32>,
    pub queueing_max_ns: u64,
    pub latency_max_ns: u64,
}

impl IdStats {
    fn new() -> Self {
        let h = || {
            Histogram::new_with_bounds(1, HISTOGRAM_MAX_NS, HISTOGRAM_SIGFIG)
                .expect("constant histogram bounds are valid")
        };
        Self {
            count: 0,
            dropped: 0,
            queueing: h(),
            latency: h(),
            queueing_max_ns: 0,
            latency_max_ns: 0,
        }
    }
    fn reset(&mut self) {
        self.count = 0;
        self.dropped = 0;
        self.queueing.reset();
        self.latency.reset();
        self.queueing_max_ns = 0;
        self.latency_max_ns = 0;
    }
    fn merge(&mut self, o: &IdStats) {
        self.count += o.count;
        self.dropped += o.dropped;
        // Same bounds on both sides: adding cannot fail or resize.
        let _ = self.queueing.add(&o.queueing);
        let _ = self.latency.add(&o.latency);
        self.queueing_max_ns = self.queueing_max_ns.max(o.queueing_max_ns);
        self.latency_max_ns = self.latency_max_ns.max(o.latency_max_ns);
    }
    /// The quantile definition of every figure: hdrhistogram's `value_at_quantile`, the
    /// smallest recorded value v (to [`HISTOGRAM_SIGFIG`] digits, reported as the upper end of
    /// its bucket) with at least q of the samples ≤ v (nearest rank). `None` without samples.
    pub fn quantile(h: &Histogram<u32>, q: f64) -> Option<u64> {
        (!h.is_empty()).then(|| h.value_at_quantile(q))
    }
}

/// An identifier as the statistics name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IdKey {
    pub id: u32,
    pub extended: bool,
}

/// The statistics of one bus over an interval. [`Bus::swap_stats`] hands the running block
/// out and continues in a fresh one, so a reader can merge and print without the bus waiting.
#[derive(Debug, Clone)]
pub struct BusStats {
    /// Frames that left the wire.
    pub frames: u64,
    /// Time the bus was occupied (SOF through intermission of every frame), ns.
    pub busy_ns: u64,
    /// Completed 1 s load windows, the sum and the largest of their loads (busy / window).
    pub windows: u64,
    pub window_load_sum: f64,
    pub window_load_max: f64,
    /// Submissions stamped before an arbitration decision already taken, and the worst by how
    /// much (ns).
    pub violations: u64,
    pub violation_max_ns: u64,
    /// Arbitrations between identical arbitration fields of two nodes.
    pub arbitration_ties: u64,
    pub nodes: Vec<NodeStats>,
    /// Per identifier slot; the last slot pools identifiers beyond `max_ids`.
    pub ids: Vec<IdStats>,
    /// The identifier of each slot with data in this block.
    pub id_keys: Vec<Option<IdKey>>,
}

impl BusStats {
    pub fn new(cfg: &BusConfig) -> Self {
        Self {
            frames: 0,
            busy_ns: 0,
            windows: 0,
            window_load_sum: 0.0,
            window_load_max: 0.0,
            violations: 0,
            violation_max_ns: 0,
            arbitration_ties: 0,
            nodes: vec![NodeStats::default(); cfg.max_nodes],
            ids: (0..=cfg.max_ids).map(|_| IdStats::new()).collect(),
            id_keys: vec![None; cfg.max_ids + 1],
        }
    }

    /// Clears every figure, keeping the storage.
    pub fn reset(&mut self) {
        self.frames = 0;
        self.busy_ns = 0;
        self.windows = 0;
        self.window_load_sum = 0.0;
        self.window_load_max = 0.0;
        self.violations = 0;
        self.violation_max_ns = 0;
        self.arbitration_ties = 0;
        self.nodes.fill(NodeStats::default());
        self.ids.iter_mut().for_each(IdStats::reset);
        self.id_keys.fill(None);
    }

    /// Adds `o` (a later interval of the same bus) to `self`.
    pub fn merge(&mut self, o: &BusStats) {
        self.frames += o.frames;
        self.busy_ns += o.busy_ns;
        self.windows += o.windows;
        self.window_load_sum += o.window_load_sum;
        self.window_load_max = self.window_load_max.max(o.window_load_max);
        self.violations += o.violations;
        self.violation_max_ns = self.violation_max_ns.max(o.violation_max_ns);
        self.arbitration_ties += o.arbitration_ties;
        for (a, b) in self.nodes.iter_mut().zip(&o.nodes) {
            a.sent += b.sent;
            a.dropped += b.dropped;
            a.lost_at_leave += b.lost_at_leave;
            a.max_depth = a.max_depth.max(b.max_depth);
        }
        for (a, b) in self.ids.iter_mut().zip(&o.ids) {
            a.merge(b);
        }
        for (a, b) in self.id_keys.iter_mut().zip(&o.id_keys) {
            if b.is_some() {
                *a = *b;
            }
        }
    }

    /// Mean load over the completed windows (busy / window time); `None` before the first.
    pub fn window_load_mean(&self) -> Option<f64> {
        (self.windows > 0).then(|| self.window_load_sum / self.windows as f64)
    }
}

/// Identifier → statistics slot, fixed capacity.
#[derive(Debug, Clone)]
struct IdMap {
    /// Standard identifiers: slot + 1, 0 = none yet.
    std: Vec<u16>,
    /// Extended identifiers: (id, slot), linear search (rare on a CANopen bus).
    ext: Vec<(u32, u16)>,
    used: usize,
    max: usize,
}

impl IdMap {
    fn new(max: usize) -> Self {
        Self {
            std: vec![0; 2048],
            ext: Vec::with_capacity(max),
            used: 0,
            max,
        }
    }
    /// The slot of `frame`'s identifier (the pooled last slot once all are taken).
    fn slot(&mut self, frame: &CanFrame) -> usize {
        if frame.is_extended() {
            if let Some(&(_, s)) = self.ext.iter().find(|(id, _)| *id == frame.id()) {
                return s as usize;
            }
            if self.used == self.max {
                return self.max;
            }
            self.ext.push((frame.id(), self.used as u16));
        } else {
            let e = &mut self.std[(frame.id() & 0x7FF) as usize];
            if *e != 0 {
                return (*e - 1) as usize;
            }
            if self.used == self.max {
                return self.max;
            }
            *e = self.used as u16 + 1;
        }
        self.used += 1;
        self.used - 1
    }
}

/// One bus: its queues, the frame on the wire, and the running statistics.
#[derive(Debug)]
pub struct Bus {
    cfg: BusConfig,
    /// `queue_len` slots per node, each node's a ring.
    slots: Vec<Pending>,
    queues: Vec<Queue>,
    nodes_added: usize,
    in_flight: Option<InFlight>,
    /// The bus is free for the next SOF from here (end of the last intermission).
    free_at_ns: u64,
    last_decision_ns: Option<u64>,
    ids: IdMap,
    stats: Box<BusStats>,
    window_start_ns: u64,
    window_busy_ns: u64,
}

impl Bus {
    /// A bus with no node yet; load windows start at `t0_ns`.
    pub fn new(cfg: BusConfig, t0_ns: u64) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self {
            slots: vec![Pending::default(); cfg.max_nodes * cfg.queue_len],
            queues: vec![Queue::default(); cfg.max_nodes],
            nodes_added: 0,
            in_flight: None,
            free_at_ns: t0_ns,
            last_decision_ns: None,
            ids: IdMap::new(cfg.max_ids),
            stats: Box::new(BusStats::new(&cfg)),
            window_start_ns: t0_ns,
            window_busy_ns: 0,
            cfg,
        })
    }

    pub fn config(&self) -> &BusConfig {
        &self.cfg
    }

    /// Puts a new node on the bus; `None` when all `max_nodes` were used.
    pub fn add_node(&mut self) -> Option<usize> {
        let n = self.nodes_added;
        if n == self.cfg.max_nodes {
            return None;
        }
        self.nodes_added += 1;
        self.queues[n] = Queue {
            head: 0,
            len: 0,
            active: true,
        };
        Some(n)
    }

    /// Takes a node off the bus: its waiting frames are lost (counted), a frame of it already
    /// on the wire completes. Returns the number lost.
    pub fn remove_node(&mut self, node: usize) -> usize {
        let Some(q) = self.queues.get_mut(node) else {
            return 0;
        };
        if !q.active {
            return 0;
        }
        let on_wire = self.in_flight.is_some_and(|f| f.node == node);
        let keep = usize::from(on_wire);
        let lost = q.len - keep;
        q.len = keep;
        q.active = false;
        self.stats.nodes[node].lost_at_leave += lost as u64;
        lost
    }

    pub fn is_active(&self, node: usize) -> bool {
        self.queues.get(node).is_some_and(|q| q.active)
    }

    /// Frames of `node` not yet off the wire.
    pub fn queue_depth(&self, node: usize) -> usize {
        self.queues.get(node).map_or(0, |q| q.len)
    }

    /// `node` hands `frame` to its controller at `submit_ns`; `tag` comes back in its
    /// [`Delivery`].
    pub fn submit(
        &mut self,
        node: usize,
        frame: CanFrame,
        submit_ns: u64,
        tag: u32,
    ) -> Result<(), SubmitError> {
        let qlen = self.cfg.queue_len;
        let Some(q) = self.queues.get_mut(node).filter(|q| q.active) else {
            return Err(SubmitError::NoNode(node));
        };
        if q.len == qlen {
            self.stats.nodes[node].dropped += 1;
            let slot = self.ids.slot(&frame);
            self.stats.ids[slot].dropped += 1;
            self.stats.id_keys[slot] = Some(key_of(&frame));
            return Err(SubmitError::QueueFull { node, len: qlen });
        }
        let i = node * qlen + (q.head + q.len) % qlen;
        q.len += 1;
        let depth = q.len as u32;
        self.slots[i] = Pending {
            frame,
            submit_ns,
            tag,
        };
        let ns = &mut self.stats.nodes[node];
        ns.max_depth = ns.max_depth.max(depth);
        if let Some(d) = self.last_decision_ns
            && submit_ns < d
        {
            self.stats.violations += 1;
            self.stats.violation_max_ns = self.stats.violation_max_ns.max(d - submit_ns);
        }
        Ok(())
    }

    /// Counts a frame the sender refused itself because its queue was full (the `wire:`
    /// client decides that at send time, as the kernel would).
    pub fn record_refused(&mut self, node: usize, frame: &CanFrame) {
        if let Some(ns) = self.stats.nodes.get_mut(node) {
            ns.dropped += 1;
            let slot = self.ids.slot(frame);
            self.stats.ids[slot].dropped += 1;
            self.stats.id_keys[slot] = Some(key_of(frame));
        }
    }

    /// Counts `n` frames the sender refused itself whose identifiers are not known (their
    /// notices were lost; the node's total stays exact).
    pub fn record_refused_count(&mut self, node: usize, n: u64) {
        if let Some(ns) = self.stats.nodes.get_mut(node) {
            ns.dropped += n;
        }
    }

    /// When the frame on the wire completes (its end of frame), if one is on the wire.
    pub fn next_delivery_ns(&self) -> Option<u64> {
        self.in_flight.map(|f| f.eof_ns)
    }

    /// When the next arbitration will take place with what is queued now (after the frame on
    /// the wire, if one is: at its free time at the earliest), if anything is queued besides it.
    pub fn next_decision_ns(&self) -> Option<u64> {
        match self.in_flight {
            Some(f) => self
                .earliest_waiting(Some(f.node))
                .map(|t| t.max(f.free_ns)),
            None => self.earliest_waiting(None).map(|t| t.max(self.free_at_ns)),
        }
    }

    /// Nothing on the wire and nothing queued: only a new submission makes anything happen.
    pub fn is_quiet(&self) -> bool {
        self.in_flight.is_none() && self.earliest_head().is_none()
    }

    fn earliest_head(&self) -> Option<u64> {
        self.earliest_waiting(None)
    }

    /// The earliest submit time among the frames that will compete next: each node's head,
    /// or for `on_wire` (the node whose head is on the wire) the frame behind it.
    fn earliest_waiting(&self, on_wire: Option<usize>) -> Option<u64> {
        let qlen = self.cfg.queue_len;
        self.queues[..self.nodes_added]
            .iter()
            .enumerate()
            .filter_map(|(n, q)| {
                let skip = usize::from(on_wire == Some(n));
                (q.len > skip).then(|| self.slots[n * qlen + (q.head + skip) % qlen].submit_ns)
            })
            .min()
    }

    /// Advances the bus: delivers every frame whose end of frame is ≤ `deliver_until` (in time
    /// order, to `out`) and takes every arbitration decision due at ≤ `decide_until`. A hub
    /// with look-ahead L passes `decide_until = now − L` (submissions still in flight can
    /// arrive before the decisions that concern them) and `deliver_until = now`.
    pub fn poll(&mut self, decide_until: u64, deliver_until: u64, out: &mut impl FnMut(&Delivery)) {
        loop {
            if let Some(f) = self.in_flight {
                if f.eof_ns > deliver_until {
                    break;
                }
                self.complete(f, out);
                continue;
            }
            let Some(earliest) = self.earliest_head() else {
                break;
            };
            let t = earliest.max(self.free_at_ns);
            if t > decide_until {
                break;
            }
            self.decide(t);
        }
        let horizon = match self.in_flight {
            Some(f) => f.start_ns.min(decide_until),
            None => decide_until,
        };
        self.close_windows(horizon);
    }

    /// Arbitration at `t`: the heads submitted by then compete, the lowest field wins.
    fn decide(&mut self, t: u64) {
        let qlen = self.cfg.queue_len;
        let mut best: Option<(u32, usize)> = None;
        let mut tie = false;
        for (n, q) in self.queues[..self.nodes_added].iter().enumerate() {
            if q.len == 0 {
                continue;
            }
            let p = &self.slots[n * qlen + q.head];
            if p.submit_ns > t {
                continue;
            }
            let k = arbitration_key(&p.frame);
            match best {
                Some((bk, _)) if k > bk => {}
                Some((bk, _)) if k == bk => tie = true,
                _ => {
                    best = Some((k, n));
                    tie = false;
                }
            }
        }
        let Some((_, node)) = best else {
            return;
        };
        if tie {
            self.stats.arbitration_ties += 1;
        }
        let q = self.queues[node];
        let p = self.slots[node * qlen + q.head];
        let fb = bits::exact(&p.frame);
        let rate = self.cfg.bitrate_bps;
        self.in_flight = Some(InFlight {
            node,
            start_ns: t,
            eof_ns: t + bits::bits_to_ns(fb.to_eof(), rate),
            free_ns: t + bits::bits_to_ns(fb.total(), rate),
        });
        self.last_decision_ns = Some(t);
    }

    fn complete(&mut self, f: InFlight, out: &mut impl FnMut(&Delivery)) {
        let qlen = self.cfg.queue_len;
        let q = &mut self.queues[f.node];
        let p = self.slots[f.node * qlen + q.head];
        q.head = (q.head + 1) % qlen;
        q.len -= 1;
        self.in_flight = None;
        self.free_at_ns = f.free_ns;
        let d = Delivery {
            node: f.node,
            frame: p.frame,
            tag: p.tag,
            submit_ns: p.submit_ns,
            start_ns: f.start_ns,
            eof_ns: f.eof_ns,
        };
        let st = &mut *self.stats;
        st.frames += 1;
        st.busy_ns += f.free_ns - f.start_ns;
        st.nodes[f.node].sent += 1;
        let slot = self.ids.slot(&p.frame);
        st.id_keys[slot] = Some(key_of(&p.frame));
        let s = &mut st.ids[slot];
        s.count += 1;
        let queueing = f.start_ns.saturating_sub(p.submit_ns);
        let latency = f.eof_ns.saturating_sub(p.submit_ns);
        s.queueing.saturating_record(queueing.max(1));
        s.latency.saturating_record(latency.max(1));
        s.queueing_max_ns = s.queueing_max_ns.max(queueing);
        s.latency_max_ns = s.latency_max_ns.max(latency);
        self.add_busy(f.start_ns, f.free_ns);
        out(&d);
    }

    /// Books the occupied interval [s, e) into the 1 s windows (in time order).
    fn add_busy(&mut self, s: u64, e: u64) {
        // A frame that started before the open window (a late submission on an idle bus) is
        // booked into it.
        let mut s = s.max(self.window_start_ns);
        while s < e {
            let w_end = self.window_start_ns + WINDOW_NS;
            if s >= w_end {
                self.close_window();
                continue;
            }
            let seg = e.min(w_end);
            self.window_busy_ns += seg - s;
            s = seg;
        }
    }

    fn close_windows(&mut self, horizon: u64) {
        while horizon >= self.window_start_ns + WINDOW_NS {
            self.close_window();
        }
    }

    fn close_window(&mut self) {
        let load = self.window_busy_ns as f64 / WINDOW_NS as f64;
        let st = &mut *self.stats;
        st.windows += 1;
        st.window_load_sum += load;
        st.window_load_max = st.window_load_max.max(load);
        self.window_start_ns += WINDOW_NS;
        self.window_busy_ns = 0;
    }

    /// The running statistics block (since the last [`Bus::swap_stats`]).
    pub fn stats(&self) -> &BusStats {
        &self.stats
    }

    /// Hands out the running statistics block and continues in `spare` (which must be a
    /// [`BusStats::reset`] block of this bus's configuration); no allocation.
    pub fn swap_stats(&mut self, spare: &mut Box<BusStats>) {
        std::mem::swap(&mut self.stats, spare);
    }
}

fn key_of(f: &CanFrame) -> IdKey {
    IdKey {
        id: f.id(),
        extended: f.is_extended(),
    }
}
