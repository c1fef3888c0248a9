//! The dependency rules of docs/architecture.md, checked on the resolved graph
//! (`cargo metadata`): transitive NORMAL dependencies only (dev/build dependencies may differ).
//! A crate that gains a forbidden dependency, directly or through another crate, fails here.

use serde_json::Value;
use std::collections::{BTreeSet, HashMap};

fn graph() -> (HashMap<String, Vec<String>>, HashMap<String, String>) {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // The stack is Linux-only: resolve for this host's triple (other platforms' crates need
    // not be downloaded).
    let triple = format!("{}-unknown-linux-gnu", std::env::consts::ARCH);
    let out = std::process::Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--offline"])
        .args(["--filter-platform", &triple])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("running cargo metadata");
    assert!(
        out.status.success(),
        "cargo metadata: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m: Value = serde_json::from_slice(&out.stdout).expect("cargo metadata JSON");
    let mut name_of = HashMap::new();
    for p in m["packages"].as_array().unwrap() {
        name_of.insert(
            p["id"].as_str().unwrap().to_string(),
            p["name"].as_str().unwrap().to_string(),
        );
    }
    let mut deps = HashMap::new();
    for n in m["resolve"]["nodes"].as_array().unwrap() {
        let normal: Vec<String> = n["deps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| {
                d["dep_kinds"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|k| k["kind"].is_null())
            })
            .map(|d| d["pkg"].as_str().unwrap().to_string())
            .collect();
        deps.insert(n["id"].as_str().unwrap().to_string(), normal);
    }
    (deps, name_of)
}

/// Names of every crate `krate` pulls in through normal dependencies.
fn closure(krate: &str) -> BTreeSet<String> {
    let (deps, name_of) = graph();
    let root = name_of
        .iter()
        .find(|(_, n)| n.as_str() == krate)
        .map(|(id, _)| id.clone())
        .unwrap_or_else(|| panic!("{krate} is not in the workspace graph"));
    let mut seen = BTreeSet::new();
    let mut todo = vec![root];
    while let Some(id) = todo.pop() {
        for d in deps.get(&id).into_iter().flatten() {
            if seen.insert(name_of[d].clone()) {
                todo.push(d.clone());
            }
        }
    }
    seen
}

fn forbid(krate: &str, forbidden: &[&str]) {
    let c = closure(krate);
    let hits: Vec<&&str> = forbidden.iter().filter(|f| c.contains(**f)).collect();
    assert!(hits.is_empty(), "{krate} depends on {hits:?}");
}

/// The stack library, by domain, in the order its crates may use each other (a crate may use
/// those before it, never those after it).
const STACK: [&str; 5] = [
    "crs-supervisor",
    "sim-runs",
    "plant-experiments",
    "calibration-campaigns",
    "stack-reports",
];

/// `forbidden` followed by every crate of the stack library.
fn and_the_stack<'a>(forbidden: &[&'a str]) -> Vec<&'a str> {
    forbidden.iter().copied().chain(STACK).collect()
}

/// IPC, real time, CAN and CLI crates.
const RUNTIME: [&str; 7] = [
    "iceoryx2",
    "socketcan",
    "clap",
    "ruckig",
    "crs-ipc",
    "can-transport",
    "tracing-subscriber",
];

#[test]
fn the_model_library_and_the_data_format_pull_in_no_ipc_rt_can_or_cli() {
    forbid("cdpr-model", &RUNTIME);
    forbid("cdpr-analysis", &RUNTIME);
    // The design analyses sit on the model library, below its reports and every daemon.
    forbid(
        "cdpr-analysis",
        &and_the_stack(&["model-analysis", "motion-core", "sim-plant", "drive-io"]),
    );
    forbid("crs-dataset", &RUNTIME);
    forbid("surrogate", &RUNTIME);
    forbid("load-tracking", &RUNTIME);
    forbid("config-diagnostics", &RUNTIME);
    // The load estimator reads forces; it needs neither the simulator nor the bus.
    forbid("load-tracking", &and_the_stack(&["sim-plant", "drive-io"]));
    // The ride physics is a model too: the stack runs it, it knows no IPC or real time.
    forbid("ride-physics", &RUNTIME);
    forbid("ride-physics", &and_the_stack(&["motion-core"]));
    // So is the motion cueing (washout, tilt coordination, vestibular models): the stack runs
    // it and feeds motion-core, which it only knows through its tests.
    forbid("motion-cueing", &RUNTIME);
    forbid(
        "motion-cueing",
        &and_the_stack(&["motion-core", "sim-plant", "drive-io"]),
    );
    // The model's analyses (`crs model …`) are model too: the plant's measurement is handed in.
    forbid("model-analysis", &RUNTIME);
    forbid(
        "model-analysis",
        &and_the_stack(&["motion-core", "sim-plant", "drive-io"]),
    );
}

#[test]
fn the_plot_layer_is_plotters_alone() {
    // Every SVG of the model, calibration and ride crates is drawn through crs-plot, so it sits
    // below all of them: plotters (its SVG backend) and thiserror, no crate of this workspace.
    let c = closure("crs-plot");
    let beyond: Vec<&String> = c
        .iter()
        .filter(|n| {
            ![
                "plotters",
                "plotters-backend",
                "plotters-svg",
                "num-traits",
                "autocfg",
                "libm",
                "thiserror",
                "thiserror-impl",
                "proc-macro2",
                "quote",
                "syn",
                "unicode-ident",
            ]
            .contains(&n.as_str())
        })
        .collect();
    assert!(beyond.is_empty(), "crs-plot depends on {beyond:?}");
    assert!(c.contains("plotters"), "{c:?}");
    for user in [
        "model-analysis",
        "calibrate-diagnosis",
        "ride-physics",
        "motion-cueing",
        "stack-reports",
        "plant-experiments",
    ] {
        assert!(
            closure(user).contains("crs-plot"),
            "{user} should draw its SVGs with crs-plot"
        );
    }
    // No other crate of the workspace draws with plotters directly.
    let (deps, name_of) = graph();
    let direct: Vec<&String> = deps
        .iter()
        .filter(|(id, _)| id.starts_with("path+file://") && name_of[*id] != "crs-plot")
        .filter(|(_, ds)| ds.iter().any(|d| name_of[d] == "plotters"))
        .map(|(id, _)| &name_of[id])
        .collect();
    assert!(direct.is_empty(), "{direct:?} use plotters directly");
}

#[test]
fn the_contract_crates_depend_on_no_other_layer() {
    forbid(
        "crs-ipc",
        &and_the_stack(&["cdpr-model", "motion-core", "drive-io", "sim-plant"]),
    );
    // The bus model sits on the transport's frame and bit lengths only.
    forbid(
        "can-bus-model",
        &[
            "cdpr-model",
            "motion-core",
            "crs-ipc",
            "drive-io",
            "sim-plant",
            "can-wire",
        ],
    );
    forbid(
        "can-transport",
        &[
            "cdpr-model",
            "motion-core",
            "crs-ipc",
            "drive-io",
            "sim-plant",
        ],
    );
}

#[test]
fn the_drive_side_links_no_master() {
    // The simulated plant and the winch emulator's drive side are the master's counterpart:
    // they share the protocol (drive-bus) and drives.toml (drives-config) with drive-io, not
    // its master, its start-up plans or its loop, so an error there cannot hide on both sides.
    for krate in ["cia402-drive", "sim-plant"] {
        forbid(krate, &["drive-io", "drive-commissioning"]);
    }
    assert!(closure("sim-plant").contains("cia402-drive"));
    // What both sides share sits below both: no master, no drive side, no IPC.
    forbid(
        "drive-bus",
        &[
            "drives-config",
            "cia402-drive",
            "drive-commissioning",
            "drive-io",
            "crs-ipc",
            "iceoryx2",
        ],
    );
    forbid(
        "drives-config",
        &["cia402-drive", "drive-commissioning", "drive-io", "crs-ipc"],
    );
    forbid(
        "drive-commissioning",
        &["drive-io", "cia402-drive", "crs-ipc"],
    );
    // The master's daemon holds the master only: the drive side is a test counterpart.
    forbid("drive-io", &["cia402-drive"]);
}

#[test]
fn the_closure_is_transitive() {
    // motion-core → crs-ipc → iceoryx2: a rule on a transitive crate can fail.
    let c = closure("motion-core");
    assert!(c.contains("crs-ipc") && c.contains("iceoryx2"), "{c:?}");
}

#[test]
fn the_daemon_does_not_link_the_bus_the_simulator_or_the_stack() {
    forbid(
        "motion-core",
        &and_the_stack(&[
            "drive-io",
            "drive-bus",
            "drives-config",
            "cia402-drive",
            "can-transport",
            "socketcan",
            "sim-plant",
            "calibrate",
            "calibrate-diagnosis",
        ]),
    );
}

#[test]
fn the_safety_monitor_shares_no_code_with_the_controller() {
    forbid(
        "safety-monitor",
        &and_the_stack(&[
            "cdpr-model",
            "motion-core",
            "surrogate",
            "sim-plant",
            "drive-io",
            "drive-bus",
            "drives-config",
            "cia402-drive",
            "drive-commissioning",
        ]),
    );
}

#[test]
fn the_plants_oracle_shares_no_code_with_the_model_library() {
    // The second formulation of the plant's equilibrium must not reach the
    // equations it checks, nor nalgebra (whose code paths the model library's solvers use).
    let c = closure("plant-oracle");
    let allowed = BTreeSet::from([
        "glam",
        "thiserror",
        "thiserror-impl",
        "serde",
        "serde_core",
        "serde_derive",
    ]);
    let workspace_or_math: Vec<&String> = c
        .iter()
        .filter(|n| {
            !allowed.contains(n.as_str())
                && !["proc-macro2", "quote", "syn", "unicode-ident"].contains(&n.as_str())
        })
        .collect();
    assert!(
        workspace_or_math.is_empty(),
        "plant-oracle depends on {workspace_or_math:?}"
    );
    assert!(c.contains("glam"), "{c:?}");
    assert!(closure("sim-plant").contains("plant-oracle"));
}

#[test]
fn the_benchmark_plant_shares_no_code_with_what_it_tests() {
    // The diagnosis benchmark's independent generator writes the effects a second time: it
    // must reach neither the candidates it judges (calibrate), nor the simulated plant whose
    // parameterization they share, nor the model library's equations or nalgebra. It stands
    // on plant-oracle's energy formulation (glam) and draws its noise with rand.
    let c = closure("bench-plant");
    for f in [
        "calibrate",
        "calibrate-diagnosis",
        "sim-plant",
        "cdpr-model",
        "nalgebra",
        "crs-dataset",
        "motion-core",
    ] {
        assert!(!c.contains(f), "bench-plant depends on {f}: {c:?}");
    }
    let workspace: Vec<&String> = c
        .iter()
        .filter(|n| {
            ![
                "plant-oracle",
                "glam",
                "rand",
                "rand_core",
                "rand_chacha",
                "rand_distr",
                "ppv-lite86",
                "zerocopy",
                "zerocopy-derive",
                "getrandom",
                "libc",
                "cfg-if",
                "num-traits",
                "autocfg",
                "libm",
                "wasi",
                "wasip2",
                "wit-bindgen",
                "wit-bindgen-rt",
                "bitflags",
                "r-efi",
                "thiserror",
                "thiserror-impl",
                "serde",
                "serde_core",
                "serde_derive",
                "proc-macro2",
                "quote",
                "syn",
                "unicode-ident",
            ]
            .contains(&n.as_str())
        })
        .collect();
    assert!(
        workspace.is_empty(),
        "bench-plant depends on {workspace:?} beyond plant-oracle, glam, rand"
    );
    assert!(c.contains("plant-oracle"), "{c:?}");
}

#[test]
fn the_rt_utility_stays_small() {
    // The independent monitor links crs-rt (sleep, priority, affinity, mlock: operating-system
    // plumbing every loop shares). Any dependency crs-rt gained would be linked into the
    // monitor too, so it has exactly libc and thiserror.
    let (deps, name_of) = graph();
    let id = name_of
        .iter()
        .find(|(_, n)| n.as_str() == "crs-rt")
        .map(|(id, _)| id.clone())
        .expect("crs-rt is in the workspace graph");
    let direct: BTreeSet<&str> = deps[&id].iter().map(|d| name_of[d].as_str()).collect();
    assert_eq!(direct, BTreeSet::from(["libc", "thiserror"]));
    for user in [
        "motion-core",
        "drive-io",
        "sim-plant",
        "safety-monitor",
        "crs-console",
    ] {
        assert!(
            closure(user).contains("crs-rt"),
            "{user} should take its real-time set-up from crs-rt"
        );
    }
}

#[test]
fn only_the_command_line_and_the_safety_hil_use_the_stack_library() {
    // The safety HIL (a test harness) runs its processes under the stack's one supervisor,
    // and uses nothing else of the stack library.
    let (deps, name_of) = graph();
    for (id, ds) in &deps {
        let who = name_of[id].as_str();
        if who == "crs" || STACK.contains(&who) {
            continue;
        }
        for d in ds {
            let d = name_of[d].as_str();
            let allowed = who == "safety-hil" && d == "crs-supervisor";
            assert!(
                allowed || !(d == "crs" || STACK.contains(&d)),
                "{who} depends on {d} (the stack library or the CLI)"
            );
        }
    }
    let hil = closure("safety-hil");
    assert!(hil.contains("crs-supervisor"), "{hil:?}");
    let beyond_the_supervisor: Vec<&str> = STACK[1..]
        .iter()
        .copied()
        .chain([
            "sim-plant",
            "calibrate",
            "calibrate-diagnosis",
            "cdpr-model",
            "motion-core",
            "surrogate",
            "plotters",
            "tokio",
        ])
        .collect();
    forbid("safety-hil", &beyond_the_supervisor);
}

#[test]
fn the_stack_library_uses_its_crates_downwards_only() {
    // Each crate of the stack library may use those listed before it in STACK, none after it.
    for (i, krate) in STACK.iter().enumerate() {
        forbid(krate, &STACK[i + 1..]);
    }
    // The supervisor (what the safety HIL links) holds processes, transports and timing
    // profiles: no simulator, model, calibration or console.
    forbid(
        "crs-supervisor",
        &[
            "sim-plant",
            "calibrate",
            "calibrate-diagnosis",
            "cdpr-model",
            "motion-core",
            "surrogate",
            "crs-console",
            "plotters",
        ],
    );
    // The plant experiments run the plant model alone, not the stack's processes.
    forbid("plant-experiments", &["crs-supervisor", "sim-runs"]);
    assert!(closure("stack-reports").contains("calibration-campaigns"));
}

#[test]
fn nothing_depends_on_the_safety_hil() {
    // The fault-injection harness is a test tool: no daemon, library or CLI may link it.
    let (deps, name_of) = graph();
    assert!(name_of.values().any(|n| n == "safety-hil"));
    for (id, ds) in &deps {
        assert!(
            !ds.iter().any(|d| name_of[d] == "safety-hil"),
            "{} depends on safety-hil",
            name_of[id]
        );
    }
}

#[test]
fn nothing_links_the_test_rigs_or_the_wire_hub() {
    // The drive rigs (winch emulator, HIL scenarios, bus bench) are test doubles and the
    // can-wire hub is the simulated wire: a daemon that linked either could run against a
    // double in production. crs-supervisor starts the hub's binary, it does not link it; only the
    // rigs' bus bench runs a hub in its own process. The bus model is the hub's alone.
    let (deps, name_of) = graph();
    for (krate, allowed) in [
        ("drive-rig", &[][..]),
        ("can-wire", &["drive-rig"][..]),
        ("can-bus-model", &["can-wire"][..]),
    ] {
        assert!(name_of.values().any(|n| n == krate), "{krate} missing");
        for (id, ds) in &deps {
            assert!(
                allowed.contains(&name_of[id].as_str()) || !ds.iter().any(|d| name_of[d] == krate),
                "{} depends on {krate}",
                name_of[id]
            );
        }
    }
}

#[test]
fn calibration_needs_neither_the_simulator_nor_the_bus() {
    for krate in ["calibrate", "calibrate-diagnosis"] {
        forbid(krate, &["sim-plant", "drive-io", "iceoryx2", "socketcan"]);
    }
    // The identification core knows neither the effect diagnosis above it nor a plot.
    forbid("calibrate", &["calibrate-diagnosis", "crs-plot"]);
}

#[test]
fn the_shared_limits_depend_on_nothing() {
    // crs-limits is named by the model library, the contract and the independent monitor
    // alike: any dependency it gained would link them together.
    let c = closure("crs-limits");
    assert!(c.is_empty(), "crs-limits depends on {c:?}");
    for user in [
        "cdpr-model",
        "surrogate",
        "crs-ipc",
        "safety-monitor",
        "motion-core",
    ] {
        assert!(
            closure(user).contains("crs-limits"),
            "{user} should take MAX_CABLES / the |Δq| limit from crs-limits"
        );
    }
}

#[test]
fn the_test_support_is_a_dev_dependency_only() {
    // The counting allocator replaces the global allocator: linked into a daemon it would
    // count every allocation of the hard loop's process. No library or binary may need it.
    let (deps, name_of) = graph();
    for (id, ds) in &deps {
        assert!(
            !ds.iter().any(|d| name_of[d] == "crs-test-support"),
            "{} has crs-test-support as a normal dependency",
            name_of[id]
        );
    }
    assert!(closure("crs-test-support").is_empty());
}
