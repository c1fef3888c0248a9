//! Measured samples for identification: the commanded lengths q_cmd, the measured pose x_M,
//! the measured forces f_M (spec ch. 6.1: W_S = {x_M, q_θ, f_M}), read from the data-set format
//! of docs/data-format.md via `crs_dataset`.

use cdpr_model::Pose;
use crs_dataset::{Dataset, Phase};

/// One measured sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// Running sample number of the data set.
    pub sample: u64,
    /// Reference pose index (samples of one pose share it; splits keep them together).
    pub pose_index: u64,
    pub phase: Phase,
    /// Commanded controlled lengths, m.
    pub q_cmd: Vec<f64>,
    /// Measured pose x_M.
    pub pose: Pose,
    /// Measured cable forces f_M, N.
    pub forces: Option<Vec<f64>>,
    /// Commanded reference pose, when recorded.
    pub pose_ref: Option<Pose>,
    /// Direction of motion per cable for the hysteresis candidate: +1 loading (the force rose
    /// since the previous sample), −1 unloading, 0 unknown (first sample). From the measured
    /// forces when present, else from the command (a shortened cable loads).
    pub direction: Vec<f64>,
}

/// Why a data set cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ObservationError {
    #[error("data set has {got} cables but the platform has {expected}")]
    CableCount { expected: usize, got: usize },
    #[error("data set has no samples")]
    Empty,
    #[error(
        "sample {sample}: force of cable {cable} is {force} N (must be > 0 for identification)"
    )]
    NonPositiveForce {
        sample: u64,
        cable: usize,
        force: f64,
    },
}

/// Converts a data set (already validated line by line by `crs_dataset`) into
/// observations for a platform with `m` cables.
pub fn from_dataset(ds: &Dataset, m: usize) -> Result<Vec<Observation>, ObservationError> {
    if ds.m != m {
        return Err(ObservationError::CableCount {
            expected: m,
            got: ds.m,
        });
    }
    if ds.samples.is_empty() {
        return Err(ObservationError::Empty);
    }
    let mut out: Vec<Observation> = Vec::with_capacity(ds.samples.len());
    for s in &ds.samples {
        if let Some((cable, &force)) = s
            .forces
            .as_ref()
            .and_then(|f| f.iter().enumerate().find(|(_, f)| **f <= 0.0))
        {
            return Err(ObservationError::NonPositiveForce {
                sample: s.sample,
                cable: cable + 1,
                force,
            });
        }
        let direction = match out.last() {
            None => vec![0.0; m],
            Some(prev) => (0..m)
                .map(|i| match (&s.forces, &prev.forces) {
                    (Some(f), Some(fp)) => sign(f[i] - fp[i]),
                    _ => sign(prev.q_cmd[i] - s.q_cmd[i]),
                })
                .collect(),
        };
        out.push(Observation {
            sample: s.sample,
            pose_index: s.pose_index,
            phase: s.phase,
            q_cmd: s.q_cmd.clone(),
            pose: s.pose,
            forces: s.forces.clone(),
            pose_ref: s.pose_ref,
            direction,
        });
    }
    Ok(out)
}

fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Splits by pose index: poses with `pose_index % every == every − 1` are held out (with all
/// their tension-test rows), the rest train. `every == 0` holds nothing out.
pub fn split(obs: &[Observation], every: u64) -> (Vec<Observation>, Vec<Observation>) {
    if every == 0 {
        return (obs.to_vec(), Vec::new());
    }
    obs.iter()
        .cloned()
        .partition(|o| o.pose_index % every != every - 1)
}
