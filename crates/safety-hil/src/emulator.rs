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
    /// When the emulation loop first reported this winch's injected force (0: not yet/none).
    pub force_override_applied_ns: u64,
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
            Some(&"drive") if f.len() == 9 => s.drives.push(DriveStatus {
                length_m: f[2].parse().ok()?,
                velocity_m_per_s: f[3].parse().ok()?,
                nmt: f[4].parse().ok()?,
                statusword: f[5].parse().ok()?,
                demand: f[6].parse().ok()?,
                left_follow_ns: f[7].parse().ok()?,
                force_override_applied_ns: f[8].parse().ok()?,
            }),
            _ => {}
        }
    }
    (header && s.drives.len() == 8).then_some(s)
}

pub const DEMAND_HOLD: u8 = 0;
pub const DEMAND_QUICK_STOP: u8 = 1;
pub const DEMAND_FOLLOW: u8 = 2;

/// What this harness injects through the winch emulator's control file: measured forces per
/// cable (None: the emulator's stand-in), the safety I/O node's reset key and e-stop button.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Control {
    pub forces: [Option<f64>; 8],
    pub reset_key: bool,
    pub estop: bool,
}

impl Control {
    /// The control file's text (`winch-emulator --control-file`): one line per injected
    /// value; an empty file is the emulator's own state.
    pub fn to_text(self) -> String {
        let mut t = String::new();
        for (i, f) in self.forces.iter().enumerate() {
            if let Some(f) = f {
                t.push_str(&format!("force {} {f}\n", i + 1));
            }
        }
        if self.reset_key {
            t.push_str("reset_key on\n");
        }
        if self.estop {
            t.push_str("estop pressed\n");
        }
        t
    }
}

/// Writes `c` as the emulator's control file in `dir` (atomically: rename; the emulator re-reads
/// it every 5 ms).
pub fn write_control(dir: &Path, c: &Control) -> Res<()> {
    let p = dir.join("emulator.control");
    let tmp = dir.join("emulator.control.tmp");
    std::fs::write(&tmp, c.to_text())
        .and_then(|_| std::fs::rename(&tmp, &p))
        .map_err(|e| format!("{}: {e}", p.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_files_parse_and_partial_ones_do_not() {
        let mut text = String::from("emulator 123 45 1 2 99\n");
        for i in 0..8 {
            text.push_str(&format!("drive {i} 6.5 0.0 5 4663 2 0 {}\n", 1000 + i));
        }
        let s = parse_status(&text).expect("a complete status");
        assert_eq!(
            (s.time_ns, s.syncs, s.inhibit, s.safety_trips),
            (123, 45, true, 2)
        );
        assert_eq!(s.drives.len(), 8);
        assert_eq!(s.drives[3].demand, DEMAND_FOLLOW);
        assert_eq!(s.drives[5].force_override_applied_ns, 1005);
        // A status written half (7 drives) or with a bad number is no status.
        let cut: String = text.lines().take(8).map(|l| format!("{l}\n")).collect();
        assert!(parse_status(&cut).is_none());
        assert!(parse_status(&text.replace("6.5", "six")).is_none());
        assert!(parse_status("").is_none());
    }

    #[test]
    fn the_control_file_says_what_is_injected_and_nothing_else() {
        let mut c = Control::default();
        assert_eq!(c.to_text(), "");
        c.forces[3] = Some(10_500.0);
        c.reset_key = true;
        assert_eq!(c.to_text(), "force 4 10500\nreset_key on\n");
        c.forces[3] = None;
        c.reset_key = false;
        c.estop = true;
        assert_eq!(c.to_text(), "estop pressed\n");
    }
}
