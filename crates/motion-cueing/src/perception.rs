//! The perception of a whole run: the vehicle's motion and the cabin's, each through the same
//! vestibular models ([`crate::vestibular`]), compared per axis — raw (what the cabin
//! reproduces of the vehicle's specific force and angular velocity) and perceived (what the
//! rider in the cabin perceives against what the vehicle's occupant did): RMS, RMS error,
//! correlation and the share of time the error exceeds the perception threshold.

use crate::cabin::Felt;
use crate::lti::LtiError;
use crate::vehicle::VehicleSample;
use crate::vestibular::{AxisError, Vestibular, VestibularParams, axis_error};
use nalgebra::Vector3;

/// Signals of a run on one time base (SI, head axes), for the report and the plots.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PerceptionSeries {
    pub t_s: Vec<f64>,
    pub vehicle_f: Vec<Vector3<f64>>,
    pub vehicle_w: Vec<Vector3<f64>>,
    pub cabin_f: Vec<Vector3<f64>>,
    pub cabin_w: Vec<Vector3<f64>>,
    pub perceived_vehicle_f: Vec<Vector3<f64>>,
    pub perceived_vehicle_w: Vec<Vector3<f64>>,
    pub perceived_cabin_f: Vec<Vector3<f64>>,
    pub perceived_cabin_w: Vec<Vector3<f64>>,
}

/// Cabin against vehicle on one axis: raw and perceived.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct AxisReport {
    pub raw: AxisError,
    pub perceived: AxisError,
}

/// The comparison for the three specific-force and the three angular-velocity axes.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PerceptionReport {
    /// x, y, z (m/s²).
    pub specific_force: [AxisReport; 3],
    /// Roll, pitch, yaw rates (rad/s).
    pub angular_velocity: [AxisReport; 3],
    pub samples: usize,
    pub dt_s: f64,
}

/// Runs both models over `samples` (time, vehicle motion, what the cabin's rider felt), taken
/// every `dt` seconds.
pub fn analyse(
    params: &VestibularParams,
    dt: f64,
    samples: impl IntoIterator<Item = (f64, VehicleSample, Felt)>,
) -> Result<(PerceptionReport, PerceptionSeries), LtiError> {
    let v = Vestibular::new(*params, dt)?;
    let mut s = PerceptionSeries::default();
    let mut pv: Option<crate::vestibular::Perceiver> = None;
    let mut pc: Option<crate::vestibular::Perceiver> = None;
    for (t, veh, cab) in samples {
        // Both riders start settled at rest, upright in gravity (not on the first sample: the
        // cabin may still be finishing its move to the neutral pose).
        let rest = Vector3::new(0.0, 0.0, cdpr_model::dynamics::GRAVITY_M_PER_S2);
        let pvs = pv.get_or_insert_with(|| v.perceiver(&rest));
        let (fv, wv) = v.step(pvs, &veh.specific_force, &veh.angular_velocity);
        let pcs = pc.get_or_insert_with(|| v.perceiver(&rest));
        let (fc, wc) = v.step(pcs, &cab.specific_force, &cab.angular_velocity);
        s.t_s.push(t);
        s.vehicle_f.push(veh.specific_force);
        s.vehicle_w.push(veh.angular_velocity);
        s.cabin_f.push(cab.specific_force);
        s.cabin_w.push(cab.angular_velocity);
        s.perceived_vehicle_f.push(fv);
        s.perceived_vehicle_w.push(wv);
        s.perceived_cabin_f.push(fc);
        s.perceived_cabin_w.push(wc);
    }
    let col = |x: &[Vector3<f64>], k: usize| -> Vec<f64> { x.iter().map(|v| v[k]).collect() };
    let report = |r: &[Vector3<f64>],
                  c: &[Vector3<f64>],
                  pr: &[Vector3<f64>],
                  pcab: &[Vector3<f64>],
                  k: usize,
                  th: f64| AxisReport {
        raw: axis_error(&col(r, k), &col(c, k), th),
        perceived: axis_error(&col(pr, k), &col(pcab, k), th),
    };
    let (tf, tw) = (
        params.threshold_specific_force,
        params.threshold_angular_velocity,
    );
    let rep = PerceptionReport {
        specific_force: [0, 1, 2].map(|k| {
            report(
                &s.vehicle_f,
                &s.cabin_f,
                &s.perceived_vehicle_f,
                &s.perceived_cabin_f,
                k,
                tf,
            )
        }),
        angular_velocity: [0, 1, 2].map(|k| {
            report(
                &s.vehicle_w,
                &s.cabin_w,
                &s.perceived_vehicle_w,
                &s.perceived_cabin_w,
                k,
                tw,
            )
        }),
        samples: s.t_s.len(),
        dt_s: dt,
    };
    Ok((rep, s))
}

impl PerceptionReport {
    /// A markdown table: per axis RMS of the vehicle, of the cabin, RMS error and correlation,
    /// raw and perceived, and the share above threshold (perceived). A correlation that is
    /// undefined (a signal that does not vary) reads "–".
    pub fn markdown(&self) -> String {
        let corr = |c: Option<f64>| c.map_or("–".to_string(), |c| format!("{c:.2}"));
        let mut s = String::from(
            "| axis | unit | vehicle RMS | cabin RMS | raw RMS error | raw corr. | perceived RMS error | perceived corr. | perceived error > threshold |\n|---|---|---|---|---|---|---|---|---|\n",
        );
        for (name, unit, r, scale) in [
            ("f_x", "m/s²", &self.specific_force[0], 1.0),
            ("f_y", "m/s²", &self.specific_force[1], 1.0),
            ("f_z", "m/s²", &self.specific_force[2], 1.0),
            (
                "ω_x",
                "°/s",
                &self.angular_velocity[0],
                180.0 / std::f64::consts::PI,
            ),
            (
                "ω_y",
                "°/s",
                &self.angular_velocity[1],
                180.0 / std::f64::consts::PI,
            ),
            (
                "ω_z",
                "°/s",
                &self.angular_velocity[2],
                180.0 / std::f64::consts::PI,
            ),
        ] {
            s.push_str(&format!(
                "| {name} | {unit} | {:.3} | {:.3} | {:.3} | {} | {:.3} | {} | {:.0} % |\n",
                r.raw.rms_reference * scale,
                r.raw.rms_signal * scale,
                r.raw.rms_error * scale,
                corr(r.raw.correlation),
                r.perceived.rms_error * scale,
                corr(r.perceived.correlation),
                r.perceived.above_threshold * 100.0
            ));
        }
        s
    }
}
