//! The winch emulator's files: its status file (true lengths, velocities, NMT state, demand and
//! the safety watch of every drive, written by the emulator) and its control file (a measured
//! force to report, written here).

use crate::Res;
use std::path::Path;

#[derive(Debug, Clone, Copy, Default)]
pub struct DriveStatus {
    pub length_m: f64,
    pub velocity_m_per_s: f64,
    pub nmt: u8,
    pub statusword: u16,
    pub demand: u8,
    pub left_follow_ns: u64,
}

#[derive(Debug, Clone, Default)]
pub struct EmuStatus {
    pub time_ns: u64,
    pub syncs: u64,
    pub inhibit: bool,
    pub safety_trips: u64,
    pub safety_tripped_ns: u64,
    pub drives: Vec<DriveStatus>,
}

pub fn parse_status(text: &str) -> Option<EmuStatus> {
    let mut s = EmuStatus::default();
    let mut header = false;
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"emulator") if f.len() == 6 => {
                s.time_ns = f[1].parse().ok()?;
                s.syncs = f[2].parse().ok()?;
                s.inhibit = f[3] == "1";
                s.safety_trips = f[4].parse().ok()?;
                s.safety_tripped_ns = f[5].parse().ok()?;
                header = true;
            }
            Some(&"drive") if f.len() == 8 => s.drives.push(DriveStatus {
                length_m: f[2].parse().ok()?,
                velocity_m_per_s: f[3].parse().ok()?,
                nmt: f[4].parse().ok()?,
                statusword: f[5].parse().ok()?,
                demand: f[6].parse().ok()?,
                left_follow_ns: f[7].parse().ok()?,
            }),
            _ => {}
        }
    }
    (header && s.drives.len() == 8).then_some(s)
}

pub const DEMAND_HOLD: u8 = 0;
pub const DEMAND_QUICK_STOP: u8 = 1;
pub const DEMAND_FOLLOW: u8 = 2;

/// The winch emulator reports `force_n` as cable `cable`'s (1-based) measured force from its
/// next SYNC on (its `--control-file`; the emulator has no physics, its force is a constant
/// pretension otherwise).
pub fn inject_force(dir: &Path, cable: usize, force_n: f64) -> Res<()> {
    let p = dir.join("emulator.control");
    let tmp = dir.join("emulator.control.tmp");
    std::fs::write(&tmp, format!("force {cable} {force_n}\n"))
        .and_then(|_| std::fs::rename(&tmp, &p))
        .map_err(|e| format!("{}: {e}", p.display()))
}
