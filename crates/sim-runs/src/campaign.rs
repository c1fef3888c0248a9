//! Calibration campaigns: generation (Halton poses with a force margin, toured nearest-first
//! and checked with motion-core's own configure step), timing for rests at each pose, and the
//! waypoint CSV motion-core reads (`trajectory::read_waypoints`).

use cdpr_model::Pose;
use cdpr_model::config::Platform;
use cdpr_model::offset_target::OffsetTarget;
use motion_core::daemon::lifecycle::Configured;
use motion_core::daemon::trajectory::{self, PlannerLimits, PlanningFailed, Waypoint};
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    #[error("--poses must be ≥ 1 and --fraction in (0, 1]")]
    Arguments,
    #[error(
        "only {found} of {wanted} poses are feasible with margin {margin_n} N: lower --poses or --force-margin-n"
    )]
    TooFewPoses {
        found: usize,
        wanted: usize,
        margin_n: f64,
    },
    #[error("--dwell-s must be finite and ≥ 0, got {0}")]
    Dwell(f64),
    #[error(transparent)]
    Planning(#[from] PlanningFailed),
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Formatting the waypoint CSV for `path`.
    #[error("{}: formatting the CSV: {source}", path.display())]
    Csv {
        path: PathBuf,
        #[source]
        source: csv::Error,
    },
}

/// i-th element of the van der Corput sequence in `base` (one Halton coordinate).
fn radical_inverse(mut i: u64, base: u64) -> f64 {
    let (mut f, mut r) = (1.0, 0.0);
    while i > 0 {
        f /= base as f64;
        r += f * (i % base) as f64;
        i /= base;
    }
    r
}

/// Reference forces (eq. 3.41) of `pose` within [f_min + margin, f_max − margin].
fn force_margin_ok(target: &mut OffsetTarget, p: &Platform, pose: &Pose, margin: f64) -> bool {
    let prm = p.model.params();
    match target.reference_forces(pose) {
        Ok((f, fd)) => {
            fd.feasible
                && f.iter()
                    .all(|v| *v >= prm.f_min + margin && *v <= prm.f_max - margin)
        }
        Err(_) => false,
    }
}

/// `poses` campaign poses: a 6-D Halton sequence over `fraction` of the workspace box, kept
/// where the reference forces keep `force_margin_n`, toured nearest-first from home; a pose
/// whose segment the daemon's checks (`checks`, see `lifecycle::configure_checks`) refuse is
/// replaced by the next candidate.
pub fn generate(
    checks: &Configured,
    poses: usize,
    fraction: f64,
    force_margin_n: f64,
) -> Result<Vec<Waypoint>, CampaignError> {
    let pf = checks.platform();
    if poses == 0 || !(fraction > 0.0 && fraction <= 1.0) {
        return Err(CampaignError::Arguments);
    }
    let (lo, hi) = cdpr_model::offset_target::region_box(&pf.region);
    let mut target = OffsetTarget::new(&pf.model);
    let mut cand = Vec::new();
    let bases = [2u64, 3, 5, 7, 11, 13];
    let mut i = 1u64;
    while cand.len() < 8 * poses && i < 200_000 {
        let x: [f64; 6] = std::array::from_fn(|k| {
            let c = 0.5 * (lo[k] + hi[k]);
            let h = 0.5 * (hi[k] - lo[k]) * fraction;
            c + h * (2.0 * radical_inverse(i, bases[k]) - 1.0)
        });
        i += 1;
        let pose = Pose::from_array(x);
        if force_margin_ok(&mut target, pf, &pose, force_margin_n) {
            cand.push(pose);
        }
    }
    let mut chosen: Vec<Waypoint> = Vec::new();
    // The first `poses` candidates in Halton order (spread over the box) make the pool; the
    // tour visits them nearest-first.
    let mut reserve = cand.into_iter();
    let mut pool: Vec<Pose> = reserve.by_ref().take(poses).collect();
    let mut cur = pf.home;
    while chosen.len() < poses {
        if pool.is_empty() {
            match reserve.next() {
                Some(p) => pool.push(p),
                None => break,
            }
        }
        pool.sort_by(|p, q| {
            let d = |x: &Pose| (x.r - cur.r).norm();
            d(q).total_cmp(&d(p))
        });
        let next = pool.pop().expect("non-empty");
        let mut trial = chosen.clone();
        trial.push(Waypoint {
            pose: next,
            not_before_s: 0.0,
        });
        if checks.verify_plan(&trial).is_ok() {
            chosen = trial;
            cur = next;
        } else if let Some(p) = reserve.next() {
            pool.push(p);
        }
    }
    if chosen.len() < poses {
        return Err(CampaignError::TooFewPoses {
            found: chosen.len(),
            wanted: poses,
            margin_n: force_margin_n,
        });
    }
    Ok(chosen)
}

/// Waypoints with earliest-arrival times such that the platform rests `dwell_s` at each one
/// (the planner holds a waypoint until the next segment may start, `trajectory::plan_samples`),
/// and the plan's total duration (s).
pub fn timed_waypoints(
    start: Pose,
    waypoints: &[Waypoint],
    lim: PlannerLimits,
    period_s: f64,
    dwell_s: f64,
) -> Result<(Vec<Waypoint>, f64), CampaignError> {
    if !(dwell_s.is_finite() && dwell_s >= 0.0) {
        return Err(CampaignError::Dwell(dwell_s));
    }
    let untimed: Vec<Waypoint> = waypoints
        .iter()
        .map(|w| Waypoint {
            pose: w.pose,
            not_before_s: 0.0,
        })
        .collect();
    let mut steps = vec![0usize; waypoints.len()];
    trajectory::plan_samples::<CampaignError>(start, &untimed, lim, period_s, |seg, _| {
        steps[seg] += 1;
        Ok(())
    })?;
    let mut t = 0.0;
    let mut out = Vec::with_capacity(waypoints.len());
    for (k, w) in waypoints.iter().enumerate() {
        if k > 0 {
            t += dwell_s;
        }
        t += steps[k] as f64 * period_s;
        out.push(Waypoint {
            pose: w.pose,
            not_before_s: t,
        });
    }
    Ok((out, t))
}

/// One row of a waypoint CSV: the numbers as `{:?}` writes them (shortest text that reads back
/// to the same f64), so a written campaign reads back bit for bit.
#[derive(serde::Serialize)]
struct WaypointRow {
    t_s: String,
    x_m: String,
    y_m: String,
    z_m: String,
    phi_x_deg: String,
    phi_y_deg: String,
    phi_z_deg: String,
}

/// Writes waypoints in the CSV format motion-core reads (`trajectory::read_waypoints`), the
/// comment as `#` lines on top.
pub fn write_waypoints(path: &Path, wps: &[Waypoint], comment: &str) -> Result<(), CampaignError> {
    let csv_err = |source| CampaignError::Csv {
        path: path.to_path_buf(),
        source,
    };
    let mut text = Vec::new();
    for line in comment.lines() {
        text.extend_from_slice(format!("# {line}\n").as_bytes());
    }
    let mut w = csv::Writer::from_writer(text);
    for wp in wps {
        let p = wp.pose.to_array();
        let f = |v: f64| format!("{v:?}");
        w.serialize(WaypointRow {
            t_s: f(wp.not_before_s),
            x_m: f(p[0]),
            y_m: f(p[1]),
            z_m: f(p[2]),
            phi_x_deg: f(p[3].to_degrees()),
            phi_y_deg: f(p[4].to_degrees()),
            phi_z_deg: f(p[5].to_degrees()),
        })
        .map_err(csv_err)?;
    }
    let text = w.into_inner().map_err(|e| csv_err(e.into_error().into()))?;
    std::fs::write(path, text).map_err(|source| CampaignError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Why `crs calibrate campaign` could not make its file.
#[derive(Debug, thiserror::Error)]
pub enum MakeCampaignError {
    /// The daemon or platform TOML.
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    #[error(transparent)]
    Configure(#[from] motion_core::daemon::lifecycle::ConfigureError),
    #[error(transparent)]
    Campaign(#[from] CampaignError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// What a campaign file is made from.
pub struct CampaignRequest<'a> {
    /// Platform TOML (workspace region, force limits, planner limits).
    pub platform: &'a Path,
    /// Daemon TOML (planner limits, loop period, feasibility check).
    pub daemon_config: &'a Path,
    pub poses: usize,
    /// Fraction of the workspace box (around its centre) the poses are drawn from.
    pub fraction: f64,
    /// Distance of the reference forces (eq. 3.41) from f_min and f_max, N.
    pub force_margin_n: f64,
    /// The CSV to write.
    pub out: &'a Path,
}

/// Generates the campaign of `r` ([`generate`], checked with motion-core's configure step) and
/// writes it with a comment saying how it was made; returns the number of poses and the plan's
/// duration without rests (s).
pub fn make(r: &CampaignRequest<'_>) -> Result<(usize, f64), MakeCampaignError> {
    let daemon = motion_core::daemon::config::load(r.daemon_config)?;
    let pf = cdpr_model::config::load_platform(r.platform)?;
    let checks = motion_core::daemon::lifecycle::configure_checks(&daemon, &pf)?;
    let chosen = generate(&checks, r.poses, r.fraction, r.force_margin_n)?;
    let (_, dur) = timed_waypoints(
        pf.home,
        &chosen,
        checks.planner_limits(),
        checks.period_s(),
        0.0,
    )?;
    let comment = format!(
        "Calibration campaign for `{}` ({}): {} poses, written by\n`crs calibrate campaign --platform {} --poses {} --fraction {} --force-margin-n {}`.\nHalton points over {:.0} % of the workspace box with varied orientations (platform geometry\nobservable), reference forces (eq. 3.41) within [f_min + {m}, f_max - {m}] N, ordered as a\nnearest-neighbour tour from the home pose; the whole plan ({dur:.1} s without rests) passes\nmotion-core's checks (workspace, limits, eq. 3.29). t_s = 0: `crs sim --dwell-s` times it.",
        pf.name,
        r.platform.display(),
        chosen.len(),
        r.platform.display(),
        r.poses,
        r.fraction,
        r.force_margin_n,
        r.fraction * 100.0,
        m = r.force_margin_n,
    );
    if let Some(dir) = r.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    write_waypoints(r.out, &chosen, &comment)?;
    Ok((chosen.len(), dur))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_waypoints_read_back_exactly() {
        let wps = vec![
            Waypoint {
                pose: Pose::from_array([0.1, -0.2, 2.0, 0.01, -0.02, 0.03]),
                not_before_s: 1.5,
            },
            Waypoint {
                pose: Pose::from_array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]),
                not_before_s: 3.25,
            },
        ];
        let p = std::env::temp_dir().join(format!("crs-stack-wps-{}.csv", std::process::id()));
        write_waypoints(&p, &wps, "two\nlines").unwrap();
        // The exact text: comments, the header, `{:?}` numbers, no quotes, `\n` line ends.
        let d = |r: f64| format!("{:?}", r.to_degrees());
        let want = format!(
            "# two\n# lines\nt_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n1.5,0.1,-0.2,2.0,{},{},{}\n3.25,0.0,0.0,2.0,0.0,0.0,0.0\n",
            d(0.01),
            d(-0.02),
            d(0.03)
        );
        assert_eq!(std::fs::read_to_string(&p).unwrap(), want);
        let back = trajectory::read_waypoints(&p).unwrap();
        assert_eq!(back.len(), 2);
        for (a, b) in wps.iter().zip(&back) {
            assert_eq!(a.not_before_s, b.not_before_s);
            for (x, y) in a.pose.to_array().iter().zip(b.pose.to_array()) {
                assert!((x - y).abs() < 1e-15, "{x} {y}");
            }
        }
    }

    #[test]
    fn van_der_corput_base_2() {
        let v: Vec<f64> = (1..=4).map(|i| radical_inverse(i, 2)).collect();
        assert_eq!(v, vec![0.5, 0.25, 0.75, 0.125]);
    }
}
