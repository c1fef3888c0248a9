//! The elastic walls keep what the hard loop follows inside the wrench-feasible region of the
//! platform for any pilot input: full stick into every wall, edge and corner
//! of the helicopter's operating region, at maximum and minimum thrust, pedals both ways. The
//! hover model (eq. 5.21–5.22) runs at 1 kHz; its pose goes through motion-core's own cueing
//! tracker (planner limits of `lifecycle::configure`, with the dynamic wrench) and the loop's
//! own per-cycle checks (`Cycle::compute`: region, velocity/acceleration limits, eq. 3.29 with
//! w = w_e + w_in in closed form eq. 3.41, i.e. every cable force in [f_min, f_max]). No
//! reference may be refused. A control run without walls shows the same inputs would be.
use cdpr_model::config::load_platform;
use cdpr_model::statics;
use motion_core::daemon::config;
use motion_core::daemon::cueing::{CueingFilter, CueingLimits};
use motion_core::daemon::cycle::{Cycle, Reference, Rejection};
use motion_core::daemon::lifecycle;
use nalgebra::Vector3;
use ride_physics::pilot::{directions, full_stick};
use ride_physics::settings::HoverSettings;
use ride_physics::{HoverModel, HoverState, PilotInput, step};

fn cfg(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

struct Flight {
    model: HoverModel,
    state: HoverState,
    filter: CueingFilter,
    cycle: Cycle,
    sp: crs_ipc::JointSetpoint,
    forces: Vec<f64>,
    f_lo: f64,
    f_hi: f64,
    max_penetration: Vector3<f64>,
    max_ref_accel: f64,
}

/// motion-core's cueing limits for the helicopter (configure once: it evaluates the region
/// grid, slow in a debug build).
fn cueing_limits() -> CueingLimits {
    static LIMITS: std::sync::OnceLock<CueingLimits> = std::sync::OnceLock::new();
    *LIMITS.get_or_init(|| {
        let pf = load_platform(cfg("helicopter.toml")).unwrap();
        let daemon = config::load(&cfg("motion-core-helicopter.toml")).unwrap();
        let configured = lifecycle::configure(&daemon, &pf).unwrap();
        let d = configured
            .dynamic_limits()
            .expect("the helicopter has [dynamics]");
        assert!(d.acceleration_factor > 0.0 && d.acceleration_factor <= 1.0);
        let lim = configured.planner_limits();
        CueingLimits {
            linear_velocity: lim.linear_velocity,
            linear_acceleration: lim.linear_acceleration,
            angular_velocity: lim.angular_velocity,
            angular_acceleration: lim.angular_acceleration,
        }
    })
}

fn flight(model: HoverModel) -> Flight {
    let pf = load_platform(cfg("helicopter.toml")).unwrap();
    let filter = CueingFilter::new(&pf.home, cueing_limits(), 1e-3);
    let mut cycle = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    cycle.set_dynamics(pf.dynamics);
    Flight {
        model,
        state: HoverState::at_rest(&pf.home),
        filter,
        forces: vec![0.0; pf.model.m()],
        cycle,
        sp: Default::default(),
        f_lo: f64::INFINITY,
        f_hi: f64::NEG_INFINITY,
        max_penetration: Vector3::zeros(),
        max_ref_accel: 0.0,
    }
}

impl Flight {
    /// One loop period: the hover model, the cueing tracker, the loop's checks.
    fn tick(&mut self, u: &PilotInput) -> Result<Reference, Rejection> {
        step(&self.model, &mut self.state, u, 1e-3);
        let p = self.model.walls.penetration(&self.state.r);
        self.max_penetration = self.max_penetration.sup(&p);
        self.filter.set_target(&self.state.pose_array());
        let r = self.filter.step();
        self.cycle.compute(&r, &mut self.sp)?;
        let a = Vector3::from_column_slice(&r.acceleration[..3]).norm();
        self.max_ref_accel = self.max_ref_accel.max(a);
        Ok(r)
    }

    /// The closed-form forces of the dynamic wrench at `r` (what the check judged).
    fn record_forces(&mut self, r: &Reference, data: &mut cdpr_model::Data) {
        let pf_model = self.cycle.model().clone();
        cdpr_model::kinematics::inverse(&pf_model, data, &r.pose).unwrap();
        let body = self.cycle.dynamics().copied().unwrap();
        let t = cdpr_model::pose::twist_from_coordinates(&r.pose);
        let v = t * nalgebra::Vector6::from_column_slice(&r.velocity);
        let a = t * nalgebra::Vector6::from_column_slice(&r.acceleration);
        let m = cdpr_model::dynamics::Motion {
            acceleration: a.fixed_rows::<3>(0).into_owned(),
            angular_velocity: v.fixed_rows::<3>(3).into_owned(),
            angular_acceleration: a.fixed_rows::<3>(3).into_owned(),
        };
        let p = pf_model.params();
        let w = p.w_e + cdpr_model::dynamics::inertial_wrench(&body, &r.pose, &m);
        let fd = statics::force_distribution(data, &w, p.f_min, p.f_max, &mut self.forces).unwrap();
        self.f_lo = self.f_lo.min(fd.f_lo);
        self.f_hi = self.f_hi.max(fd.f_hi);
    }
}

fn helicopter_model() -> HoverModel {
    let pf = load_platform(cfg("helicopter.toml")).unwrap();
    HoverSettings::load(&cfg("ride-helicopter.toml"))
        .unwrap()
        .model(&pf, "ride-helicopter.toml")
        .unwrap()
}

#[test]
fn full_stick_into_every_wall_and_corner_is_never_refused_and_forces_stay_in_limits() {
    let model = helicopter_model();
    let pf = load_platform(cfg("helicopter.toml")).unwrap();
    let mut data = cdpr_model::Data::new(&pf.model);
    // 5 s of full stick reaches every wall at the damped speed (≈ 0.5 m/s) and sits in it;
    // 1.5 s hands off. Pedals alternate full left / full right between directions.
    let (push, release) = (5000, 1500);
    let mut summary = Vec::new();
    for (n, d) in directions().enumerate() {
        {
            let yaw = if n % 2 == 0 { 1.0 } else { -1.0 };
            let mut f = flight(model);
            let u = full_stick(d, yaw);
            for k in 0..push + release {
                let input = if k < push { u } else { PilotInput::HOVER };
                let r = f.tick(&input).unwrap_or_else(|e| {
                    panic!("direction {d:?} yaw {yaw}: step {k}: refused: {e}")
                });
                if k % 10 == 0 {
                    f.record_forces(&r, &mut data);
                }
                // The flown pose itself never leaves the region the loop enforces.
                assert!(
                    pf.region.contains(&f.state.pose()),
                    "direction {d:?}: hover pose {:?} left the region",
                    f.state.pose_array()
                );
            }
            // Each pushed axis reached its wall (the test flies into them, not short of them).
            for k in 0..3 {
                if d[k] != 0 {
                    assert!(
                        f.max_penetration[k] > 1e-3,
                        "direction {d:?}: never reached the wall on axis {k}"
                    );
                }
            }
            assert!(f.f_lo >= pf.model.params().f_min && f.f_hi <= pf.model.params().f_max);
            summary.push((d, f.max_penetration, f.f_lo, f.f_hi, f.max_ref_accel));
        }
    }
    let pen = summary
        .iter()
        .fold(Vector3::zeros(), |a: Vector3<f64>, s| a.sup(&s.1));
    let lo = summary.iter().map(|s| s.2).fold(f64::INFINITY, f64::min);
    let hi = summary
        .iter()
        .map(|s| s.3)
        .fold(f64::NEG_INFINITY, f64::max);
    println!(
        "26 full-stick flights: max wall penetration [{:.1}, {:.1}, {:.1}] mm (margins [{:.0}, {:.0}, {:.0}] mm), forces {lo:.0} … {hi:.0} N",
        pen.x * 1e3,
        pen.y * 1e3,
        pen.z * 1e3,
        (model.walls.min.x - pf.region.position.min.x) * 1e3,
        (model.walls.min.y - pf.region.position.min.y) * 1e3,
        (model.walls.min.z - pf.region.position.min.z) * 1e3
    );
}

#[test]
fn without_the_walls_the_same_inputs_are_refused() {
    // Control: the check above can fail. Walls moved far out, full stick up-and-forward.
    let mut model = helicopter_model();
    model.walls.min = Vector3::repeat(-100.0);
    model.walls.max = Vector3::repeat(100.0);
    let mut f = flight(model);
    let u = full_stick([1, 0, 1], 0.0);
    let refused = (0..20_000).find_map(|_| f.tick(&u).err());
    assert_eq!(refused, Some(Rejection::OutsideRegion));
}
