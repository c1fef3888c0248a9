//! Where a ride's pilot inputs come from: a recorded or scripted track, or a live source (a
//! game controller, [`crate::gamepad`]) polled once per model step.

use ride_physics::{PilotInput, PilotTrack};

/// Where the pilot's inputs come from at run time.
pub enum Pilot {
    Track(PilotTrack),
    Live(Box<dyn LivePilot>),
}

/// A pilot read live (a game controller): polled once per model step, must not block.
pub trait LivePilot: Send {
    fn poll(&mut self) -> PilotInput;
}
