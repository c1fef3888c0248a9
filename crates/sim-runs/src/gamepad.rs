//! A game controller as the helicopter pilot (`crs sim --source helicopter --pilot gamepad`),
//! read through the Linux joystick interface (`/dev/input/js*`, the kernel's joydev: every USB
//! or Bluetooth game controller appears there; no system library, unlike gilrs' libudev).
//! A reader thread blocks on the device and keeps the newest axis values; the 1 kHz model
//! thread polls them without blocking ([`LivePilot::poll`]).
//!
//! Axes (the common layout of XInput-style pads under joydev): 0 left stick x → pedals (yaw),
//! 1 left stick y → collective (stick up = more thrust; centred = hover), 3 right stick x →
//! cyclic roll (stick right flies towards +y), 4 right stick y → cyclic pitch (stick forward
//! flies towards +x). A controller that disconnects centres every input (hover, hands off).

use crate::pilot::LivePilot;
use ride_physics::PilotInput;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicI32, Ordering};

/// Where controllers appear.
pub const JOYSTICK_DIR: &str = "/dev/input";

/// One `struct js_event` of linux/joystick.h: time (ms), value, type, number (8 bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JsEvent {
    pub time_ms: u32,
    pub value: i16,
    pub kind: u8,
    pub number: u8,
}

const JS_EVENT_AXIS: u8 = 0x02;
const JS_EVENT_INIT: u8 = 0x80;

impl JsEvent {
    pub fn decode(b: &[u8; 8]) -> Self {
        JsEvent {
            time_ms: u32::from_ne_bytes([b[0], b[1], b[2], b[3]]),
            value: i16::from_ne_bytes([b[4], b[5]]),
            kind: b[6],
            number: b[7],
        }
    }
}

/// The newest axis values (−32767 … 32767), shared between the reader and the model thread.
#[derive(Default)]
pub struct Axes([AtomicI32; 8]);

impl Axes {
    /// Applies one event (axis events only; the initial-state flag is ignored).
    pub fn apply(&self, e: &JsEvent) {
        if e.kind & !JS_EVENT_INIT == JS_EVENT_AXIS && (e.number as usize) < self.0.len() {
            self.0[e.number as usize].store(e.value as i32, Ordering::Relaxed);
        }
    }

    /// Centres every axis (device gone).
    pub fn centre(&self) {
        self.0.iter().for_each(|a| a.store(0, Ordering::Relaxed));
    }

    /// The pilot input of the module's mapping.
    pub fn input(&self) -> PilotInput {
        let a = |k: usize| (self.0[k].load(Ordering::Relaxed) as f64 / 32767.0).clamp(-1.0, 1.0);
        PilotInput {
            collective: (0.5 - 0.5 * a(1)).clamp(0.0, 1.0),
            roll: -a(3),
            pitch: -a(4),
            yaw: a(0),
        }
    }
}

struct Gamepad(Arc<Axes>);

impl LivePilot for Gamepad {
    fn poll(&mut self) -> PilotInput {
        self.0.input()
    }
}

/// The joystick devices present in `dir` (`js0`, `js1`, …), sorted.
pub fn devices(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("js"))
        })
        .collect();
    v.sort();
    v
}

/// Why no game controller could be flown; each message says what to do.
#[derive(Debug, thiserror::Error)]
pub enum GamepadError {
    /// No `js*` device in `dir`.
    #[error(
        "no game controller found ({}/js* does not exist): connect one (USB or Bluetooth; \
         the kernel's joydev module must be loaded) or fly a pilot CSV or a script \
         (--pilot FILE.csv | script:walls)",
        dir.display()
    )]
    NoController { dir: PathBuf },
    /// The device exists but does not open (usually permissions).
    #[error(
        "game controller {}: cannot open: {source} (permissions: the user needs the `input` group)",
        path.display()
    )]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The reader thread did not start.
    #[error("{0}")]
    Thread(#[source] std::io::Error),
}

/// Opens the first game controller; without one, an error that says what to do.
pub fn open() -> Result<Box<dyn LivePilot>, GamepadError> {
    open_in(Path::new(JOYSTICK_DIR))
}

/// [`open`] in another directory (tests).
pub fn open_in(dir: &Path) -> Result<Box<dyn LivePilot>, GamepadError> {
    let Some(path) = devices(dir).into_iter().next() else {
        return Err(GamepadError::NoController {
            dir: dir.to_path_buf(),
        });
    };
    let mut file = match std::fs::File::open(&path) {
        Ok(f) => f,
        Err(source) => return Err(GamepadError::Open { path, source }),
    };
    let axes = Arc::new(Axes::default());
    let a = axes.clone();
    std::thread::Builder::new()
        .name("crs-gamepad".into())
        .spawn(move || {
            let mut b = [0u8; 8];
            while file.read_exact(&mut b).is_ok() {
                a.apply(&JsEvent::decode(&b));
            }
            // Unplugged or read error: hands off.
            a.centre();
        })
        .map_err(GamepadError::Thread)?;
    Ok(Box::new(Gamepad(axes)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(value: i16, number: u8) -> [u8; 8] {
        let mut b = [0u8; 8];
        b[0..4].copy_from_slice(&1234u32.to_ne_bytes());
        b[4..6].copy_from_slice(&value.to_ne_bytes());
        b[6] = JS_EVENT_AXIS;
        b[7] = number;
        b
    }

    #[test]
    fn axis_events_map_to_the_pilot_controls() {
        let axes = Axes::default();
        assert_eq!(axes.input(), PilotInput::HOVER);
        for (v, n) in [(-32767, 1), (32767, 3), (-32767, 4), (16384, 0)] {
            axes.apply(&JsEvent::decode(&ev(v, n)));
        }
        let u = axes.input();
        assert_eq!((u.collective, u.roll, u.pitch), (1.0, -1.0, 1.0));
        assert!((u.yaw - 0.5).abs() < 1e-4);
        // Buttons (type 1) do not move axes.
        let mut b = ev(1, 1);
        b[6] = 0x01;
        axes.apply(&JsEvent::decode(&b));
        assert_eq!(axes.input().collective, 1.0);
        axes.centre();
        assert_eq!(axes.input(), PilotInput::HOVER);
    }

    #[test]
    fn no_controller_is_a_clear_message_not_a_crash() {
        let dir = std::env::temp_dir().join(format!("crs-no-js-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let e = open_in(&dir).err().unwrap();
        assert!(matches!(e, GamepadError::NoController { .. }), "{e}");
        let e = e.to_string();
        assert!(
            e.starts_with("no game controller found") && e.contains("--pilot FILE.csv"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
