//! # model-analysis: analyses of a platform model, as reports
//!
//! What `crs model …` computes and shows, as a library: each analysis is one function that takes
//! a loaded [`Platform`](cdpr_model::config::Platform) (or the spec's planar robot) and returns a
//! report; the report prints itself as the table people read (`Display`), as JSON for scripts
//! (`json()`), and writes its CSV or SVG where it has one. The command line only parses flags,
//! loads the platform and prints.
//!
//! | analysis | module | equations |
//! |---|---|---|
//! | inverse / forward kinematics | [`kinematics`] | 2.3–2.8, 2.11, 2.16–2.29, 2.42 |
//! | force distribution, stiffness | [`statics`] | 3.29, 3.41, 5.11, 2.67–2.78 |
//! | wrench-feasible workspace (grid, hull, CSV) | [`workspace`] | 3.29, 3.41 |
//! | reachable workspace of the kinematic controller (SVG) | [`reachable`] | 3.33–3.35, 2.76, 3.23–3.24 |
//! | pose sensitivity to parameter errors (map, SVG) | [`sensitivity`] | 3.25–3.28 |
//! | the spec's planar 4-cable robot (SVG) | [`planar`] | 3.40, 4.24–4.28, 3.29, 3.33–3.35 |
//! | icosahedron cabin truss | [`truss`] | 5.2–5.7 |
//!
//! Layer: model. It depends on `cdpr-model` and knows nothing of IPC, real time, CAN, the
//! simulated plant or command lines; the plant's measurement of the reachable workspace
//! (`plant_experiments::reachable_on_plant`) is handed in as [`reachable::Measured`] values.

pub mod kinematics;
pub mod planar;
pub mod reachable;
pub mod sensitivity;
pub mod statics;
pub mod truss;
pub mod workspace;

use cdpr_model::Pose;
use serde_json::json;

/// Why an analysis could not be made.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error(transparent)]
    Kinematics(#[from] cdpr_model::kinematics::KinematicsError),
    #[error(transparent)]
    Statics(#[from] cdpr_model::statics::StaticsError),
    #[error(transparent)]
    Feasibility(#[from] cdpr_model::feasibility::FeasibilityError),
    #[error(transparent)]
    Elastostatics(#[from] cdpr_model::elastostatics::ElastostaticsError),
    #[error(transparent)]
    ForwardKinematics(#[from] cdpr_model::forward::FkError),
    #[error(transparent)]
    Workspace(#[from] cdpr_model::workspace::WorkspaceError),
    #[error(transparent)]
    Sensitivity(#[from] cdpr_analysis::sensitivity::SensitivityError),
    #[error(transparent)]
    Planar(#[from] cdpr_analysis::planar::PlanarError),
    #[error(transparent)]
    Truss(#[from] cdpr_analysis::truss::TrussError),
    /// The sensitivity needs the controller's forces, which a pose outside the closed form's
    /// workspace does not have.
    #[error(
        "the pose {pose} is not wrench feasible with the closed form (eq. 3.41): cable {cable} would need {force_n:.0} N; \
         the controller has no forces to command there"
    )]
    PoseNotFeasible {
        pose: String,
        cable: usize,
        force_n: f64,
    },
    /// Not one pose of the truss's worst-case grid could be evaluated.
    #[error("no pose of the grid could be evaluated")]
    NoPoseEvaluated,
    #[error(transparent)]
    Csv(#[from] csv::Error),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Plot(#[from] crs_plot::PlotError),
}

/// A report of an analysis: a table for people (`Display`) and JSON for scripts.
pub trait Report: std::fmt::Display {
    fn json(&self) -> serde_json::Value;
}

macro_rules! report {
    ($($t:ty),*) => {$(
        impl Report for $t {
            fn json(&self) -> serde_json::Value {
                <$t>::json(self)
            }
        }
    )*};
}

report!(
    kinematics::IkReport,
    kinematics::FkReport,
    statics::ForcesReport,
    statics::StiffnessReport,
    workspace::WorkspaceReport,
    reachable::ReachableReport,
    sensitivity::SensitivityReport,
    planar::PlanarReport,
    truss::TrussReport
);

/// A pose as JSON: position in m, rotation in degrees.
pub fn pose_json(p: &Pose) -> serde_json::Value {
    json!({
        "position_m": [p.r.x, p.r.y, p.r.z],
        "rotation_deg": [p.phi.x.to_degrees(), p.phi.y.to_degrees(), p.phi.z.to_degrees()],
    })
}

/// A pose for people: position in m, rotation in degrees, 4 decimals.
pub fn fmt_pose(p: &Pose) -> String {
    format!(
        "r = [{:.4}, {:.4}, {:.4}] m, φ = [{:.4}, {:.4}, {:.4}]°",
        p.r.x,
        p.r.y,
        p.r.z,
        p.phi.x.to_degrees(),
        p.phi.y.to_degrees(),
        p.phi.z.to_degrees()
    )
}
