//! What the repeatability checks found ([`crate::repeatability`]: multi-start, eq. 6.8; second
//! run, eq. 6.10; bootstrap): the figures a pipeline report carries.

use crate::effects::Effect;
use serde::Serialize;

/// What to run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RepeatabilityConfig {
    /// Starts of the multi-start test (0 = off).
    pub multi_starts: usize,
    /// Bootstrap resamples (0 = off).
    pub bootstrap: usize,
    /// Seed of the random starts and resamples (reproducible).
    pub seed: u64,
}

/// Multi-start result (eq. 6.8).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MultiStart {
    pub starts: usize,
    /// Starts whose fit failed (an error, not a number).
    pub failed: usize,
    /// Starts that reached the pipeline's optimum (cost within 1e-6, anchors within 1 mm).
    pub same_optimum: usize,
    /// Starts that ended at a lower cost than the pipeline's (by more than 1e-6 relative).
    pub lower_cost: usize,
    /// Largest frame-anchor distance (mm) from the pipeline's optimum over the converged starts.
    pub max_anchor_distance_mm: Option<f64>,
    /// Lowest cost found relative to the pipeline's (≤ 1 when a start did better).
    pub best_cost_ratio: Option<f64>,
}

/// Second optimisation run on the held-out set (eq. 6.10).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SecondRun {
    /// `None` when the fit failed (`failure` says why).
    pub max_anchor_change_mm: Option<f64>,
    pub mean_anchor_change_mm: Option<f64>,
    /// Largest |Δa₂| / (√2 σ) over the frame-anchor coordinates with a finite 1σ: ≈ 1–3 when
    /// both runs agree within their statistics.
    pub max_change_over_sigma: Option<f64>,
    pub failure: Option<String>,
}

/// Spread of one parameter over the bootstrap runs that identified it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamSpread {
    pub name: String,
    /// The pipeline's value and 1σ (NaN when it has none, e.g. not in its final model).
    pub value: f64,
    pub sigma: f64,
    /// Bootstrap runs that had it free, their mean and standard deviation.
    pub runs: usize,
    pub mean: f64,
    pub sd: f64,
}

/// Bootstrap result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Bootstrap {
    pub runs: usize,
    /// Runs whose pipeline failed or whose final step did not validate.
    pub failed: usize,
    /// Runs that chose exactly the pipeline's set of effects (in any order).
    pub same_effects: usize,
    /// How often each catalogue effect was chosen.
    pub effect_counts: Vec<(Effect, usize)>,
    /// k_F per cable and every extension parameter of any run.
    pub params: Vec<ParamSpread>,
    /// Largest bootstrap standard deviation of a frame-anchor coordinate, mm.
    pub max_anchor_sd_mm: Option<f64>,
}

/// Everything the repeatability section reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Repeatability {
    pub config: RepeatabilityConfig,
    pub multi_start: Option<MultiStart>,
    pub second_run: Option<SecondRun>,
    pub bootstrap: Option<Bootstrap>,
}
