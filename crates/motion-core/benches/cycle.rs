//! Per-cycle compute of the 1 ms hard loop (target p99 ≤ 2 µs): `Cycle::compute` =
//! checks (finite, workspace box, velocity/acceleration limits of table 5.1, wrench feasibility
//! eq. 3.29 with the closed-form forces eq. 3.41) + standard IK (eq. 2.3) + the polynomial
//! surrogate offset (eq. 5.26), exactly as the daemon runs it on the default platform
//! (`config/icosahedron.toml`, `check_wrench_feasibility = true`), with the static wrench w_e
//! and, side by side, the dynamic wrench w = w_e + w_in of the reference (eq. 5.13–5.16, the
//! platform's `[dynamics]`, the daemon's default).
//!
//! The surrogate is fitted here, in the set-up, like `crs surrogate fit`: degree 3 (84 Legendre
//! coefficients per cable) to q_off(x) = φ_el(x, f_ref(x)) − φ(x) (`cdpr_model::offset_target`).
//! The references are the daemon's demo trajectory (`config/demo-waypoints.csv`) sampled at
//! 1 ms by the same ruckig planner, so the inputs move through the workspace with real
//! velocities and accelerations; the benches cycle through them.
//!
//! Criterion reports means/medians of batches; the tail the loop cares about needs per-call
//! times, so after criterion this bench times 1e6 single calls with CLOCK_MONOTONIC (the clock
//! the daemon's own compute histogram uses) and prints exact p50 / p99 / p99.9 / max.
//! `cargo bench -p motion-core --bench cycle`; under `cargo test` (no `--bench` argument) the
//! per-call run shrinks to 1e4 calls as a smoke test.

use cdpr_model::Pose;
use cdpr_model::config::{Platform, load_platform};
use cdpr_model::offset_target::{OffsetTarget, region_box};
use criterion::Criterion;
use crs_ipc::JointSetpoint;
use crs_limits::quantile::quantile_sorted;
use motion_core::daemon::cycle::{Cycle, Reference};
use motion_core::daemon::realtime::monotonic_ns;
use motion_core::daemon::trajectory;
use std::hint::black_box;
use surrogate::{FitOptions, Region, Surrogate, fit};

fn config(name: &str) -> String {
    format!("{}/../../config/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// Degree-3 surrogate of the platform's elastostatic offset, as `crs surrogate fit` builds it
/// (fewer validation samples than the CLI's 10 000 to keep the set-up short; the fit itself is
/// the same).
fn fit_surrogate(pf: &Platform) -> Surrogate {
    let m = pf.model.m();
    let (lower, upper) = region_box(&pf.region);
    let mut target = OffsetTarget::new(&pf.model);
    let opts = FitOptions {
        degree: 3,
        validation_samples: 1000,
        ..FitOptions::default()
    };
    let (sg, report) = fit(
        &Region { lower, upper },
        &opts,
        m,
        &pf.model.identity_hex(),
        |x: &[f64; 6]| {
            let mut out = vec![0.0; m];
            target.offset(&Pose::from_array(*x), &mut out).map(|_| out)
        },
    )
    .unwrap_or_else(|e| panic!("surrogate fit on {}: {e}", pf.name));
    eprintln!(
        "surrogate: degree {}, {} coefficients/cable, max |φ_sg| {:.2} mm, certified {:.2} mm",
        report.degree,
        report.n_coeffs_per_cable,
        report.max_abs_offset_mm,
        report.certified_bound_mm
    );
    sg
}

/// The demo trajectory sampled at 1 ms with the daemon's planner limits (motion-core.toml:
/// velocity_scale 0.3, acceleration_scale 0.2, jerk 20 m/s³ / 200 °/s³; accelerations scaled
/// to what the dynamic wrench keeps feasible, as `lifecycle::configure` does).
fn demo_references(pf: &Platform) -> Vec<Reference> {
    let waypoints = trajectory::read_waypoints(config("demo-waypoints.csv").as_ref())
        .unwrap_or_else(|e| panic!("{e}"));
    let daemon = motion_core::daemon::config::load(config("motion-core.toml").as_ref())
        .unwrap_or_else(|e| panic!("{e}"));
    let lim = motion_core::daemon::lifecycle::configure_checks(&daemon, pf)
        .unwrap_or_else(|e| panic!("{e}"))
        .planner_limits();
    let mut refs = Vec::new();
    trajectory::plan_samples::<String>(pf.home, &waypoints, lim, 1e-3, |_, r| {
        refs.push(r);
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    refs
}

struct Setup {
    with_surrogate: Cycle,
    with_surrogate_dynamic: Cycle,
    without_surrogate: Cycle,
    refs: Vec<Reference>,
}

fn setup() -> Setup {
    let pf = load_platform(config("icosahedron.toml")).unwrap_or_else(|e| panic!("{e}"));
    let sg = fit_surrogate(&pf);
    let new_cycle = || Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    let mut with_surrogate = new_cycle();
    let mut with_surrogate_dynamic = new_cycle();
    let n = sg.n_cables();
    with_surrogate
        .set_surrogate(Box::new(sg.clone()), n)
        .unwrap_or_else(|e| panic!("{e}"));
    with_surrogate_dynamic
        .set_surrogate(Box::new(sg), n)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        pf.dynamics.is_some(),
        "config/icosahedron.toml has [dynamics]"
    );
    with_surrogate_dynamic.set_dynamics(pf.dynamics);
    let refs = demo_references(&pf);
    // Every reference must pass the checks: a rejected one returns early and would flatter
    // the figures.
    let mut sp = JointSetpoint::default();
    for cycle in [&mut with_surrogate, &mut with_surrogate_dynamic] {
        for (k, r) in refs.iter().enumerate() {
            cycle
                .compute(r, &mut sp)
                .unwrap_or_else(|e| panic!("reference {k} refused: {e}"));
            assert!(
                sp.surrogate_offset_m[..n].iter().any(|o| *o != 0.0),
                "the surrogate offset must be non-zero"
            );
        }
    }
    Setup {
        with_surrogate,
        with_surrogate_dynamic,
        without_surrogate: new_cycle(),
        refs,
    }
}

fn criterion_benches(c: &mut Criterion, s: &mut Setup) {
    let refs = &s.refs;
    let mut sp = JointSetpoint::default();
    for (name, cycle) in [
        ("cycle_compute_checks_ik_surrogate", &mut s.with_surrogate),
        (
            "cycle_compute_dynamic_wrench_checks_ik_surrogate",
            &mut s.with_surrogate_dynamic,
        ),
        (
            "cycle_compute_checks_ik_no_surrogate",
            &mut s.without_surrogate,
        ),
    ] {
        let mut k = 0usize;
        c.bench_function(name, |b| {
            b.iter(|| {
                k = if k + 1 == refs.len() { 0 } else { k + 1 };
                cycle.compute(black_box(&refs[k]), &mut sp).is_ok()
            })
        });
    }
}

/// Exact quantile of sorted samples, by the stack's one definition (nearest rank,
/// [`crs_limits::quantile`]); every call here has samples.
fn quantile(sorted: &[u64], q: f64) -> u64 {
    quantile_sorted(sorted, q).expect("samples")
}

/// Times `calls` single `Cycle::compute` calls and prints p50 / p99 / p99.9 / max. `verdict`:
/// compare with the target (only meaningful for an optimised `cargo bench` run).
fn per_call_histogram(s: &mut Setup, calls: usize, verdict: bool) {
    let mut times = vec![0u64; calls];
    let mut overhead = vec![0u64; calls.min(100_000)];
    let mut sp = JointSetpoint::default();
    // Cost of the timing itself (two clock reads): reported, not subtracted.
    for t in overhead.iter_mut() {
        let t0 = monotonic_ns();
        *t = monotonic_ns() - t0;
    }
    overhead.sort_unstable();
    for (name, cycle) in [
        ("checks + IK + surrogate", &mut s.with_surrogate),
        (
            "checks with the dynamic wrench + IK + surrogate",
            &mut s.with_surrogate_dynamic,
        ),
        ("checks + IK, no surrogate", &mut s.without_surrogate),
    ] {
        let mut k = 0usize;
        let mut failed = 0usize;
        for t in times.iter_mut() {
            k = if k + 1 == s.refs.len() { 0 } else { k + 1 };
            let r = &s.refs[k];
            let t0 = monotonic_ns();
            let ok = cycle.compute(black_box(r), &mut sp).is_ok();
            *t = monotonic_ns() - t0;
            failed += usize::from(!ok);
        }
        assert_eq!(failed, 0, "{failed} references refused");
        times.sort_unstable();
        let mean = times.iter().sum::<u64>() as f64 / calls as f64;
        let p99 = quantile(&times, 0.99);
        println!(
            "per-call Cycle::compute ({name}), {calls} calls: p50 {} ns, p99 {} ns, p99.9 {} ns, max {} ns, mean {mean:.0} ns — target p99 ≤ 2000 ns: {}",
            quantile(&times, 0.5),
            p99,
            quantile(&times, 0.999),
            times[calls - 1],
            match (verdict, p99 <= 2000) {
                (false, _) => "(smoke run, not a measurement)",
                (true, true) => "met",
                (true, false) => "MISSED",
            }
        );
    }
    println!(
        "timer overhead (two CLOCK_MONOTONIC reads, included above): p50 {} ns, p99 {} ns",
        quantile(&overhead, 0.5),
        quantile(&overhead, 0.99)
    );
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` does not (smoke run).
    let full = std::env::args().any(|a| a == "--bench");
    let mut s = setup();
    println!(
        "{} references from the demo trajectory (config/demo-waypoints.csv at 1 ms), platform config/icosahedron.toml",
        s.refs.len()
    );
    let mut c = Criterion::default().configure_from_args();
    criterion_benches(&mut c, &mut s);
    c.final_summary();
    let optimised = !cfg!(debug_assertions);
    per_call_histogram(
        &mut s,
        if full { 1_000_000 } else { 10_000 },
        full && optimised,
    );
}
