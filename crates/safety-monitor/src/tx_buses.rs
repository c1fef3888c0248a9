//! The monitor's sending side on every CAN interface the drives are on: the NMT stop and the
//! safety heartbeat pairs go to every interface, a drive's quick stop to its own.
//!
//! [`TxBuses`] is itself a [`CanBus`] whose `send` reaches every interface, so the stop path's
//! retry and escalation ([`crate::stop_path`]) work unchanged: a send that failed on some
//! interfaces (a full TX queue) fails as a whole, and sending the SAME frame again right after
//! goes only to the interfaces that did not take it — a retry never duplicates a heartbeat pair
//! on an interface that already has it (a repeated counter there would look like a replay).

use can_transport::{CanBus, CanError, CanFrame, RxFrame};
use std::time::Duration;

/// At most this many interfaces (drive-io's limit).
pub const MAX_INTERFACES: usize = 8;

/// One transmit socket per interface (see the module docs).
pub struct TxBuses {
    buses: Vec<Box<dyn CanBus>>,
    /// The frame of the last send that failed somewhere, and the interfaces still missing it.
    pending: Option<(CanFrame, u8)>,
    /// Interfaces where the doubled safety frames travel (bit k = interface k).
    safety_mask: u8,
}

impl TxBuses {
    /// `buses[k]` = interface k (at most [`MAX_INTERFACES`]; more are ignored); the safety
    /// frames go on `safety_interfaces` (every interface if empty).
    pub fn new(mut buses: Vec<Box<dyn CanBus>>, safety_interfaces: &[usize]) -> Self {
        buses.truncate(MAX_INTERFACES);
        let all = mask_of(buses.len());
        let safety_mask = match safety_interfaces
            .iter()
            .filter(|k| **k < buses.len())
            .fold(0u8, |m, k| m | (1 << k))
        {
            0 => all,
            m => m,
        };
        Self {
            buses,
            pending: None,
            safety_mask,
        }
    }

    /// The interfaces of the safety frames (the safety I/O node's), as a bus of its own.
    pub fn safety(&mut self) -> Subset<'_> {
        let m = self.safety_mask;
        Subset(self, m)
    }

    fn send_masked(&mut self, frame: &CanFrame, mask: u8) -> Result<(), CanError> {
        let targets = match self.pending {
            Some((f, missing)) if f == *frame => missing & mask,
            _ => mask,
        };
        let mut missing = 0u8;
        let mut other: Option<CanError> = None;
        for (k, bus) in self.buses.iter_mut().enumerate() {
            if targets & (1 << k) == 0 {
                continue;
            }
            match bus.send(frame) {
                Ok(()) => {}
                Err(e @ CanError::TxFull { .. }) => {
                    missing |= 1 << k;
                    other.get_or_insert(e);
                }
                Err(e) => {
                    missing |= 1 << k;
                    // A hard error outranks a full queue: report it.
                    other = Some(e);
                }
            }
        }
        if missing == 0 {
            self.pending = None;
            Ok(())
        } else {
            self.pending = Some((*frame, missing));
            Err(other.unwrap_or(CanError::TxFull {
                iface: self.interface().to_string(),
            }))
        }
    }

    pub fn len(&self) -> usize {
        self.buses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.buses.is_empty()
    }

    /// The sending socket of interface `iface` (a drive's own frames: its quick stop).
    pub fn on(&mut self, iface: usize) -> Option<&mut dyn CanBus> {
        match self.buses.get_mut(iface) {
            Some(b) => Some(b.as_mut()),
            None => None,
        }
    }
}

fn mask_of(n: usize) -> u8 {
    if n >= 8 { u8::MAX } else { (1u8 << n) - 1 }
}

/// Some of the interfaces, as one bus (the safety frames' interfaces).
pub struct Subset<'a>(&'a mut TxBuses, u8);

impl CanBus for Subset<'_> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        self.0.send_masked(frame, self.1)
    }
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        self.0.recv_timeout(timeout)
    }
    fn interface(&self) -> &str {
        self.0.interface()
    }
}

impl CanBus for TxBuses {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let all = mask_of(self.buses.len());
        self.send_masked(frame, all)
    }

    /// The monitor never receives on its sending sockets (its reader has its own).
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        std::thread::sleep(timeout);
        Ok(None)
    }

    fn interface(&self) -> &str {
        self.buses.first().map_or("none", |b| b.interface())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A bus that records what it sent and refuses the first `fail` sends.
    struct Rec {
        sent: Arc<Mutex<Vec<CanFrame>>>,
        fail: u32,
    }

    impl CanBus for Rec {
        fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
            if self.fail > 0 {
                self.fail -= 1;
                return Err(CanError::TxFull {
                    iface: "rec".into(),
                });
            }
            self.sent.lock().unwrap().push(*frame);
            Ok(())
        }
        fn recv_timeout(&mut self, _: Duration) -> Result<Option<RxFrame>, CanError> {
            Ok(None)
        }
        fn interface(&self) -> &str {
            "rec"
        }
    }

    #[test]
    fn a_retry_reaches_only_the_interfaces_that_missed_the_frame() {
        let logs: Vec<Arc<Mutex<Vec<CanFrame>>>> = (0..3).map(|_| Arc::default()).collect();
        let fails = [0, 1, 0];
        let buses: Vec<Box<dyn CanBus>> = logs
            .iter()
            .zip(fails)
            .map(|(l, fail)| {
                Box::new(Rec {
                    sent: l.clone(),
                    fail,
                }) as Box<dyn CanBus>
            })
            .collect();
        let mut tx = TxBuses::new(buses, &[1]);
        let f = CanFrame::new(0x101, &[1, 2, 3]).unwrap();
        assert!(tx.send(&f).is_err(), "interface 1 refused it");
        tx.send(&f).unwrap();
        let g = CanFrame::new(0x000, &[2, 0]).unwrap();
        tx.send(&g).unwrap();
        for (k, l) in logs.iter().enumerate() {
            assert_eq!(
                *l.lock().unwrap(),
                vec![f, g],
                "interface {k}: each frame once"
            );
        }
        // A drive's own frame goes to its interface only.
        let q = CanFrame::new(0x201, &[2, 0, 0, 0, 0, 0]).unwrap();
        tx.on(2).unwrap().send(&q).unwrap();
        assert_eq!(logs[2].lock().unwrap().len(), 3);
        assert_eq!(logs[0].lock().unwrap().len(), 2);
        // The safety frames go to the safety interface only.
        let h = CanFrame::new(0x102, &[9; 8]).unwrap();
        tx.safety().send(&h).unwrap();
        assert_eq!(logs[1].lock().unwrap().last(), Some(&h));
        assert_ne!(logs[0].lock().unwrap().last(), Some(&h));
    }
}
