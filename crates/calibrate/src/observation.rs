//! Measured samples for identification: the commanded lengths q_cmd, the measured pose x_M,
//! the measured forces f_M (spec ch. 6.1: W_S = {x_M, q_θ, f_M}), read from the data-set format
//! of docs/data-format.md via `crs_dataset`.

use cdpr_model::Pose;
use crs_dataset::{Dataset, Phase};
use serde::Serialize;

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
    /// since the previous sample), −1 unloading, 0 unknown (first sample), held while the
    /// force does not change. From the measured forces when present, else from the command (a
    /// shortened cable loads).
    pub direction: Vec<f64>,
    /// The same, but a reversal counts only once the force has moved back by more than
    /// [`FORCE_DIRECTION_BAND_N`] from its extreme since the last switch (noise does not flip
    /// it; a friction that needs a force change to slip neither).
    pub direction_beyond_noise: Vec<f64>,
    /// Direction of the winch per cable from the command sequence: +1 after the cable's last
    /// command change lengthened it, −1 after it shortened it, HELD while its command does not
    /// change (a winch at rest stays on the branch it arrived on); 0 before the first change
    /// (the data set does not say how the first row was reached).
    pub command_direction: Vec<f64>,
}

/// Where the hysteresis candidate takes a cable's direction of motion from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub enum DirectionSource {
    /// The change of its measured force since the previous row (loading / unloading).
    Force,
    /// The same, a reversal counting once the force moved back beyond the measurement noise
    /// ([`FORCE_DIRECTION_BAND_N`]).
    ForceBeyondNoise,
    /// Its command sequence, held while the command does not change (the winch's direction).
    Command,
}

impl Observation {
    /// Direction of loading per cable (+1 loading, −1 unloading) from `source`: the force
    /// change, or the command sequence (a shortening winch loads its cable).
    #[inline]
    pub fn loading(&self, source: DirectionSource, i: usize) -> f64 {
        match source {
            DirectionSource::Force => self.direction[i],
            DirectionSource::ForceBeyondNoise => self.direction_beyond_noise[i],
            DirectionSource::Command => -self.command_direction[i],
        }
    }
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
    // Force of each cable at its direction's last switch (or extreme since), without and with
    // the noise band.
    let mut extreme_raw = vec![0.0; m];
    let mut extreme = vec![0.0; m];
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
        let prev = out.last();
        let direction = force_direction(
            prev.map(|p| (p.direction.as_slice(), p)),
            s,
            &mut extreme_raw,
            0.0,
        );
        let direction_beyond_noise = force_direction(
            prev.map(|p| (p.direction_beyond_noise.as_slice(), p)),
            s,
            &mut extreme,
            FORCE_DIRECTION_BAND_N,
        );
        let command_direction = match out.last() {
            None => vec![0.0; m],
            Some(prev) => (0..m)
                .map(|i| {
                    let d = sign(s.q_cmd[i] - prev.q_cmd[i]);
                    if d == 0.0 {
                        prev.command_direction[i]
                    } else {
                        d
                    }
                })
                .collect(),
        };
        out.push(Observation {
            command_direction,
            direction_beyond_noise,
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

/// Direction of loading of every cable at sample `s` after the previous sample (its direction
/// state and observation), with reversals counted beyond `band` from the force's extreme since
/// the last switch (updated in `extreme`); without forces from the command.
fn force_direction(
    prev: Option<(&[f64], &Observation)>,
    s: &crs_dataset::Sample,
    extreme: &mut [f64],
    band: f64,
) -> Vec<f64> {
    let m = s.q_cmd.len();
    match (prev, &s.forces) {
        (None, Some(f)) => {
            extreme.copy_from_slice(f);
            vec![0.0; m]
        }
        (None, None) => vec![0.0; m],
        (Some((dir, p)), Some(f)) if p.forces.is_some() => (0..m)
            .map(|i| {
                let (d, e) = schmitt(dir[i], extreme[i], f[i], band);
                extreme[i] = e;
                d
            })
            .collect(),
        (Some((_, p)), _) => (0..m).map(|i| sign(p.q_cmd[i] - s.q_cmd[i])).collect(),
    }
}

/// A measured force change smaller than this does not reverse a cable's direction of loading:
/// the difference of two readings with the spec's 20 N load-cell noise scatters by 28 N (1σ),
/// so a reversal is told from the noise at 3.5σ. The direction is held until the force has
/// moved this far back from its extreme since the last switch (a Schmitt trigger).
pub const FORCE_DIRECTION_BAND_N: f64 = 100.0;

/// Direction state (±1, 0 before the first move) after the input moved to `u`, with its
/// extreme since the last switch `ext`; a reversal needs `band` from the extreme.
fn schmitt(d: f64, ext: f64, u: f64, band: f64) -> (f64, f64) {
    if d > 0.0 {
        if u > ext {
            (1.0, u)
        } else if u < ext - band {
            (-1.0, u)
        } else {
            (d, ext)
        }
    } else if d < 0.0 {
        if u < ext {
            (-1.0, u)
        } else if u > ext + band {
            (1.0, u)
        } else {
            (d, ext)
        }
    } else if u > ext + band {
        (1.0, u)
    } else if u < ext - band {
        (-1.0, u)
    } else {
        (0.0, ext)
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use cdpr_model::Pose;
    use crs_dataset::Sample;

    fn ds(rows: &[([f64; 2], [f64; 2])]) -> Dataset {
        let mut d = Dataset::new(2, true, false);
        d.samples = rows
            .iter()
            .enumerate()
            .map(|(k, (q, f))| Sample {
                sample: k as u64,
                pose_index: k as u64,
                phase: Phase::Pose,
                q_cmd: q.to_vec(),
                pose: Pose::default(),
                forces: Some(f.to_vec()),
                pose_ref: None,
            })
            .collect();
        d
    }

    /// The winch's direction comes from its last command change and is held while the command
    /// rests; before the first change it is unknown (0).
    #[test]
    fn the_command_direction_is_held_while_the_command_rests() {
        let o = from_dataset(
            &ds(&[
                ([5.0, 6.0], [1000.0; 2]),
                ([5.1, 6.0], [1000.0; 2]),
                ([5.1, 5.9], [1000.0; 2]),
                ([5.1, 5.9], [1000.0; 2]),
                ([5.0, 5.9], [1000.0; 2]),
            ]),
            2,
        )
        .unwrap();
        let d: Vec<Vec<f64>> = o.iter().map(|o| o.command_direction.clone()).collect();
        assert_eq!(
            d,
            vec![
                vec![0.0, 0.0],
                vec![1.0, 0.0],
                vec![1.0, -1.0],
                vec![1.0, -1.0],
                vec![-1.0, -1.0]
            ]
        );
    }

    /// The force direction switches only when the force has moved back from its extreme by
    /// more than the band (measurement noise does not flip it).
    #[test]
    fn the_force_direction_needs_a_reversal_beyond_the_noise_band() {
        let b = FORCE_DIRECTION_BAND_N;
        let f = |v: f64| ([5.0, 5.0], [v, 1000.0]);
        let o = from_dataset(
            &ds(&[
                f(1000.0),
                f(1000.0 + 0.5 * b),
                f(1000.0 + 1.5 * b),
                f(1000.0 + 1.2 * b),
                f(1000.0 + 3.0 * b),
                f(1000.0 + 1.9 * b),
            ]),
            2,
        )
        .unwrap();
        let d: Vec<f64> = o.iter().map(|o| o.direction_beyond_noise[0]).collect();
        assert_eq!(d, vec![0.0, 0.0, 1.0, 1.0, 1.0, -1.0]);
        // Without the band every reversal counts.
        let d: Vec<f64> = o.iter().map(|o| o.direction[0]).collect();
        assert_eq!(d, vec![0.0, 1.0, 1.0, -1.0, 1.0, -1.0]);
    }
}
