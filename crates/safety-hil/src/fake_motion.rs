//! The fake motion core: setpoints and the platform identity at the loop period, published by
//! this process (iceoryx2 node `shil-fake-motion-core`), with faults switched on through
//! [`FakeCtl`]: offsets (ramped at 0.1 m/s, 10 m/s²), NaN poses, sequence gaps, a wrong identity, a pose
//! jump with consistent lengths, a step with lying timestamps, a pause.

use crate::Res;
use crate::configs::HOME;
use crs_ipc::{IpcNode, JointSetpoint, PlatformIdentity, monotonic_ns};
use safety_monitor::identity::platform_identity;
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::platform::load_platform;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, AtomicU64, Ordering};

/// The offset ramp's speed and acceleration.
const OFFSET_SPEED_M_PER_S: f64 = 0.1;
const OFFSET_ACCEL_M_PER_S2: f64 = 10.0;

// Setpoints at 1 kHz with injectable faults.
#[derive(Default)]
pub struct FakeCtl {
    pub stop: AtomicBool,
    /// Stop publishing (frozen) while set.
    pub paused: AtomicBool,
    /// Offset target on cable `cable` in µm; the offset ramps towards it at 0.1 m/s.
    pub offset_target_um: AtomicI64,
    pub cable: AtomicU32,
    /// Publish NaN poses while set.
    pub nan: AtomicBool,
    /// Skip one sequence number every this many setpoints (0 = none).
    pub skip_every: AtomicU32,
    /// Announce a wrong platform identity while set.
    pub wrong_identity: AtomicBool,
    /// When the first wrong identity was announced (CLOCK_MONOTONIC ns; 0 = not yet).
    pub wrong_identity_sent_ns: AtomicU64,
    /// Publish the pose moved this far in x (µm) with CONSISTENT cable lengths, at once.
    pub pose_jump_um: AtomicI64,
    /// Move the pose in x by this much (µm) per setpoint from now on, with CONSISTENT cable
    /// lengths, from rest at once (no acceleration phase).
    pub pose_speed_um: AtomicI64,
    /// Add this (µm) to cable `cable` at once (no ramp) ...
    pub step_um: AtomicI64,
    /// ... and claim this much more time (ns) per setpoint in the timestamps from then on.
    pub timestamp_lie_ns: AtomicU64,
    /// First time the published |offset| exceeded 100 mm (CLOCK_MONOTONIC ns; 0 = never).
    pub crossed_ns: AtomicU64,
    /// Current offset (µm) and setpoints published.
    pub offset_um: AtomicI64,
    pub published: AtomicU64,
}

pub struct Fake {
    pub ctl: Arc<FakeCtl>,
    pub handle: Option<std::thread::JoinHandle<Res<()>>>,
}

impl Fake {
    pub fn start(prefix: &str, platform: &Path, period_ns: u64) -> Res<Fake> {
        let ctl = Arc::new(FakeCtl::default());
        let p = load_platform(platform).map_err(|e| e.to_string())?;
        let (c, prefix) = (ctl.clone(), prefix.to_string());
        let handle = std::thread::spawn(move || -> Res<()> {
            let node = IpcNode::with_prefix("shil-fake-motion-core", &prefix)
                .map_err(|e| e.to_string())?;
            let sp_pub = node
                .publisher::<JointSetpoint>()
                .map_err(|e| e.to_string())?;
            let id_pub = node
                .publisher::<PlatformIdentity>()
                .map_err(|e| e.to_string())?;
            let id = platform_identity(&p);
            let kin = StandardKinematics::new(&p);
            let mut q = [0.0; crs_ipc::MAX_CABLES];
            kin.lengths(&HOME, &mut q);
            let mut seq = 0u64;
            let mut lie_total = 0u64;
            let mut offset_um = 0i64;
            let mut offset_vel = 0.0f64;
            let mut moved_um = 0i64;
            let mut next = monotonic_ns();
            let mut n = 0u64;
            while !c.stop.load(Ordering::Relaxed) {
                next += period_ns;
                crs_rt::sleep_until(next);
                let now = monotonic_ns();
                if now > next + period_ns / 2 {
                    // This thread was stalled (a loaded host, the guest): skip the missed
                    // ticks, never publish a burst. A burst is a real velocity demand (several
                    // setpoints' motion within one SYNC), which drive-io's acceleration limit
                    // rightly refuses; motion-core ticks on its own clock.
                    next = now;
                }
                if c.paused.load(Ordering::Relaxed) {
                    continue;
                }
                if n.is_multiple_of(100) {
                    let mut h = *id.as_bytes();
                    let wrong = c.wrong_identity.load(Ordering::Relaxed);
                    if wrong {
                        h[31] ^= 0x5A;
                    }
                    let _ = id_pub.publish(&PlatformIdentity::new(crs_ipc::PlatformId::new(h), 8));
                    if wrong && c.wrong_identity_sent_ns.load(Ordering::Relaxed) == 0 {
                        c.wrong_identity_sent_ns
                            .store(monotonic_ns(), Ordering::Relaxed);
                    }
                }
                n += 1;
                let target = c.offset_target_um.load(Ordering::Relaxed);
                // 0.1 m/s reached and left at OFFSET_ACCEL_M_PER_S2 (below drive-io's step
                // limit of 50 m/s²: a velocity step out of a hold is refused there), braking
                // so as to stop at the target.
                let dt = period_ns as f64 * 1e-9;
                let d = (target - offset_um) as f64 * 1e-6;
                let v_goal = d.signum()
                    * (2.0 * OFFSET_ACCEL_M_PER_S2 * d.abs())
                        .sqrt()
                        .min(OFFSET_SPEED_M_PER_S);
                let dv = OFFSET_ACCEL_M_PER_S2 * dt;
                offset_vel = offset_vel + (v_goal - offset_vel).clamp(-dv, dv);
                let step = (offset_vel * dt * 1e6).round() as i64;
                offset_um += if (target - offset_um).abs() <= step.abs().max(1) {
                    offset_vel = 0.0;
                    target - offset_um
                } else {
                    step
                };
                seq += 1;
                let skip = c.skip_every.load(Ordering::Relaxed);
                if skip > 0 && seq.is_multiple_of(u64::from(skip)) {
                    seq += 1;
                }
                lie_total += c.timestamp_lie_ns.load(Ordering::Relaxed);
                let mut s = JointSetpoint {
                    cable_count: 8,
                    sequence: seq,
                    timestamp_ns: now + lie_total,
                    pose: HOME,
                    cable_length_m: q,
                    ..JointSetpoint::default()
                };
                moved_um += c.pose_speed_um.load(Ordering::Relaxed);
                let jump = c.pose_jump_um.load(Ordering::Relaxed) + moved_um;
                if jump != 0 {
                    s.pose[0] += jump as f64 * 1e-6;
                    kin.lengths(&s.pose, &mut s.cable_length_m);
                }
                let cable = (c.cable.load(Ordering::Relaxed) as usize).min(7);
                s.cable_length_m[cable] +=
                    (offset_um + c.step_um.load(Ordering::Relaxed)) as f64 * 1e-6;
                if c.nan.load(Ordering::Relaxed) {
                    s.pose[3] = f64::NAN;
                }
                // The spec's 100 mm (the harness's monitor runs with dq_limit_mm = 100).
                let limit_um = (safety_monitor::config::DELTA_Q_LIMIT_M * 1e6).round() as i64;
                if offset_um.abs() > limit_um && c.crossed_ns.load(Ordering::Relaxed) == 0 {
                    c.crossed_ns.store(now, Ordering::Relaxed);
                }
                sp_pub.publish(&s).map_err(|e| e.to_string())?;
                c.offset_um.store(offset_um, Ordering::Relaxed);
                c.published.fetch_add(1, Ordering::Relaxed);
            }
            Ok(())
        });
        Ok(Fake {
            ctl,
            handle: Some(handle),
        })
    }

    pub fn stop(&mut self) -> Res<()> {
        self.ctl.stop.store(true, Ordering::Relaxed);
        match self.handle.take() {
            Some(h) => h
                .join()
                .map_err(|_| "fake publisher panicked".to_string())?,
            None => Ok(()),
        }
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}
